//! A rolling window of rows addressed by absolute row index — the halo.
//!
//! Rows enter at the bottom ([`RowWindow::push`]) and leave at the top
//! ([`RowWindow::evict_below`]); evicted buffers are recycled, so in steady
//! state the window allocates nothing.

use std::collections::VecDeque;

/// Rows `first..first + len()` of equal length.
#[derive(Debug)]
pub struct RowWindow<T> {
    first: usize,
    row_len: usize,
    rows: VecDeque<Vec<T>>,
    spare: Vec<Vec<T>>,
    high_water: usize,
}

impl<T: Copy> RowWindow<T> {
    /// An empty window whose next row is row 0.
    pub fn new(row_len: usize) -> Self {
        RowWindow {
            first: 0,
            row_len,
            rows: VecDeque::new(),
            spare: Vec::new(),
            high_water: 0,
        }
    }

    /// Index of the first row held.
    pub fn first(&self) -> usize {
        self.first
    }

    /// One past the last row held.
    pub fn end(&self) -> usize {
        self.first + self.rows.len()
    }

    /// Most rows ever held at once.
    pub fn high_water(&self) -> usize {
        self.high_water
    }

    /// Append a row filled with `fill`; returns it.
    pub fn push(&mut self, fill: T) -> &mut [T] {
        let mut v = self.spare.pop().unwrap_or_default();
        v.clear();
        v.resize(self.row_len, fill);
        self.rows.push_back(v);
        self.high_water = self.high_water.max(self.rows.len());
        self.rows
            .back_mut()
            .map(|v| v.as_mut_slice())
            .unwrap_or(&mut [])
    }

    /// Append a copy of `row` (of the window's row length).
    pub fn push_copy(&mut self, row: &[T]) {
        let mut v = self.spare.pop().unwrap_or_default();
        v.clear();
        v.extend_from_slice(row);
        self.rows.push_back(v);
        self.high_water = self.high_water.max(self.rows.len());
    }

    /// Append a row for a caller that overwrites every value: a recycled
    /// buffer keeps its stale contents (no fill); a new one is filled with
    /// `fill`.
    pub fn push_stale(&mut self, fill: T) {
        match self.spare.pop() {
            Some(v) if v.len() == self.row_len => {
                self.rows.push_back(v);
                self.high_water = self.high_water.max(self.rows.len());
            }
            other => {
                if let Some(v) = other {
                    self.spare.push(v);
                }
                self.push(fill);
            }
        }
    }

    /// Row `y` (absolute). Panics if not held: a halo bug, not an input error.
    #[inline]
    pub fn get(&self, y: usize) -> &[T] {
        &self.rows[y - self.first]
    }

    /// Mutable rows `a..b` (absolute), in order.
    pub fn range_mut(&mut self, a: usize, b: usize) -> Vec<&mut [T]> {
        let first = self.first;
        self.rows
            .range_mut(a - first..b - first)
            .map(|v| v.as_mut_slice())
            .collect()
    }

    /// Drop rows below `y`, keeping their buffers for reuse.
    pub fn evict_below(&mut self, y: usize) {
        while self.first < y && !self.rows.is_empty() {
            if let Some(v) = self.rows.pop_front() {
                self.spare.push(v);
            }
            self.first += 1;
        }
        if self.rows.is_empty() && self.first < y {
            self.first = y;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rolls_and_recycles() {
        let mut w = RowWindow::<u8>::new(3);
        for i in 0..5 {
            w.push(i);
        }
        w.evict_below(3);
        assert_eq!(w.first(), 3);
        assert_eq!(w.get(4), &[4, 4, 4]);
        w.push(9);
        assert_eq!(w.end(), 6);
        assert_eq!(w.high_water(), 5);
        assert_eq!(w.range_mut(4, 6).len(), 2);
    }
}
