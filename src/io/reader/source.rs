//! The strip source of an open EXR: block rows decoded in parallel, a
//! bounded read-ahead, rows handed to the pipeline in order.

use super::{invalid, BlockRow, Decoder, ExrInput, Source, Strip};
use crate::error::Result;
use rayon::iter::{
    IndexedParallelIterator, IntoParallelIterator, IntoParallelRefIterator, ParallelIterator,
};

use super::decode::{decode_rows_into, release_span};
pub use crate::pipeline::READ_AHEAD_BYTES;
use crate::pipeline::{read_ahead_blocks, ReadAhead};

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
    /// The block rows a decoder thread decodes ahead ([`Source::decoder`]).
    pub(super) ahead: Option<super::ahead::Ahead>,
    /// Blocks a batch decoded without a decoder thread holds at the least
    /// (0: [`read_ahead_blocks`]).
    pub(super) batch_blocks: usize,
    /// A strip's buffer given back, for the next strip decoded without a
    /// decoder thread.
    pub(super) spare: Vec<f32>,
}

/// The block rows of the batch that starts at block row `from`: whole block
/// rows until the batch covers `max_rows` rows and holds at least `blocks`
/// blocks (0: [`read_ahead_blocks`], READ_AHEAD_BYTES of blocks, two chunks
/// at the least) whatever the thread count: several strips' blocks decode in
/// parallel (two per worker made the reader the critical path), memory does
/// not grow with the threads, and a 1-thread run cuts the work as a
/// 16-thread one.
fn batch_end(input: &ExrInput, from: usize, max_rows: usize, blocks: usize) -> usize {
    let want_chunks = match blocks {
        0 => read_ahead_blocks(input.block_bytes()) as usize,
        n => n,
    };
    let (mut end, mut chunks, mut rows) = (from, 0, 0);
    while end < input.rows.len() && (chunks < want_chunks || rows < max_rows) {
        chunks += input.rows[end].chunks.len();
        rows += input.rows[end].y1 - input.rows[end].y0;
        end += 1;
    }
    end
}

/// Decode the block rows `batch` into `buf` (`row_len` values a row), in
/// parallel, and release the file's pages they were read from.
fn decode_batch(
    input: &ExrInput,
    batch: &[BlockRow],
    buf: &mut Vec<f32>,
    row_len: usize,
    released: &mut Option<(usize, usize)>,
) -> Result<()> {
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
    let mut slices = Vec::with_capacity(batch.len());
    let mut rest = &mut buf[..];
    for r in batch {
        let (head, tail) = rest.split_at_mut((r.y1 - r.y0) * row_len);
        slices.push(head);
        rest = tail;
    }
    let region = crate::trace::region("decode");
    let spans: Vec<Result<(usize, usize)>> = batch
        .par_iter()
        .zip(slices.into_par_iter())
        .map(|(r, dst)| {
            let _task = region.task("decode");
            decode_rows_into(input, r, dst, row_len)
        })
        .collect();
    for sp in spans {
        release_span(input, released, sp?);
    }
    Ok(())
}

/// Rows of an input file, whatever its format.
pub enum InputSource<'a> {
    /// OpenEXR blocks.
    Exr(ExrSource<'a>),
    /// Radiance scanlines.
    Rgbe(crate::io::rgbe::RgbeSource<'a>),
    /// A portable float map's rows.
    Pfm(crate::io::pfm::PfmSource<'a>),
}

impl InputSource<'_> {
    /// Decode batches of at least `blocks` blocks where no decoder thread
    /// decodes ahead (0: [`read_ahead_blocks`]): a first pass over the input
    /// holds no more than the run's window of blocks.
    pub fn with_batch_blocks(mut self, blocks: usize) -> Self {
        if let InputSource::Exr(s) = &mut self {
            s.batch_blocks = blocks;
        }
        self
    }
}

impl Source for InputSource<'_> {
    fn next_strip(&mut self, max_rows: usize) -> Result<Option<Strip>> {
        match self {
            InputSource::Exr(s) => s.next_strip(max_rows),
            InputSource::Rgbe(s) => s.next_strip(max_rows),
            InputSource::Pfm(s) => s.next_strip(max_rows),
        }
    }

    fn decoder<'s>(
        &mut self,
        ahead: &ReadAhead<'_>,
        pool: &'s rayon::ThreadPool,
    ) -> Option<Decoder<'s>>
    where
        Self: 's,
    {
        match self {
            InputSource::Exr(s) => s.decoder(ahead, pool),
            InputSource::Rgbe(_) | InputSource::Pfm(_) => None,
        }
    }

    fn wait_ready(&mut self) {
        if let InputSource::Exr(s) = self {
            s.wait_ready();
        }
    }

    fn give_back(&mut self, buf: Vec<f32>) {
        if let InputSource::Exr(s) = self {
            s.give_back(buf);
        }
    }
}

impl Source for ExrSource<'_> {
    fn next_strip(&mut self, max_rows: usize) -> Result<Option<Strip>> {
        let h = self.input.size().1;
        let buffered = |s: &Self| (s.buf.len() - s.head) / s.row_len;
        let taken = if let Some(ahead) = self.ahead.as_mut() {
            ahead.take(self.input, max_rows, self.row_len)?
        } else {
            // A batch is decoded only once the last is handed over (its
            // last strip may be short): the buffer is then reused as it is,
            // never moved or grown around rows still held.
            while buffered(self) == 0 && self.next_row < self.input.rows.len() {
                let end = batch_end(self.input, self.next_row, max_rows, self.batch_blocks);
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
            // Hand over a copy of the front rows, exactly as large as they
            // are (handing over the buffer itself would send its whole
            // read-ahead capacity down the pipeline with every strip, and
            // draining it would move the rest at every strip).
            let n = max_rows.min(buffered(self));
            let k = n * self.row_len;
            let mut data = std::mem::take(&mut self.spare);
            data.clear();
            data.extend_from_slice(&self.buf[self.head..self.head + k]);
            self.head += k;
            (n > 0).then_some((data, n))
        };
        let Some((data, n)) = taken else {
            return if self.buf_y0 >= h {
                Ok(None)
            } else {
                Err(invalid(&self.input.path, "missing rows"))
            };
        };
        let strip = Strip {
            y0: self.buf_y0,
            rows: n,
            data,
        };
        self.buf_y0 += n;
        Ok(Some(strip))
    }

    /// The block rows decoded ahead on a thread of its own
    /// (`super::ahead`).
    fn decoder<'s>(
        &mut self,
        ahead: &ReadAhead<'_>,
        pool: &'s rayon::ThreadPool,
    ) -> Option<Decoder<'s>>
    where
        Self: 's,
    {
        if self.ahead.is_some() || self.buf.len() > self.head {
            return None;
        }
        let released = self.released.take();
        let blocks = (ahead.window_blocks)(self.input.block_bytes());
        let (ahead, decoder) = super::ahead::start(
            self.input,
            (self.next_row, self.row_len),
            (ahead.strip_rows, blocks as usize),
            (pool, ahead.recycled.clone()),
            released,
        );
        self.ahead = Some(ahead);
        Some(decoder)
    }

    fn wait_ready(&mut self) {
        if let Some(ahead) = self.ahead.as_mut() {
            ahead.wait(self.input);
        }
    }

    /// Kept for the next strip decoded here; a decoder thread takes its
    /// buffers back through `ReadAhead::recycled` instead.
    fn give_back(&mut self, buf: Vec<f32>) {
        if self.ahead.is_none() {
            self.spare = buf;
        }
    }
}
