//! The stage's row passes: the box luminance of new pixel rows (with the
//! summed-area table's rows), the base rows (the vertical gather of the
//! horizontal pass), and the coarse grids' share of final rows. Each is a
//! parallel loop, a task a row.

use rayon::iter::{
    IndexedParallelIterator, IntoParallelIterator, IntoParallelRefMutIterator, ParallelIterator,
};

use super::coarse;
use super::{
    csum_add, csum_prefix, mirror, Back, ChannelMode, CoarseGrid, RowWindow, Rows, Rules, Shape,
    TableRows,
};

/// The box luminance of pixel rows `a..` of `input` into `rows` (`pad`
/// mirrored pixels each side) and, with `csum` (the table's rows before `a`,
/// its new rows, its block), the summed-area table's rows for them. Returns
/// the rows made, to read.
pub(super) fn box_luminance<'a>(
    shape: &Shape,
    rules: &Rules,
    input: &RowWindow<f32>,
    a: usize,
    rows: Vec<&'a mut [f32]>,
    csum: Option<TableRows<'_>>,
) -> Vec<&'a [f32]> {
    if rows.is_empty() {
        return Vec::new();
    }
    let (above, mut csum_rows, block) = match csum {
        Some(t) => (Some(t.old), t.new.into_iter().map(Some).collect(), t.block),
        None => (None, rows.iter().map(|_| None).collect::<Vec<_>>(), 1),
    };
    let region = crate::trace::region("box luminance");
    let rows: Vec<&'a [f32]> = rows
        .into_par_iter()
        .zip(csum_rows.par_iter_mut())
        .enumerate()
        .map_init(Vec::<f64>::new, |core, (k, (row, csum_row))| {
            let _task = region.task("box luminance");
            ybox_row(shape, rules, input, a + k, row, core);
            if let Some(c) = csum_row {
                csum_prefix(row, c);
            }
            &*row
        })
        .collect();
    drop(region);
    if let Some(old) = above {
        let mut new: Vec<&mut [f64]> = csum_rows.into_iter().flatten().collect();
        make_csums(&old, &mut new, a, block);
    }
    rows
}

/// The summed-area table's rows `a..` (`rows`; the rows before them in
/// `old`) for the box luminance (`--bound-from`): each row's running sum
/// (made with its row), plus here the row above's where the row is not the
/// first of its block, on the image's grid of blocks, so the table does not
/// depend on the strips. The same operations in the same order as
/// [`csum_row`]. On the calling thread: a strip's additions cost less than a
/// parallel loop.
fn make_csums(old: &Rows<'_, f64>, rows: &mut [&mut [f64]], a: usize, block: usize) {
    for k in 0..rows.len() {
        if (a + k) % block == 0 {
            continue;
        }
        match k {
            0 => csum_add(old.get(a - 1), rows[0]),
            _ => {
                let (above, below) = rows.split_at_mut(k);
                csum_add(above[k - 1], below[0]);
            }
        }
    }
}

impl Back {
    /// Base rows up to `target`: the vertical gather of the horizontal pass
    /// `hpass`.
    pub(super) fn base_rows(
        &mut self,
        shape: &Shape,
        rules: &Rules,
        hpass: &Rows<'_, f64>,
        target: usize,
    ) {
        let base_rows = &mut self.base_rows;
        let a = base_rows.end();
        if target <= a {
            return;
        }
        for _ in a..target {
            base_rows.push_stale(0.0); // every value is written below
        }
        let region = crate::trace::region("base rows");
        base_rows
            .range_mut(a, target)
            .into_par_iter()
            .enumerate()
            .for_each_init(Vec::new, |taps, (k, row)| {
                let _task = region.task("base rows");
                base_row(shape, rules, hpass, a + k, row, taps);
            });
    }

    /// The coarse grids' share of the final accumulator rows `a..b`: first
    /// the 4x grid's into the 2x rows they read for the first time, then
    /// the 2x grid's into them ([`coarse::tent_row`]).
    pub(super) fn coarse_share(&mut self, w: usize, a: usize, b: usize) {
        let four = self.coarse_rows_read(a, b);
        let Back { acc, c2, c4, .. } = self;
        let region = crate::trace::region("upsample");
        if let Some((f, l)) = four {
            upsample(c4, w.div_ceil(2), c2.acc.range_mut(f, l), f, &region);
        }
        upsample(c2, w, acc.range_mut(a, b), a, &region);
    }
}

/// Rows `first..` of a grid `n_fine` columns a channel take `coarse`'s
/// share, a task a row of `region`.
fn upsample(
    coarse: &CoarseGrid,
    n_fine: usize,
    rows: Vec<&mut [f64]>,
    first: usize,
    region: &crate::trace::Span,
) {
    rows.into_par_iter()
        .enumerate()
        .for_each_init(<[Vec<f64>; 2]>::default, |up, (k, row)| {
            let _task = region.task("upsample");
            coarse::tent_row(coarse, n_fine, first + k, row, up);
        });
}

/// Box luminance row `y` (`core`: the task's scratch): the mean of each
/// pixel's samples in f64, the emission guide's light taken out, stored in
/// f32 (`LumRows`) with `pad` mirrored pixels each side.
fn ybox_row(
    shape: &Shape,
    rules: &Rules,
    input: &RowWindow<f32>,
    y: usize,
    row: &mut [f32],
    core: &mut Vec<f64>,
) {
    let Shape {
        grid,
        w,
        pad,
        inv_s2,
        ..
    } = *shape;
    let (s, in_w) = (grid.s, grid.in_w);
    core.clear();
    core.resize(w, 0.0);
    for j in y * s..(y + 1) * s {
        let row = input.get(j);
        rules.lum.box_row_add(row, in_w, s, core);
        // The emission guide's light is not tested.
        if let Some(em) = &rules.emission {
            for (px, v) in core.iter_mut().enumerate() {
                for i in px * s..(px + 1) * s {
                    *v -= em.luminance(row, in_w, i);
                }
            }
        }
    }
    core.iter_mut().for_each(|v| *v *= inv_s2);
    // --edge pad: a partial pixel's mean is over its real samples.
    if let Some((nx, ny)) = &rules.real_counts {
        for (v, &n) in core.iter_mut().zip(nx) {
            let real = n * ny[y];
            if real != s * s {
                *v *= (s * s) as f64 / real as f64;
            }
        }
    }
    for (o, &v) in row[pad..pad + w].iter_mut().zip(core.iter()) {
        *o = v as f32;
    }
    for i in 0..pad {
        row[i] = row[pad + mirror(i as i64 - pad as i64, w)];
        row[pad + w + i] = row[pad + mirror((w + i) as i64, w)];
    }
}

/// Base row `y`: the vertical gather of the horizontal pass (`taps`: the
/// task's scratch).
fn base_row(
    shape: &Shape,
    rules: &Rules,
    hpass: &Rows<'_, f64>,
    y: usize,
    row: &mut [f64],
    taps: &mut Vec<f64>,
) {
    let Shape {
        grid,
        w,
        h,
        nch,
        inv_s2,
        ..
    } = *shape;
    let s = grid.s;
    let j0 = rules.base.gather(y, h, grid.in_h, taps);
    for c in 0..nch {
        let dst = &mut row[c * w..(c + 1) * w];
        if rules.modes[c] == ChannelMode::Nearest {
            // The centre row's centre sample (horizontal pass).
            dst.copy_from_slice(&hpass.get(y * s + (s - 1) / 2)[c * w..(c + 1) * w]);
            continue;
        }
        dst.iter_mut().for_each(|v| *v = -0.0);
        for (t, &wt) in taps.iter().enumerate() {
            let src = &hpass.get(j0 + t)[c * w..(c + 1) * w];
            for (d, &v) in dst.iter_mut().zip(src) {
                *d += wt * v;
            }
        }
        dst.iter_mut().for_each(|v| *v *= inv_s2);
    }
}
