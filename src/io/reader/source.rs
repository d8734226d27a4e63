//! The strip source of an open EXR: block rows decoded in parallel, a
//! bounded read-ahead, rows handed to the pipeline in order.

use super::*;

use crate::pipeline::read_ahead_blocks;
pub use crate::pipeline::READ_AHEAD_BYTES;

/// A [`Source`] over an [`ExrInput`].
pub struct ExrSource<'a> {
    pub(super) input: &'a ExrInput,
    pub(super) next_row: usize,
    /// Decoded rows; those before `head` (values) are handed over.
    pub(super) buf: Vec<f32>,
    pub(super) head: usize,
    pub(super) buf_y0: usize,
    pub(super) row_len: usize,
    /// Byte range of the file consumed (and released) so far.
    pub(super) released: Option<(usize, usize)>,
    /// The batches a decoder thread decodes ahead ([`Source::decoder`]).
    pub(super) ahead: Option<Ahead>,
}

/// Batches the reader holds when it decodes ahead: one handed over while the
/// next decodes (the memory estimate's `READ_AHEAD_BATCHES`).
pub const AHEAD_BUFFERS: usize = crate::pipeline::READ_AHEAD_BATCHES as usize;

/// The reader's ends of the channels to its decoder thread.
pub(super) struct Ahead {
    /// Decoded batches, in order (an error ends them).
    full: crossbeam_channel::Receiver<Result<Batch>>,
    /// Buffers handed over, back to the decoder, with the trace id of the
    /// segment that gave each back.
    free: crossbeam_channel::Sender<(Vec<f32>, u64)>,
    /// A batch received by [`Source::wait_ready`], not yet taken.
    next: Option<Result<Batch>>,
}

/// One decoded batch of block rows.
pub(super) struct Batch {
    buf: Vec<f32>,
    /// The trace id of the segment that decoded it.
    decoded_by: u64,
}

/// The block rows of the batch that starts at block row `from`: whole block
/// rows until the batch covers `max_rows` rows and holds at least
/// [`read_ahead_blocks`] blocks (READ_AHEAD_BYTES of blocks, two chunks, and at
/// least READ_AHEAD_MIN_BLOCKS where blocks are large) whatever the thread
/// count: several strips' blocks decode in parallel (two per worker made the
/// reader the critical path: the model's T∞ 0.57 -> 0.31 s on the 6144x6144
/// bench), memory does not grow with the threads, and a 1-thread run cuts the
/// work as a 16-thread one.
fn batch_end(input: &ExrInput, from: usize, max_rows: usize) -> usize {
    let want_chunks = read_ahead_blocks(input.block_bytes()) as usize;
    let (mut end, mut chunks, mut rows) = (from, 0, 0);
    while end < input.rows.len() && (chunks < want_chunks || rows < max_rows) {
        chunks += input.rows[end].chunks.len();
        rows += input.rows[end].y1 - input.rows[end].y0;
        end += 1;
    }
    end
}

/// Decode the block rows `batch` into `buf` (`row_len` values a row), and
/// release the file's pages they were read from (`released`: the range
/// released so far).
fn decode_batch(
    input: &ExrInput,
    batch: &[BlockRow],
    buf: &mut Vec<f32>,
    row_len: usize,
    released: &mut Option<(usize, usize)>,
) -> Result<()> {
    let (w, _) = input.size();
    let nch = input.selected.len();
    let total: usize = batch.iter().map(|r| r.y1 - r.y0).sum();
    // Every value of the batch is written by its blocks (they cover its
    // rows, as the offset table was checked to say), so the buffer keeps its
    // old values rather than being cleared (a pass over the whole image, on
    // the reader's critical path). It grows exactly: doubling would hold up
    // to twice the read-ahead.
    let len = total * row_len;
    buf.truncate(len);
    buf.reserve_exact(len - buf.len());
    buf.resize(len, 0.0);
    let mut span = (usize::MAX, 0usize);
    if batch.iter().all(|r| r.chunks.len() == 1) {
        // Scan lines: each block decodes straight into its rows.
        let mut slices = Vec::with_capacity(batch.len());
        let mut rest = &mut buf[..];
        for r in batch {
            let (head, tail) = rest.split_at_mut((r.y1 - r.y0) * row_len);
            slices.push(head);
            rest = tail;
        }
        let region = crate::trace::region("decode");
        let spans: Vec<Result<Landed>> = batch
            .par_iter()
            .zip(slices.into_par_iter())
            .map(|(r, dst)| {
                let _task = region.task("decode");
                let (offset, expected) = r.chunks[0];
                input.decode_chunk(
                    offset,
                    expected,
                    r.y1 - r.y0,
                    Place::InPlace { dst, width: w },
                )
            })
            .collect();
        for sp in spans {
            let (a, b) = sp?.bytes;
            span = (span.0.min(a), span.1.max(b));
        }
    } else {
        // Tiles: decode each into its own buffer, then place it.
        let region = crate::trace::region("decode tiles");
        let decoded: Vec<Result<Vec<Decoded>>> = batch
            .par_iter()
            .map(|r| {
                let _task = region.task("decode tiles");
                input.decode_row(r)
            })
            .collect();
        let mut row_base = 0;
        for (row, blocks) in batch.iter().zip(decoded) {
            let lines = row.y1 - row.y0;
            for Decoded {
                x0,
                width: bw,
                rows: data,
                bytes: (a, b),
            } in blocks?
            {
                span = (span.0.min(a), span.1.max(b));
                if x0 + bw > w {
                    return Err(invalid(&input.path, "a block lies outside the data window"));
                }
                for line in 0..lines {
                    for k in 0..nch {
                        let src = &data[(line * nch + k) * bw..][..bw];
                        let at = row_base + line * row_len + k * w + x0;
                        buf[at..at + bw].copy_from_slice(src);
                    }
                }
            }
            row_base += lines * row_len;
        }
    }
    if span.0 < span.1 {
        // Grow the released region contiguously, so the pages that
        // straddle two batches are dropped too.
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
    Ok(())
}

/// Rows of an input file, whatever its format.
pub enum InputSource<'a> {
    /// OpenEXR blocks.
    Exr(ExrSource<'a>),
    /// Radiance scanlines.
    Rgbe(crate::io::rgbe::RgbeSource<'a>),
}

impl Source for InputSource<'_> {
    fn next_strip(&mut self, max_rows: usize) -> Result<Option<Strip>> {
        match self {
            InputSource::Exr(s) => s.next_strip(max_rows),
            InputSource::Rgbe(s) => s.next_strip(max_rows),
        }
    }

    fn decoder<'s>(&mut self, max_rows: usize, pool: &'s rayon::ThreadPool) -> Option<Decoder<'s>>
    where
        Self: 's,
    {
        match self {
            InputSource::Exr(s) => s.decoder(max_rows, pool),
            InputSource::Rgbe(_) => None,
        }
    }

    fn wait_ready(&mut self) {
        if let InputSource::Exr(s) = self {
            s.wait_ready();
        }
    }
}

impl Source for ExrSource<'_> {
    fn next_strip(&mut self, max_rows: usize) -> Result<Option<Strip>> {
        let h = self.input.size().1;
        let buffered = |s: &Self| (s.buf.len() - s.head) / s.row_len;
        if buffered(self) == 0 {
            if let Some(ahead) = self.ahead.as_mut() {
                // The batch `wait_ready` waited for (or waited for here;
                // none: the decoder has ended).
                match ahead.next.take().or_else(|| ahead.full.recv().ok()) {
                    Some(Ok(batch)) => {
                        crate::trace::wait_for(batch.decoded_by);
                        self.buf = batch.buf;
                        self.head = 0;
                    }
                    Some(Err(e)) => return Err(e),
                    None => {}
                }
            } else {
                // A batch is decoded only once the last is handed over (its
                // last strip may be short): the buffer is then reused as it
                // is, never moved or grown around rows still held.
                while buffered(self) == 0 && self.next_row < self.input.rows.len() {
                    let end = batch_end(self.input, self.next_row, max_rows);
                    let batch = &self.input.rows[self.next_row..end];
                    self.head = 0;
                    decode_batch(
                        self.input,
                        batch,
                        &mut self.buf,
                        self.row_len,
                        &mut self.released,
                    )?;
                    self.next_row = end;
                }
            }
        }
        let n = max_rows.min(buffered(self));
        if n == 0 {
            return if self.buf_y0 >= h {
                Ok(None)
            } else {
                Err(invalid(&self.input.path, "missing rows"))
            };
        }
        // Hand over a copy of the front rows, exactly as large as they are
        // (handing over the buffer itself would send its whole read-ahead
        // capacity down the pipeline with every strip, and draining it would
        // move the rest at every strip).
        let k = n * self.row_len;
        let data = self.buf[self.head..self.head + k].to_vec();
        self.head += k;
        let strip = Strip {
            y0: self.buf_y0,
            rows: n,
            data,
        };
        self.buf_y0 += n;
        if let Some(ahead) = &self.ahead {
            if buffered(self) == 0 {
                // Handed over: the buffer goes back for the batch after
                // next (a decoder that has ended drops it).
                let buf = std::mem::take(&mut self.buf);
                self.head = 0;
                let _ = ahead.free.send((buf, crate::trace::current_segment()));
            }
        }
        Ok(Some(strip))
    }

    /// The batches decoded on a thread of their own: [`AHEAD_BUFFERS`]
    /// buffers go round, so that one batch decodes while the one before it
    /// is handed over (and memory stays at two batches).
    fn decoder<'s>(&mut self, max_rows: usize, pool: &'s rayon::ThreadPool) -> Option<Decoder<'s>>
    where
        Self: 's,
    {
        if self.ahead.is_some() || self.buf.len() > self.head {
            return None;
        }
        let (full_tx, full) = crossbeam_channel::bounded(1);
        let (free, free_rx) = crossbeam_channel::bounded(AHEAD_BUFFERS);
        for _ in 0..AHEAD_BUFFERS {
            free.send((Vec::new(), 0)).ok()?;
        }
        self.ahead = Some(Ahead {
            full,
            free,
            next: None,
        });
        let input = self.input;
        let row_len = self.row_len;
        let mut next_row = self.next_row;
        let mut released = self.released.take();
        Some(Box::new(move || {
            let mut b = 0;
            while next_row < input.rows.len() {
                let Ok((mut buf, freed_by)) = free_rx.recv() else {
                    return;
                };
                let end = batch_end(input, next_row, max_rows);
                let mut decoded_by = 0;
                let r = pool.install(|| {
                    let segment = crate::trace::segment("decode", b, &[freed_by]);
                    decoded_by = segment.id();
                    let batch = &input.rows[next_row..end];
                    decode_batch(input, batch, &mut buf, row_len, &mut released)
                });
                let failed = r.is_err();
                let sent = full_tx.send(r.map(|()| Batch { buf, decoded_by }));
                if sent.is_err() || failed {
                    return;
                }
                next_row = end;
                b += 1;
            }
        }))
    }

    fn wait_ready(&mut self) {
        let empty = self.buf.len() == self.head;
        if let Some(ahead) = self.ahead.as_mut() {
            if empty && ahead.next.is_none() {
                ahead.next = ahead.full.recv().ok();
            }
        }
    }
}
