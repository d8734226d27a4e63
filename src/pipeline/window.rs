//! A rolling window of rows addressed by absolute row index — the halo.
//!
//! Rows enter at the bottom ([`RowWindow::push`]) and leave at the top
//! ([`RowWindow::evict_below`]); evicted buffers are recycled, so in steady
//! state the window allocates nothing.

use std::collections::VecDeque;

/// Rows `first..first + len()` of equal length.
///
/// Rows live in blocks: one row each for rows pushed one at a time, several
/// for a strip taken whole ([`RowWindow::push_rows`], the input's rows: no
/// copy). A block leaves when its last row does.
#[derive(Debug)]
pub struct RowWindow<T> {
    first: usize,
    row_len: usize,
    /// Each row held: its block (counted from `base`) and first value.
    rows: VecDeque<(usize, usize)>,
    blocks: VecDeque<Vec<T>>,
    /// Per block, whether it is a strip taken whole (lent: it goes back to
    /// its source, never to `spare`, even when it is one row long).
    lent: VecDeque<bool>,
    /// The number of the block at the front of `blocks`.
    base: usize,
    spare: Vec<Vec<T>>,
    high_water: usize,
    /// Where a strip's buffer goes once its rows have left (back to the
    /// source that filled it, [`RowWindow::recycle_strips`]).
    recycle: Option<crossbeam_channel::Sender<Vec<T>>>,
}

impl<T: Copy> RowWindow<T> {
    /// An empty window whose next row is row 0.
    pub fn new(row_len: usize) -> Self {
        RowWindow {
            first: 0,
            row_len,
            rows: VecDeque::new(),
            blocks: VecDeque::new(),
            lent: VecDeque::new(),
            base: 0,
            spare: Vec::new(),
            high_water: 0,
            recycle: None,
        }
    }

    /// The values in a row.
    pub fn row_len(&self) -> usize {
        self.row_len
    }

    /// Send the buffers of strips taken whole ([`RowWindow::push_rows`]) to
    /// `tx` once their rows have left, for the source to fill again (when
    /// `tx` is full they are dropped).
    pub fn recycle_strips(&mut self, tx: crossbeam_channel::Sender<Vec<T>>) {
        self.recycle = Some(tx);
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

    /// Append `v` as a block of `n` whole rows (`lent`: a strip's).
    fn push_block(&mut self, v: Vec<T>, n: usize, lent: bool) {
        let id = self.base + self.blocks.len();
        self.rows.extend((0..n).map(|k| (id, k * self.row_len)));
        self.blocks.push_back(v);
        self.lent.push_back(lent);
        self.high_water = self.high_water.max(self.rows.len());
    }

    /// Append a row filled with `fill`; returns it.
    pub fn push(&mut self, fill: T) -> &mut [T] {
        let mut v = self.spare.pop().unwrap_or_default();
        v.clear();
        v.resize(self.row_len, fill);
        self.push_block(v, 1, false);
        self.blocks
            .back_mut()
            .map(|v| v.as_mut_slice())
            .unwrap_or(&mut [])
    }

    /// Append `rows` rows held in order in `data` (of `rows` times the row
    /// length), keeping its buffer.
    pub fn push_rows(&mut self, data: Vec<T>, rows: usize) {
        assert_eq!(data.len(), rows * self.row_len, "a strip of whole rows");
        self.push_block(data, rows, true);
    }

    /// Append a row for a caller that overwrites every value: a recycled
    /// buffer keeps its stale contents (no fill); a new one is filled with
    /// `fill`.
    pub fn push_stale(&mut self, fill: T) {
        match self.spare.pop() {
            Some(v) if v.len() == self.row_len => self.push_block(v, 1, false),
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
        let (b, at) = self.rows[y - self.first];
        &self.blocks[b - self.base][at..at + self.row_len]
    }

    /// Mutable rows `a..b` (absolute), in order.
    pub fn range_mut(&mut self, a: usize, b: usize) -> Vec<&mut [T]> {
        let mut out = Vec::with_capacity(b.saturating_sub(a));
        if a >= b {
            return out;
        }
        if self.row_len == 0 {
            out.extend((a..b).map(|_| <&mut [T]>::default()));
            return out;
        }
        let (first, row_len, base) = (self.first, self.row_len, self.base);
        let (b0, at0) = self.rows[a - first];
        let (b1, at1) = self.rows[b - 1 - first];
        for (k, block) in self.blocks.range_mut(b0 - base..=b1 - base).enumerate() {
            let id = b0 + k;
            let from = if id == b0 { at0 } else { 0 };
            let to = if id == b1 { at1 + row_len } else { block.len() };
            out.extend(block[from..to].chunks_exact_mut(row_len));
        }
        out
    }

    /// Every row held, shared.
    pub fn rows(&self) -> Rows<'_, T> {
        Rows {
            first: self.first,
            rows: (self.first..self.end()).map(|y| self.get(y)).collect(),
        }
    }

    /// From one borrow, the rows before `y` shared and the rows from `y`
    /// mutable: one pass may read the first while another writes the rest.
    pub fn split_at(&mut self, y: usize) -> (Rows<'_, T>, Vec<&mut [T]>) {
        let first = self.first;
        let y = y.clamp(first, self.end());
        let mut old = self.range_mut(first, self.end());
        let new = old.split_off(y - first);
        let rows = old.into_iter().map(|r| &*r).collect();
        (Rows { first, rows }, new)
    }

    /// Drop rows below `y`, keeping the buffers of the window's own rows for
    /// reuse.
    pub fn evict_below(&mut self, y: usize) {
        while self.first < y && !self.rows.is_empty() {
            self.rows.pop_front();
            self.first += 1;
        }
        if self.rows.is_empty() && self.first < y {
            self.first = y;
        }
        // Blocks before the first row held (all of them when none is).
        let keep_from = self
            .rows
            .front()
            .map_or(self.base + self.blocks.len(), |r| r.0);
        while self.base < keep_from {
            let lent = self.lent.pop_front().unwrap_or(false);
            if let Some(v) = self.blocks.pop_front() {
                // The window's own row is kept; a strip's buffer goes (back
                // to its source, where there is a way), one row long or not:
                // kept, the one-row strips of a whole image piled up here.
                if !lent {
                    self.spare.push(v);
                } else if let Some(tx) = &self.recycle {
                    let _ = tx.try_send(v);
                }
            }
            self.base += 1;
        }
    }
}

/// Rows `first..first + len` of a window, shared ([`RowWindow::rows`],
/// [`RowWindow::split_at`]).
#[derive(Clone, Debug)]
pub struct Rows<'a, T> {
    first: usize,
    rows: Vec<&'a [T]>,
}

impl<'a, T> Rows<'a, T> {
    /// Row `y` (absolute). Panics if not held: a halo bug, not an input error.
    #[inline]
    pub fn get(&self, y: usize) -> &'a [T] {
        self.rows[y - self.first]
    }

    /// Row `y` where held.
    #[inline]
    pub fn try_get(&self, y: usize) -> Option<&'a [T]> {
        y.checked_sub(self.first)
            .and_then(|k| self.rows.get(k).copied())
    }

    /// Index of the first row.
    pub fn first(&self) -> usize {
        self.first
    }

    /// These rows and then `more` (rows from `self`'s end), as one view.
    pub fn with(mut self, more: impl IntoIterator<Item = &'a [T]>) -> Self {
        self.rows.extend(more);
        self
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

    #[test]
    fn strip_buffers_go_back_once_their_last_row_has_left() {
        let (tx, rx) = crossbeam_channel::bounded(1);
        let mut w = RowWindow::<u8>::new(2);
        w.recycle_strips(tx);
        w.push_rows(vec![0, 0, 1, 1, 2, 2], 3);
        w.push(3);
        w.push_rows(vec![4, 4, 5, 5], 2);
        w.evict_below(2);
        assert!(rx.try_recv().is_err(), "row 2 is still held");
        w.evict_below(4);
        assert_eq!(rx.try_recv().ok(), Some(vec![0, 0, 1, 1, 2, 2]));
        // The single row's buffer stays for the window's own reuse; a
        // strip the channel has no room for is dropped.
        let (tx, rx) = crossbeam_channel::bounded(0);
        w.recycle_strips(tx);
        w.evict_below(6);
        assert_eq!((w.spare.len(), rx.try_recv().ok()), (1, None));
    }

    #[test]
    fn a_split_shares_the_rows_above_and_lends_the_rest() {
        let mut w = RowWindow::<u8>::new(2);
        w.push_rows(vec![0, 0, 1, 1, 2, 2], 3);
        w.push(3);
        w.evict_below(1);
        let (old, new) = w.split_at(2);
        assert_eq!(
            (old.first(), old.get(1), old.try_get(2)),
            (1, &[1u8, 1][..], None)
        );
        assert_eq!(new.len(), 2);
        for r in new {
            r[1] = 7;
        }
        assert_eq!(old.with([&[5u8, 5][..]]).get(2), &[5, 5]);
        assert_eq!((w.get(2), w.get(3)), (&[2u8, 7][..], &[3u8, 7][..]));
        assert_eq!(w.rows().get(3), &[3, 7]);
        // At the window's ends: all shared, or all lent.
        assert_eq!(w.split_at(9).1.len(), 0);
        assert_eq!(w.split_at(0).1.len(), 3);
    }

    #[test]
    fn strips_taken_whole_mix_with_single_rows() {
        let mut w = RowWindow::<u8>::new(2);
        w.push_rows(vec![0, 0, 1, 1, 2, 2], 3);
        w.push(3);
        w.push_rows(vec![4, 4, 5, 5], 2);
        assert_eq!((w.first(), w.end(), w.high_water()), (0, 6, 6));
        for y in 0..6 {
            assert_eq!(w.get(y), &[y as u8; 2]);
        }
        for (k, r) in w.range_mut(1, 5).into_iter().enumerate() {
            assert_eq!(r, &[k as u8 + 1; 2]);
            r[0] = 9;
        }
        assert_eq!(w.get(4), &[9, 4]);
        // The first block leaves with its last row, not before.
        w.evict_below(2);
        assert_eq!((w.first(), w.get(2)), (2, &[9u8, 2][..]));
        w.evict_below(5);
        assert_eq!((w.first(), w.get(5)), (5, &[5u8, 5][..]));
        assert_eq!(w.blocks.len(), 1);
        w.evict_below(9);
        assert_eq!((w.first(), w.end(), w.blocks.len()), (9, 9, 0));
        // The single row's buffer is kept for reuse, the strips' are not.
        assert_eq!(w.spare.len(), 1);
        w.push(7);
        assert_eq!(w.get(9), &[7, 7]);
        // Nor a strip of one row: a window fed one-row strips holds no
        // more buffers than rows (and row 9's own).
        for y in 10..100 {
            w.push_rows(vec![y as u8; 2], 1);
            w.evict_below(y - 2);
        }
        assert_eq!((w.blocks.len(), w.spare.len()), (3, 1));
        // Zero-length rows are still rows.
        let mut z = RowWindow::<u8>::new(0);
        z.push(0);
        z.push_rows(Vec::new(), 2);
        assert_eq!(
            (z.end(), z.get(2).len(), z.range_mut(0, 3).len()),
            (3, 0, 3)
        );
    }
}
