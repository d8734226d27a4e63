//! One block row of an open EXR decoded into place, and the file's pages
//! released behind it: shared by the strip source and its decoder thread.

use super::blocks::invalid;
use super::{BlockRow, Decoded, ExrInput, Place};
use crate::error::Result;

/// Decode block row `r` into `dst` (its rows, `row_len` values each):
/// scan lines straight into place, tiles each into its own buffer, then
/// placed. Returns the file's byte range it was read from.
pub(super) fn decode_rows_into(
    input: &ExrInput,
    r: &BlockRow,
    dst: &mut [f32],
    row_len: usize,
) -> Result<(usize, usize)> {
    let (w, _) = input.size();
    let lines = r.y1 - r.y0;
    if let [(offset, expected)] = r.chunks[..] {
        let place = Place::InPlace { dst, width: w };
        return Ok(input.decode_chunk(offset, expected, lines, place)?.bytes);
    }
    let nch = input.selected.len();
    let mut span = (usize::MAX, 0usize);
    for Decoded {
        x0,
        width: bw,
        rows: data,
        bytes: (a, b),
    } in input.decode_row(r)?
    {
        span = (span.0.min(a), span.1.max(b));
        if x0 + bw > w {
            return Err(invalid(&input.path, "a block lies outside the data window"));
        }
        for line in 0..lines {
            for k in 0..nch {
                let src = &data[(line * nch + k) * bw..][..bw];
                let at = line * row_len + k * w + x0;
                dst[at..at + bw].copy_from_slice(src);
            }
        }
    }
    Ok(span)
}

/// Release the file's pages of `span` (consumed), growing the released
/// region `released` contiguously, so the pages that straddle two spans
/// are dropped too.
pub(super) fn release_span(
    input: &ExrInput,
    released: &mut Option<(usize, usize)>,
    span: (usize, usize),
) {
    if span.0 >= span.1 {
        return;
    }
    let (lo, hi) = match *released {
        None => span,
        Some((lo, hi)) => (lo.min(span.0), hi.max(span.1)),
    };
    let from = match *released {
        Some((plo, phi)) if span.0 >= plo => (phi.min(span.0)).saturating_sub(4096),
        _ => lo,
    };
    let to = match *released {
        Some((plo, _)) if span.0 < plo => (plo + 4096).min(hi),
        _ => hi,
    };
    input.map.release(from, to);
    *released = Some((lo, hi));
}
