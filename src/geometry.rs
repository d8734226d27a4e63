//! Geometry: image sizes, the super-sample grid, reflection at the borders,
//! and the halo arithmetic that sizes the rolling windows.
//!
//! Coordinates: input sample `(i, j)` (column, row) lies in output pixel
//! `(i / S, j / S)` at sub-offset `(i % S, j % S)`. Its centre, in output-pixel
//! units, is `(i + 0.5) / S`; an output pixel's centre is `x + 0.5`. So a
//! sample sits `delta(a) = (a + 0.5) / S - 0.5` from its pixel's centre.

/// Reflect a virtual index onto `0..n` by the method of images: the image is
/// mirrored about each border (edge-inclusive, `-1 → 0`, `n → n-1`), and again
/// as often as needed for kernels wider than the image.
#[inline]
pub fn mirror(v: i64, n: usize) -> usize {
    debug_assert!(n > 0);
    let n = n as i64;
    // Inside the image (nearly every call): no division.
    if (0..n).contains(&v) {
        return v as usize;
    }
    let k = v.rem_euclid(2 * n);
    (if k < n { k } else { 2 * n - 1 - k }) as usize
}

/// Offset of sub-sample `a` (0..S) from the centre of its output pixel, in
/// output pixels.
#[inline]
pub fn sub_offset(a: usize, s: usize) -> f64 {
    (a as f64 + 0.5) / s as f64 - 0.5
}

/// Sizes of one filtering job.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Grid {
    /// Input width in samples.
    pub in_w: usize,
    /// Input height in samples.
    pub in_h: usize,
    /// Super-sampling factor S (input samples per output pixel, per axis).
    pub s: usize,
}

impl Grid {
    /// Output width in pixels.
    pub fn out_w(&self) -> usize {
        self.in_w / self.s
    }
    /// Output height in pixels.
    pub fn out_h(&self) -> usize {
        self.in_h / self.s
    }
}

/// The halo contract between the read cursor and the write cursor, in output
/// rows. See `docs/DESIGN.md`.
///
/// * `xbar_reach`: rows of box luminance either side of a pixel row that the
///   base noise test reads (Relation 14 at m = 1).
/// * `base_reach`: output rows either side that one sample reaches with the base
///   kernel.
/// * `search_reach`: rows either side that the width search reads (largest
///   kernel's cut-off).
/// * `spread_reach`: rows either side that the widest kernel writes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Halo {
    /// Luminance rows read by the base noise test.
    pub xbar_reach: usize,
    /// Rows written by the base kernel.
    pub base_reach: usize,
    /// Luminance rows read by the width search.
    pub search_reach: usize,
    /// Rows written by the widest kernel.
    pub spread_reach: usize,
}

impl Halo {
    /// Output rows past row `y` that must have been read before row `y` is final.
    pub fn lag(&self) -> usize {
        (self.xbar_reach + self.base_reach).max(self.search_reach + self.spread_reach)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mirror_is_edge_inclusive_and_periodic() {
        assert_eq!(mirror(-1, 5), 0);
        assert_eq!(mirror(-2, 5), 1);
        assert_eq!(mirror(5, 5), 4);
        assert_eq!(mirror(6, 5), 3);
        assert_eq!(mirror(10, 5), 0);
        assert_eq!(mirror(-6, 5), 4);
        for v in -20..20 {
            assert_eq!(mirror(v, 1), 0);
        }
        // Inside, itself; outside, its image in either border.
        for n in 1..9usize {
            let ni = n as i64;
            for v in -30..30i64 {
                if (0..ni).contains(&v) {
                    assert_eq!(mirror(v, n), v as usize);
                }
                assert_eq!(mirror(-1 - v, n), mirror(v, n), "left of {v}, n = {n}");
                assert_eq!(
                    mirror(2 * ni - 1 - v, n),
                    mirror(v, n),
                    "right of {v}, n = {n}"
                );
                assert!(mirror(v, n) < n);
            }
        }
    }

    #[test]
    fn sub_offsets_are_symmetric() {
        for s in 1..=8 {
            for a in 0..s {
                let d = sub_offset(a, s) + sub_offset(s - 1 - a, s);
                assert!(d.abs() < 1e-15);
            }
        }
        assert_eq!(sub_offset(1, 3), 0.0);
    }
}
