//! ep-box's passes (§5.1) as a rule over a band of pixels: which noisy
//! pixels are settled in which pass, and against what neighbour mean.
//!
//! Converged pixels are settled from the start (pass 0). Pass `k` settles
//! each noisy pixel with at least one of its 8 neighbours settled before pass
//! `k`; its neighbour mean is over those neighbours' references: a converged
//! pixel's luminance, a settled pixel's luminance less the excess it gave
//! away. Pixels settled in the same pass do not see each other, so the result
//! does not depend on the order they are visited in.

/// How a pass settles one pixel: given the band row `r`, column `x`, the
/// pass `k` (from 1) and the mean of its settled neighbours, the excess it
/// gives away (0: none).
pub trait Settle: FnMut(usize, usize, u8, f64) -> f64 {}
impl<F: FnMut(usize, usize, u8, f64) -> f64> Settle for F {}

/// Run up to `passes` passes (at most 254) over a band of `bh` rows of `w`
/// pixels: `noisy(r)` and `lum(r)` are row `r`'s flags (non-zero: noisy) and
/// luminance. `settle` is called once for each pixel a pass reaches, in
/// pass order and, within a pass, in row-major order. Returns the pixels no
/// pass reached (`r * w + x`), in row-major order.
pub fn chebyshev_passes<'a>(
    (w, bh): (usize, usize),
    noisy: impl Fn(usize) -> &'a [u8],
    lum: impl Fn(usize) -> &'a [f64],
    passes: usize,
    mut settle: impl Settle,
) -> Vec<u32> {
    const UNSET: u8 = u8::MAX;
    // A converged pixel's reference is its luminance, read where it is; a
    // noisy one's is kept beside its index (noisy pixels are few: a band's
    // copy of every reference would cost 8 bytes a pixel and task).
    let mut dist = vec![0u8; bh * w];
    let mut pending: Vec<u32> = Vec::new();
    let mut refs: Vec<f64> = Vec::new();
    for r in 0..bh {
        let (fl, yl) = (noisy(r), lum(r));
        for x in 0..w {
            if fl[x] != 0 {
                dist[r * w + x] = UNSET;
                pending.push((r * w + x) as u32);
                refs.push(yl[x]);
            }
        }
    }
    let at: Vec<u32> = pending.clone();
    let mut next = Vec::with_capacity(pending.len());
    for k in 1..=passes.min(UNSET as usize - 1) as u8 {
        if pending.is_empty() {
            break;
        }
        next.clear();
        for &i in &pending {
            let i = i as usize;
            let (r, x) = (i / w, i % w);
            let (mut count, mut sum) = (0u32, 0.0f64);
            for rr in r.saturating_sub(1)..(r + 2).min(bh) {
                let xa = x.saturating_sub(1);
                let row = &lum(rr)[xa..(x + 2).min(w)];
                for (j, &y) in (rr * w + xa..).zip(row) {
                    if j != i && dist[j] < k {
                        count += 1;
                        sum += match dist[j] {
                            0 => y,
                            _ => refs[at.partition_point(|&a| (a as usize) < j)],
                        };
                    }
                }
            }
            if count == 0 {
                next.push(i as u32);
                continue;
            }
            dist[i] = k;
            let excess = settle(r, x, k, sum / count as f64);
            if excess != 0.0 {
                refs[at.partition_point(|&a| (a as usize) < i)] -= excess;
            }
        }
        std::mem::swap(&mut pending, &mut next);
    }
    pending
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One call of `settle`: row, column, pass, neighbour mean.
    type Call = (usize, usize, u8, f64);

    /// Settles every pixel with what it is given, recording the calls.
    fn run(w: usize, flags: &[u8], lum: &[f64], passes: usize) -> (Vec<Call>, Vec<u32>) {
        let bh = flags.len() / w;
        let mut calls = Vec::new();
        let left = chebyshev_passes(
            (w, bh),
            |r| &flags[r * w..(r + 1) * w],
            |r| &lum[r * w..(r + 1) * w],
            passes,
            |r, x, k, mean| {
                calls.push((r, x, k, mean));
                // Give away everything above the mean.
                lum[r * w + x] - mean
            },
        );
        (calls, left)
    }

    #[test]
    fn a_lone_noisy_pixel_is_settled_in_pass_one_against_its_eight_neighbours() {
        let w = 3;
        let flags = [0, 0, 0, 0, 1, 0, 0, 0, 0];
        let lum = [1.0, 2.0, 3.0, 4.0, 100.0, 6.0, 7.0, 8.0, 9.0];
        let (calls, left) = run(w, &flags, &lum, 4);
        assert_eq!(calls, vec![(1, 1, 1, 40.0 / 8.0)]);
        assert!(left.is_empty());
    }

    #[test]
    fn a_block_of_noise_is_settled_from_its_rim_inwards_with_settled_references() {
        // 5x5, the centre 3x3 noisy: the ring of 8 in pass 1, the centre in
        // pass 2 against the ring's references (their luminance less what
        // they gave away: the mean they were settled against).
        let w = 5;
        let mut flags = [0u8; 25];
        let mut lum = [1.0f64; 25];
        for r in 1..4 {
            for x in 1..4 {
                flags[r * w + x] = 1;
                lum[r * w + x] = 10.0;
            }
        }
        let (calls, left) = run(w, &flags, &lum, 4);
        assert!(left.is_empty());
        assert_eq!(calls.len(), 9);
        assert!(calls[..8].iter().all(|c| c.2 == 1 && c.3 == 1.0));
        assert_eq!(calls[8], (2, 2, 2, 1.0));
        // Row-major within the pass.
        let order: Vec<(usize, usize)> = calls[..8].iter().map(|c| (c.0, c.1)).collect();
        let mut sorted = order.clone();
        sorted.sort();
        assert_eq!(order, sorted);
    }

    #[test]
    fn pixels_beyond_the_passes_are_left_unresolved() {
        let w = 5;
        let mut flags = [1u8; 25];
        flags[0] = 0;
        let lum = [1.0f64; 25];
        let (calls, left) = run(w, &flags, &lum, 2);
        // Chebyshev distance to (0, 0) at most 2: 8 pixels; 16 left.
        assert_eq!(calls.len(), 8);
        assert_eq!(left.len(), 16);
        assert!(calls.iter().all(|&(r, x, k, _)| r.max(x) as u8 == k));
    }
}
