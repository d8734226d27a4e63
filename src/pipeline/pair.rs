//! Two sources of the same rows read side by side: each strip holds the
//! first's channels, then the second's (`epfilt restore`'s energy image and
//! denoiser's output).

use super::{Decoder, ReadAhead, Source, Strip};
use crate::error::{Error, Result};

/// Where a channel of a pair's second half comes from: a channel of the
/// second source, or one of the first's again (`restore`: a channel the
/// denoiser did not write, taken as the energy image has it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pick {
    /// This channel of the first source.
    First(usize),
    /// This channel of the second.
    Second(usize),
}

/// Sources `a` and `b`, `w` samples wide, of `na` and `nb` channels.
pub struct Pair<A, B> {
    a: A,
    b: B,
    w: usize,
    na: usize,
    nb: usize,
    /// The second half's channels.
    picks: Vec<Pick>,
    /// Buffers of strips the run is done with, to fill again (a new buffer
    /// is faulted in page by page).
    recycled: Option<crossbeam_channel::Receiver<Vec<f32>>>,
}

impl<A: Source, B: Source> Pair<A, B> {
    /// The pair of `a` (`na` channels) and `b` (`nb`), `w` samples wide,
    /// each strip's second half made of `picks`.
    pub fn new(a: A, b: B, w: usize, (na, nb): (usize, usize), picks: Vec<Pick>) -> Self {
        Pair {
            a,
            b,
            w,
            na,
            nb,
            picks,
            recycled: None,
        }
    }
}

impl<A: Source, B: Source> Source for Pair<A, B> {
    fn next_strip(&mut self, max_rows: usize) -> Result<Option<Strip>> {
        let (sa, sb) = (self.a.next_strip(max_rows)?, self.b.next_strip(max_rows)?);
        let (sa, sb) = match (sa, sb) {
            (None, None) => return Ok(None),
            (Some(a), Some(b)) if a.y0 == b.y0 && a.rows == b.rows => (a, b),
            _ => {
                return Err(Error::Internal(
                    "the two inputs gave different rows (source bug)".into(),
                ))
            }
        };
        let (ra, rb) = (self.na * self.w, self.nb * self.w);
        if sa.data.len() != sa.rows * ra || sb.data.len() != sb.rows * rb {
            return Err(Error::Internal(
                "a strip of the wrong size (source bug)".into(),
            ));
        }
        let w = self.w;
        let mut data = (self.recycled.as_ref())
            .and_then(|r| r.try_recv().ok())
            .unwrap_or_default();
        data.clear();
        data.reserve(sa.rows * (ra + self.picks.len() * w));
        for (x, y) in sa.data.chunks_exact(ra).zip(sb.data.chunks_exact(rb)) {
            data.extend_from_slice(x);
            for p in &self.picks {
                data.extend_from_slice(match *p {
                    Pick::First(i) => &x[i * w..(i + 1) * w],
                    Pick::Second(j) => &y[j * w..(j + 1) * w],
                });
            }
        }
        Ok(Some(Strip {
            y0: sa.y0,
            rows: sa.rows,
            data,
        }))
    }

    fn decoder<'s>(
        &mut self,
        ahead: &ReadAhead<'_>,
        pool: &'s rayon::ThreadPool,
    ) -> Option<Decoder<'s>>
    where
        Self: 's,
    {
        // Each source decodes ahead on its own thread; the strips' buffers
        // are the pair's, so neither gets them back: the pair fills them
        // again.
        self.recycled = ahead.recycled.clone();
        let own = ReadAhead {
            strip_rows: ahead.strip_rows,
            recycled: None,
            window_blocks: ahead.window_blocks,
        };
        let da = self.a.decoder(&own, pool);
        let db = self.b.decoder(&own, pool);
        match (da, db) {
            (None, None) => None,
            (da, db) => Some(Box::new(move || {
                std::thread::scope(|s| {
                    if let Some(da) = da {
                        s.spawn(da);
                    }
                    if let Some(db) = db {
                        db();
                    }
                })
            })),
        }
    }

    fn wait_ready(&mut self) {
        self.a.wait_ready();
        self.b.wait_ready();
    }
}
