//! The schedule of every stage: each declares its passes (the pixel
//! stage's rules, the Gaussian stage, the order foils, restore's second
//! pass), and these pure functions of what each pass reads and what each
//! has made say how far each may go and which rows may leave.
//!
//! A pass reads earlier passes, each the rows either side of its own row
//! (pass 0: the input). It may make row `y` once every pass it reads has
//! made the rows within its reach of `y` (all of them at the image's end),
//! and a pass's rows may go once no pass that reads them will read them
//! again. The rows a chain of reads reaches past an output row is the
//! stage's lag, so the halo follows from the same declarations.

/// What a pass reads: for each earlier pass it reads (0: the input), that
/// pass and the rows either side of its own row it reads there.
pub type Reads = Vec<(usize, usize)>;

/// Rows past a row of the last pass of `passes` that it reads of the
/// input, through every pass.
pub fn lag(passes: &[Reads]) -> usize {
    let mut lag = vec![0];
    for reads in passes {
        let l = reads.iter().map(|&(j, r)| lag[j] + r).max().unwrap_or(0);
        lag.push(l);
    }
    lag.last().copied().unwrap_or(0)
}

/// The rows each pass of an image `h` rows high may make, the first passes
/// having made `made` (`made[0]`: the input rows in): each later pass as
/// far as what it reads allows, the last no further than `last`.
pub fn forward(passes: &[Reads], h: usize, made: &[usize], last: usize) -> Vec<usize> {
    let mut t = made.to_vec();
    for reads in &passes[made.len() - 1..] {
        let after = |&(j, r): &(usize, usize)| match t[j] {
            y if y == h => h,
            y => y.saturating_sub(r),
        };
        let y = reads.iter().map(after).min().unwrap_or(h);
        t.push(y);
    }
    let n = passes.len();
    t[n] = t[n].min(last);
    t
}

/// [`forward`]'s targets `t`, each pass but the input and the last held to
/// what the passes that read it need: what waits is held across the whole
/// width.
pub fn hold_back(passes: &[Reads], h: usize, t: &mut [usize]) {
    let n = passes.len();
    for i in (1..n).rev() {
        let mut need = 0;
        for (reads, &tk) in passes[i..].iter().zip(&t[i + 1..]) {
            for &(j, r) in reads {
                if j == i {
                    need = need.max((tk + r).min(h));
                }
            }
        }
        t[i] = t[i].min(need);
    }
}

/// The first row of pass `j` that one of `passes` will still read, each
/// having made its rows below `done` (`done[k]` for pass `k`).
pub fn read_from(passes: &[Reads], done: &[usize], j: usize) -> usize {
    (passes.iter().zip(&done[1..]))
        .flat_map(|(reads, &done)| {
            (reads.iter())
                .filter(move |&&(i, _)| i == j)
                .map(move |&(_, r)| done.saturating_sub(r))
        })
        .min()
        .unwrap_or(usize::MAX)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Luminance reads the input; the flags the luminance 2 rows either
    /// side; the treatment the flags and the luminance 2 rows, the input
    /// `reach`.
    fn passes(reach: usize) -> Vec<Reads> {
        vec![
            vec![(0, 0)],
            vec![(1, 2), (0, 0)],
            vec![(2, 2), (1, 2), (0, reach)],
        ]
    }

    #[test]
    fn the_lag_is_the_longest_chain_of_reaches() {
        assert_eq!(lag(&passes(0)), 4);
        assert_eq!(lag(&passes(9)), 9);
        assert_eq!(lag(&[]), 0);
    }

    #[test]
    fn a_pass_goes_as_far_as_what_it_reads_allows() {
        let p = passes(9);
        // 40 of 100 rows in: the luminance 40, the flags 38, the treatment
        // 31 (the input's reach).
        assert_eq!(forward(&p, 100, &[40], usize::MAX), [40, 40, 38, 31]);
        assert_eq!(forward(&p, 100, &[40], 20), [40, 40, 38, 20]);
        // From passes already made: the flags as far as the luminance made.
        assert_eq!(forward(&p, 100, &[40, 30], usize::MAX), [40, 30, 28, 26]);
        // Every row in: every pass may finish.
        assert_eq!(forward(&p, 100, &[100], usize::MAX), [100; 4]);
    }

    #[test]
    fn held_back_a_pass_goes_only_as_far_as_the_passes_that_read_it_need() {
        let p = passes(9);
        // The treatment reaches 31 (its receivers), the flags 33, the
        // luminance 35, though 40 and 38 could be made.
        let mut t = forward(&p, 100, &[40], usize::MAX);
        hold_back(&p, 100, &mut t);
        assert_eq!(t, [40, 35, 33, 31]);
        // The treatment held to 20: the others follow it.
        let mut t = forward(&p, 100, &[40], 20);
        hold_back(&p, 100, &mut t);
        assert_eq!(t, [40, 24, 22, 20]);
        // Rows are read no more below the lowest a reader will read.
        let done = [40, 35, 33, 31];
        assert_eq!(read_from(&p, &done, 0), 22);
        assert_eq!(read_from(&p, &done, 1), 29);
        assert_eq!(read_from(&p, &done, 2), 29);
        assert_eq!(read_from(&p, &done, 3), usize::MAX);
    }
}
