//! Decoding ahead: a decoder thread keeps a window of block rows decoding on
//! the pool, each a task of its own, while the reader hands over the rows
//! before them. A block row decodes as soon as the one a window before it is
//! handed over: no batch boundary for the pool to drain at, and memory of one
//! window.

use std::collections::{BTreeMap, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};

use super::decode::{decode_rows_into, release_span};
use super::ExrInput;
use crate::error::Result;

/// A decoded block row's values and the file's byte range they came from
/// (or the error).
type RowValues = Result<(Vec<f32>, (usize, usize))>;

/// What a decode task sends back: its block row, what it decoded, and its
/// trace segment.
type Done = (usize, RowValues, u64);

/// One decoded block row, handed over in order.
struct Block {
    buf: Vec<f32>,
    rows: usize,
    bytes: (usize, usize),
    /// The trace segment that decoded it, and whether a read has said it
    /// waited for it.
    decoded_by: u64,
    waited: bool,
}

/// The reader's side of decoding ahead.
pub(super) struct Ahead {
    /// Block rows as their tasks finish (in any order).
    done: crossbeam_channel::Receiver<Done>,
    /// Buffers handed over, back to the decoder (each a slot of the
    /// window), with the trace segment that gave each back.
    free: crossbeam_channel::Sender<(Vec<f32>, u64)>,
    /// Block rows that finished before one above them.
    early: BTreeMap<usize, (RowValues, u64)>,
    /// Block rows in order, from the one being handed over; an error only
    /// last.
    queue: VecDeque<Result<Block>>,
    /// Rows of the front block row handed over.
    front_used: usize,
    /// Rows in `queue` not handed over yet.
    queued_rows: usize,
    /// The next block row to queue, and the end of the file's.
    next_index: usize,
    end_index: usize,
    /// The strips' height.
    max_rows: usize,
    /// Byte range of the file consumed (and released) so far, and the range
    /// handed over since the last release.
    released: Option<(usize, usize)>,
    pending: Option<(usize, usize)>,
    /// Strip buffers handed back to fill again.
    recycled: Option<crossbeam_channel::Receiver<Vec<f32>>>,
}

/// Block rows decoded or decoding at once: `blocks` chunks (the memory the
/// estimate counts, `pipeline::window_blocks`), and at least the block rows
/// a strip's rows span and one block row more, so that a strip is always
/// handed over (the window waits for nothing it does not hold).
fn window(input: &ExrInput, first: usize, max_rows: usize, blocks: usize) -> usize {
    let rows = &input.rows[first..];
    let chunks = rows.first().map_or(1, |r| r.chunks.len().max(1));
    let budget = blocks / chunks;
    let lines: Vec<usize> = rows.iter().map(|r| r.y1 - r.y0).collect();
    budget.max(strip_span(&lines, max_rows) + 1).max(2)
}

/// The most consecutive block rows (of `lines` rows each) that `max_rows`
/// rows starting at a block row's first row reach into. Only the block
/// rows' own heights count: a short last block row (an image height that
/// is not a multiple of the codec's lines) spans no more than it holds.
fn strip_span(lines: &[usize], max_rows: usize) -> usize {
    let max_rows = max_rows.max(1);
    let (mut most, mut end, mut sum) = (0, 0, 0);
    for start in 0..lines.len() {
        while end < lines.len() && sum < max_rows {
            sum += lines[end];
            end += 1;
        }
        most = most.max(end - start);
        sum -= lines[start];
    }
    most.max(1)
}

/// Start decoding ahead from block row `first`, rows of `row_len` values, for
/// strips of `max_rows` rows, `blocks` blocks at once, with `pool`'s threads
/// (and strip buffers handed back from `recycled`): the reader's side, and
/// the decoder loop to run on a thread of its own (it returns once every
/// block row is decoded, after an error, or once the reader's side is
/// dropped).
pub(super) fn start<'s>(
    input: &'s ExrInput,
    (first, row_len): (usize, usize),
    (max_rows, blocks): (usize, usize),
    (pool, recycled): (
        &'s rayon::ThreadPool,
        Option<crossbeam_channel::Receiver<Vec<f32>>>,
    ),
    released: Option<(usize, usize)>,
) -> (Ahead, crate::pipeline::Decoder<'s>) {
    let end = input.rows.len();
    let slots = window(input, first, max_rows, blocks);
    let (done_tx, done) = crossbeam_channel::unbounded::<Done>();
    let (free, free_rx) = crossbeam_channel::bounded(slots);
    for _ in 0..slots {
        let _ = free.send((Vec::new(), 0));
    }
    let ahead = Ahead {
        done,
        free,
        early: BTreeMap::new(),
        queue: VecDeque::new(),
        front_used: 0,
        queued_rows: 0,
        next_index: first,
        end_index: end,
        max_rows,
        released,
        pending: None,
        recycled,
    };
    let decoder = Box::new(move || {
        let failed = AtomicBool::new(false);
        // This thread hands out the block rows, in order, as slots come
        // back; the pool decodes them.
        pool.in_place_scope(|scope| {
            for i in first..end {
                if failed.load(Ordering::Relaxed) {
                    break;
                }
                let Ok((mut buf, freed_by)) = free_rx.recv() else {
                    break;
                };
                let (done, failed) = (done_tx.clone(), &failed);
                scope.spawn(move |_| {
                    let segment = crate::trace::segment("decode", i - first, &[freed_by]);
                    let id = segment.id();
                    let r = {
                        let region = crate::trace::region("decode");
                        let _task = region.task("decode");
                        let r = &input.rows[i];
                        let len = (r.y1 - r.y0) * row_len;
                        // Every value is written by the row's blocks: the
                        // buffer keeps its old values (no clearing pass).
                        buf.truncate(len);
                        buf.resize(len, 0.0);
                        let r = decode_rows_into(input, r, &mut buf, row_len);
                        if let Ok((a, b)) = r {
                            if b - a >= RELEASE_OWN_BYTES {
                                input.map.release(a, b);
                            }
                        }
                        r
                    };
                    drop(segment);
                    if r.is_err() {
                        failed.store(true, Ordering::Relaxed);
                    }
                    let _ = done.send((i, r.map(|bytes| (buf, bytes)), id));
                });
            }
        });
    });
    (ahead, decoder)
}

/// File bytes handed over before their pages are released: each release
/// interrupts every core the process runs on (a TLB shoot-down), so
/// releasing a block row at a time costs measurably more CPU. The memory
/// estimate counts them.
const RELEASE_BYTES: usize = crate::pipeline::MAPPED_RELEASE_BYTES;

/// A decoded block row this large releases its file pages itself, at once:
/// waiting for its rows to be handed over, a window of wide blocks decoded
/// ahead held their compressed pages too, a large share of the peak on the
/// widest inputs.
/// Smaller ones go with the reader's releases, [`RELEASE_BYTES`] at a time
/// (the pages at a row's ends, shared with its neighbours, go there too; a
/// page released twice is only looked up twice).
const RELEASE_OWN_BYTES: usize = 2 << 20;

impl Ahead {
    /// The file's bytes `span` are handed over: release them with those
    /// before, [`RELEASE_BYTES`] at a time, and the rest at the end.
    fn release(&mut self, input: &ExrInput, span: (usize, usize)) {
        if span.0 >= span.1 {
            return;
        }
        let p = match self.pending {
            None => span,
            Some((a, b)) => (a.min(span.0), b.max(span.1)),
        };
        if p.1 - p.0 >= RELEASE_BYTES || self.queue.is_empty() && self.next_index >= self.end_index
        {
            release_span(input, &mut self.released, p);
            self.pending = None;
        } else {
            self.pending = Some(p);
        }
    }

    /// Queue, in order, the block rows that have arrived.
    fn settle(&mut self, input: &ExrInput) {
        while let Some((r, id)) = self.early.remove(&self.next_index) {
            let row = &input.rows[self.next_index];
            self.next_index += 1;
            match r {
                Ok((buf, bytes)) => {
                    let rows = row.y1 - row.y0;
                    self.queued_rows += rows;
                    self.queue.push_back(Ok(Block {
                        buf,
                        rows,
                        bytes,
                        decoded_by: id,
                        waited: false,
                    }));
                }
                Err(e) => {
                    // Nothing after an error is handed over.
                    self.queue.push_back(Err(e));
                    self.next_index = self.end_index;
                }
            }
        }
    }

    /// Whether the next strip can be handed over without waiting.
    fn ready(&self) -> bool {
        self.queued_rows >= self.max_rows
            || self.next_index >= self.end_index
            || matches!(self.queue.back(), Some(Err(_)))
    }

    /// Wait until the next strip's rows (or the last rows, or an error) are
    /// in order. Called outside the pool: a worker waiting here for a block
    /// row the pool has yet to decode would deadlock a 1-thread run.
    pub(super) fn wait(&mut self, input: &ExrInput) {
        self.settle(input);
        while !self.ready() {
            match self.done.recv() {
                Ok((i, r, id)) => {
                    self.early.insert(i, (r, id));
                    self.settle(input);
                }
                // The decoder has ended: what is missing stays missing.
                Err(_) => break,
            }
        }
    }

    /// Up to `max_rows` rows of `row_len` values, in order (`None`: none
    /// are left), or the error met first. Each block row handed over goes
    /// back to the decoder, its pages to the kernel.
    pub(super) fn take(
        &mut self,
        input: &ExrInput,
        max_rows: usize,
        row_len: usize,
    ) -> Result<Option<(Vec<f32>, usize)>> {
        if !self.ready() {
            self.wait(input);
        }
        if self.queued_rows == 0 {
            return match self.queue.pop_front() {
                Some(Err(e)) => Err(e),
                _ => Ok(None),
            };
        }
        let n = max_rows.min(self.queued_rows);
        // A strip buffer handed back (its pages already in), or a new one
        // that goes back to the system when dropped.
        let mut data = match self.recycled.as_ref().and_then(|r| r.try_recv().ok()) {
            Some(mut v) => {
                v.clear();
                v.reserve_exact(n * row_len);
                v
            }
            None => crate::pipeline::own_pages(n * row_len),
        };
        let mut need = n;
        while need > 0 {
            let Some(Ok(b)) = self.queue.front_mut() else {
                break;
            };
            if !b.waited {
                crate::trace::wait_for(b.decoded_by);
                b.waited = true;
            }
            let take = need.min(b.rows - self.front_used);
            data.extend_from_slice(&b.buf[self.front_used * row_len..][..take * row_len]);
            self.front_used += take;
            self.queued_rows -= take;
            need -= take;
            if self.front_used == b.rows {
                self.front_used = 0;
                if let Some(Ok(b)) = self.queue.pop_front() {
                    self.release(input, b.bytes);
                    // A decoder that has ended drops it.
                    let _ = self.free.send((b.buf, crate::trace::current_segment()));
                }
            }
        }
        Ok(Some((data, n - need)))
    }
}

#[cfg(test)]
mod tests {
    use super::strip_span;

    #[test]
    fn a_strip_spans_the_block_rows_its_rows_reach() {
        // 16-line blocks: 18 rows from a block's first reach into two.
        assert_eq!(strip_span(&[16; 10], 18), 2);
        assert_eq!(strip_span(&[16; 10], 16), 1);
        assert_eq!(strip_span(&[16; 10], 17), 2);
        // A last block row of one line (a height of 16 k + 1) does not
        // make every strip span 18 block rows.
        let mut lines = vec![16; 2048];
        lines.push(1);
        assert_eq!(strip_span(&lines, 18), 2);
        // Short block rows in the middle are spanned as they are.
        assert_eq!(strip_span(&[16, 1, 1, 1, 16], 18), 4);
        // One-line blocks (uncompressed): a block row a row.
        assert_eq!(strip_span(&[1; 100], 18), 18);
        // A strip taller than the image, and an empty image.
        assert_eq!(strip_span(&[16, 16], 100), 2);
        assert_eq!(strip_span(&[], 18), 1);
        assert_eq!(strip_span(&[16], 0), 1);
    }
}
