//! The output's scan-line blocks, filled as the rows come and compressed a
//! batch at a time on the shared pool.
//!
//! Each row goes straight into its block's bytes, in the file's channel
//! order and sample types (for ZIP, into the split bytes it deflates): the
//! writer holds no copy of the rows. On a wide output a block is tens of
//! megabytes, and rows held until their block was full, then copied into
//! it, cost as much again.

use std::sync::Mutex;

use exr::block::chunk::{Chunk, CompressedBlock, CompressedScanLineBlock};
use exr::block::{BlockIndex, UncompressedBlock};
use exr::math::Vec2;
use exr::meta::header::Header;
use rayon::iter::{IntoParallelIterator, ParallelIterator};

use crate::io::zip::{self, SplitBlock};
use crate::pipeline::Precision;

/// One block's bytes as they are filled.
pub(super) enum Fill {
    /// ZIP and ZIPS ([`zip::codes`]): the split bytes it deflates.
    Split(SplitBlock),
    /// Any other codec: the block's bytes, for `exr` to compress.
    Raw(Vec<u8>),
}

/// The blocks of an image being written: those being filled, from row `y0`
/// (each full but the last), and the buffers of those compressed.
pub(super) struct Blocks {
    w: usize,
    height: usize,
    lines: usize,
    /// For each header channel, its index in the rows written.
    order: Vec<usize>,
    /// Sample type of each channel, in the rows' order.
    types: Vec<Precision>,
    zip: bool,
    filling: Vec<Fill>,
    y0: usize,
    /// Rows filled from `y0`.
    rows: usize,
    /// ZIP's split bytes of blocks compressed, for the next ones: no more
    /// of them than blocks compressed at once.
    spare: Mutex<Vec<Vec<u8>>>,
    /// Full blocks compressed at once (one at the least).
    batch: usize,
}

/// Where a block's samples go, each as its native-endian bytes.
trait SampleSink {
    fn put<const N: usize>(&mut self, src: &[f32], bytes: impl Fn(f32) -> [u8; N]);
}

impl SampleSink for Vec<u8> {
    fn put<const N: usize>(&mut self, src: &[f32], bytes: impl Fn(f32) -> [u8; N]) {
        src.iter().for_each(|&v| self.extend_from_slice(&bytes(v)));
    }
}

impl SampleSink for SplitBlock {
    fn put<const N: usize>(&mut self, src: &[f32], bytes: impl Fn(f32) -> [u8; N]) {
        self.push(src, bytes);
    }
}

impl Blocks {
    /// No rows yet of a `w` x `height` image in blocks of `lines` rows,
    /// `order` and `types` as [`Blocks::order`] and [`Blocks::types`] say;
    /// `zip`: ZIP's bytes are split here.
    pub(super) fn new(
        (w, height, lines): (usize, usize, usize),
        order: Vec<usize>,
        types: Vec<Precision>,
        zip: bool,
    ) -> Self {
        Blocks {
            w,
            height,
            lines: lines.max(1),
            order,
            types,
            zip,
            filling: Vec::new(),
            y0: 0,
            rows: 0,
            spare: Mutex::new(Vec::new()),
            batch: 1,
        }
    }

    /// Compress full blocks once they hold `bytes` of rows as f32 (one block
    /// at the least).
    pub(super) fn set_batch_bytes(&mut self, bytes: usize) {
        let block = (self.types.len() * self.w * self.lines * 4).max(1);
        self.batch = (bytes / block).max(1);
    }

    /// Rows filled, from the image's first.
    pub(super) fn rows_in(&self) -> usize {
        self.y0 + self.rows
    }

    /// Put `data`'s rows (each the channels in the rows' order, `w` samples
    /// a channel) into their blocks, up to the row that completes a batch
    /// ([`Blocks::take`] then gives it, and its buffers serve the next
    /// blocks): the rows taken, or `None` when they run past the image.
    pub(super) fn push(&mut self, data: &[f32]) -> Option<usize> {
        let row_len = (self.types.len() * self.w).max(1);
        let mut taken = 0;
        for row in data.chunks_exact(row_len) {
            if self.rows_in() >= self.height {
                return None;
            }
            if self.rows % self.lines == 0 {
                let block = self.fresh(self.lines.min(self.height - self.rows_in()));
                self.filling.push(block);
            }
            match self.filling.last_mut()? {
                Fill::Split(s) => put_row(s, row, &self.order, &self.types, self.w),
                Fill::Raw(v) => put_row(v, row, &self.order, &self.types, self.w),
            }
            self.rows += 1;
            taken += 1;
            if self.rows % self.lines == 0 && self.rows / self.lines >= self.batch {
                break;
            }
        }
        Some(taken)
    }

    /// A block of `rows` rows to fill.
    fn fresh(&self, rows: usize) -> Fill {
        let row_bytes: usize = self.types.iter().map(|t| t.bytes()).sum::<usize>() * self.w;
        if self.zip {
            let buf = self.spare.lock().ok().and_then(|mut s| s.pop());
            Fill::Split(SplitBlock::new_in(
                buf.unwrap_or_default(),
                rows * row_bytes / 2,
            ))
        } else {
            Fill::Raw(Vec::with_capacity(rows * row_bytes))
        }
    }

    /// The blocks to compress now, each with its first row: a batch of full
    /// ones, or (`all`) every one. None yet: empty.
    pub(super) fn take(&mut self, all: bool) -> Vec<(usize, Fill)> {
        let full = match all {
            true => self.filling.len(),
            false => self.rows / self.lines,
        };
        if full == 0 || (!all && full < self.batch) {
            return Vec::new();
        }
        let (y0, lines) = (self.y0, self.lines);
        let used = (full * lines).min(self.rows);
        self.y0 += used;
        self.rows -= used;
        (self.filling.drain(..full))
            .enumerate()
            .map(|(b, f)| (y0 + b * lines, f))
            .collect()
    }

    /// Compress `blocks` in parallel, for a part whose header is `headers[0]`:
    /// each as its block index and chunk.
    pub(super) fn compress(
        &self,
        blocks: Vec<(usize, Fill)>,
        headers: &[Header],
    ) -> Vec<exr::error::Result<(usize, Chunk)>> {
        let region = crate::trace::region("compress");
        let (w, lines) = (self.w, self.lines);
        blocks
            .into_par_iter()
            .map(|(y, fill)| {
                let _task = region.task("compress");
                let header = &headers[0];
                let data = match fill {
                    Fill::Split(split) => {
                        let (stream, buf) = split.compress(zip::ZIP_LEVEL);
                        if let Ok(mut s) = self.spare.lock() {
                            s.push(buf);
                        }
                        let chunk = Chunk {
                            layer_index: 0,
                            compressed_block: CompressedBlock::ScanLine(CompressedScanLineBlock {
                                y_coordinate: y as i32 + header.own_attributes.layer_position.1,
                                compressed_pixels_le: stream,
                            }),
                        };
                        return Ok((y / lines, chunk));
                    }
                    Fill::Raw(data) => data,
                };
                let rows = lines.min(self.height - y);
                let block = UncompressedBlock {
                    index: BlockIndex {
                        layer: 0,
                        pixel_position: Vec2(0, y),
                        pixel_size: Vec2(w, rows),
                        level: Vec2(0, 0),
                    },
                    data,
                };
                Ok((y / lines, block.compress_to_chunk(headers)?))
            })
            .collect()
    }
}

/// One row's samples into `sink`, channel by channel in the file's order.
fn put_row(
    sink: &mut impl SampleSink,
    row: &[f32],
    order: &[usize],
    types: &[Precision],
    w: usize,
) {
    for &c in order {
        let src = &row[c * w..][..w];
        match types[c] {
            Precision::F32 => sink.put(src, f32::to_ne_bytes),
            Precision::F16 => sink.put(src, |v| half::f16::from_f32(v).to_bits().to_ne_bytes()),
            // Whole numbers (the pipeline's rounding checked).
            Precision::U32 => sink.put(src, |v| (v as u32).to_ne_bytes()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use exr::prelude::Compression;

    const W: usize = 5;
    const H: usize = 37;

    /// Three channels, one of each type, their rows' values whole numbers.
    fn rows() -> Vec<f32> {
        (0..H * 3 * W).map(|i| (i % 251) as f32).collect()
    }

    /// The chunks an image of `compression` gets when its rows come `piece`
    /// rows at a time and a batch holds `batch_bytes`: (block index, first
    /// row, bytes), and the most split buffers held at once.
    fn write(compression: Compression, piece: usize, batch_bytes: usize) -> (Vec<Chunked>, usize) {
        let types = vec![Precision::F32, Precision::F16, Precision::U32];
        let names: Vec<String> = ["R", "G", "id"].map(String::from).to_vec();
        let header = super::super::ExrOutput::fresh_header(W, H, &names, compression, &types);
        let lines = compression.scan_lines_per_block();
        let order = vec![1, 0, 2];
        let mut blocks = Blocks::new((W, H, lines), order, types, zip::codes(compression));
        blocks.set_batch_bytes(batch_bytes);
        let (mut out, mut most) = (Vec::new(), 0);
        let data = rows();
        let mut flush = |blocks: &mut Blocks, all: bool| {
            let ready = blocks.take(all);
            let held = ready.len() + blocks.filling.len() + blocks.spare.lock().unwrap().len();
            most = most.max(held);
            for c in blocks.compress(ready, std::slice::from_ref(&header)) {
                let (i, c) = c.unwrap();
                let CompressedBlock::ScanLine(b) = c.compressed_block else {
                    panic!("a scan-line chunk");
                };
                out.push((i, b.y_coordinate, b.compressed_pixels_le));
            }
        };
        for strip in data.chunks(piece * 3 * W) {
            let mut strip = strip;
            while !strip.is_empty() {
                let n = blocks.push(strip).unwrap();
                flush(&mut blocks, false);
                strip = &strip[n * 3 * W..];
            }
        }
        assert_eq!(blocks.rows_in(), H);
        flush(&mut blocks, true);
        (out, most)
    }

    type Chunked = (usize, i32, Vec<u8>);

    #[test]
    fn rows_in_any_pieces_make_the_same_blocks() {
        for compression in [
            Compression::ZIP16,
            Compression::ZIP1,
            Compression::Uncompressed,
            Compression::PIZ,
        ] {
            let lines = compression.scan_lines_per_block();
            let (whole, _) = write(compression, H, 0);
            assert_eq!(whole.len(), H.div_ceil(lines), "{compression:?}");
            for (k, c) in whole.iter().enumerate() {
                assert_eq!((c.0, c.1), (k, (k * lines) as i32), "{compression:?}");
            }
            for piece in [1, 7, 16, 17] {
                for batch_bytes in [0, 3 * W * 4 * lines * 2] {
                    let (chunks, _) = write(compression, piece, batch_bytes);
                    assert_eq!(
                        chunks, whole,
                        "{compression:?}, {piece} rows, {batch_bytes} B"
                    );
                }
            }
        }
    }

    #[test]
    fn a_block_is_compressed_before_the_next_is_begun() {
        // One block a batch: one split buffer, filled, compressed, and
        // filled again, whatever the strips (with rows held until a block
        // was full, a strip across two blocks began the second first).
        for piece in [1, 6, 18, H] {
            assert_eq!(write(Compression::ZIP16, piece, 0).1, 1, "{piece} rows");
        }
        // A batch of two blocks: two.
        let two = 3 * W * 4 * 16 * 2;
        assert_eq!(write(Compression::ZIP16, 5, two).1, 2);
    }

    #[test]
    fn rows_past_the_image_are_refused() {
        let types = vec![Precision::F32];
        let mut blocks = Blocks::new((2, 3, 16), vec![0], types, true);
        assert_eq!(blocks.push(&[1.0; 6]), Some(3));
        assert_eq!(blocks.push(&[1.0; 2]), None);
    }
}
