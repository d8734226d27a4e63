//! The run: the thread pool, the reader and writer threads around the
//! skeleton, and ep-box's first pass (the mean luminance).

use super::{edge, ledger};
use super::{
    window_blocks, Error, FilterParams, Instant, Ordering, OutRows, PipelineConfig, ReadAhead,
    RunStats, Sink, Source, StageSeconds, Streamer, Strip, StripLayout, STRIPS_RECYCLED,
};
use crate::error::Result;
use rayon::iter::ParallelIterator;
use rayon::slice::ParallelSlice;

/// Progress callback: (output rows done, output rows in all).
pub type Progress<'a> = &'a (dyn Fn(usize, usize) + Sync);

/// Build the filter's thread pool (and, at one thread, every stage's).
pub fn thread_pool(threads: usize) -> Result<rayon::ThreadPool> {
    named_pool(threads, "epfilt")
}

/// Build the pool that decodes and compresses blocks, beside the filter's
/// when `threads > 1` (`None`: the filter's pool does it).
///
/// A thread of a pool that waits for the rest of its parallel loop runs
/// other tasks of its pool meanwhile, and a block's decode or compression
/// is a task many times longer than the filter's: sharing one pool, a
/// strip's filtering waited for the decodes its threads picked up, and the
/// filter lane (one strip at a time) became the run's critical path. Pools
/// of their own keep the filter's loops to their own tasks. Both run at the
/// process's priority: a lower one for this pool starves decoding beside
/// other busy processes (a renderer on the same node).
pub fn io_pool(threads: usize) -> Result<Option<rayon::ThreadPool>> {
    if threads <= 1 {
        return Ok(None);
    }
    named_pool(threads, "epfilt-io").map(Some)
}

fn named_pool(threads: usize, name: &'static str) -> Result<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(move |i| format!("{name}-{i}"))
        .build()
        .map_err(|e| Error::Config(format!("cannot start {threads} threads: {e}")))
}

/// Run `job` from `source` to `sink`, rounding to the sink's precision.
/// The reader and writer run on threads of their own (`read_strips`,
/// `write_rows`), the filter on this one, tied by two bounded channels.
pub fn run<S: Source, K: Sink>(
    source: S,
    sink: K,
    job: &StripLayout,
    params: &FilterParams,
    cfg: &PipelineConfig,
    progress: Progress<'_>,
) -> Result<RunStats> {
    let params = params.validated()?;
    let streamer = Streamer::new(job, &params, cfg, sink.precisions(job.channels.len()))?;
    run_streamer(source, sink, job, streamer, cfg, progress)
}

/// [`run`] with the skeleton and its stage built (`epfilt restore`'s).
pub fn run_streamer<S: Source, K: Sink>(
    source: S,
    sink: K,
    job: &StripLayout,
    mut streamer: Streamer,
    cfg: &PipelineConfig,
    progress: Progress<'_>,
) -> Result<RunStats> {
    let pool = thread_pool(cfg.threads)?;
    let io_pool = io_pool(cfg.threads)?;
    let start = Instant::now();
    let real = job.padded_from.unwrap_or((job.grid.in_w, job.grid.in_h));
    let source = edge::Padded::new(
        source,
        real,
        (job.grid.in_w, job.grid.in_h),
        job.strip_channels(),
    );
    let total = job.grid.out_h();
    let cancelled = || {
        cfg.cancel
            .as_ref()
            .is_some_and(|c| c.load(Ordering::Relaxed))
    };
    let (strip_tx, strip_rx) = crossbeam_channel::bounded::<Result<Strip>>(2);
    let (row_tx, row_rx) = crossbeam_channel::bounded::<(usize, OutRows)>(2);
    let strip_rows = job.strip_rows(cfg);
    let pool = &pool;
    let io = io_pool.as_ref().unwrap_or(pool);
    let mut stages = StageSeconds::default();
    // The reader's window of blocks, from the job's memory, and the strips'
    // buffers back to it.
    let window = |block_bytes| match cfg.window_blocks {
        0 => window_blocks(cfg, block_bytes),
        n => n as u64,
    };
    let (recycle, recycled) = crossbeam_channel::bounded(STRIPS_RECYCLED);
    streamer.recycle_strips(recycle);
    // The output rows' buffers back from the writer: two wait at most. The
    // writer gives them back in bursts (a batch of blocks at a time), and
    // the books finish rows in a fresh buffer, faulted in page by page,
    // whenever none waits.
    let (rows_back, rows_recycled) = crossbeam_channel::bounded(2);
    streamer.recycle_rows(rows_recycled);
    let ahead = ReadAhead {
        strip_rows,
        window_blocks: &window,
        recycled: Some(recycled),
    };

    let result = std::thread::scope(|scope| -> Result<()> {
        let reader = scope.spawn(move || read_strips(source, io, ahead, strip_tx));
        let writer = scope.spawn(move || write_rows(sink, io, total, (row_rx, rows_back)));
        let channels = (&strip_rx, &row_tx);
        let (mut filter_result, writer_failed) = filter_strips(
            &mut streamer,
            channels,
            (pool, &cancelled),
            total,
            progress,
            &mut stages,
        );
        drop(strip_rx);
        if filter_result.is_ok() && !writer_failed && streamer.rows_out() != total {
            filter_result = Err(Error::Internal(format!(
                "the source ended after {} of {} output rows",
                streamer.rows_out(),
                total
            )));
        }
        drop(row_tx);
        stages.read = reader.join().unwrap_or(0.0);
        // A panic on the writer thread is a bug: report it first, never
        // behind another error.
        match writer.join() {
            Ok((write_result, busy)) => {
                stages.write = busy;
                filter_result.and(write_result)
            }
            Err(_) => Err(Error::Internal(
                "the writer thread panicked (please report this file)".into(),
            )),
        }
    });
    result?;
    let s2 = (job.grid.s * job.grid.s) as f64;
    let books = streamer.books();
    Ok(RunStats {
        method: streamer.counts(),
        ledger: books.ledger().balance(books.names(), s2),
        seconds: start.elapsed().as_secs_f64(),
        stages,
        halo: streamer.halo(),
        windows: streamer.windows(),
        digest: books.digest(),
        nonfinite_zeroed: books.nonfinite_zeroed().to_vec(),
        first_nonfinite: books.first_nonfinite(),
    })
}

/// The filter's loop: each strip from `strip_rx` through the streamer, its
/// final rows to `row_tx`, then the last rows once the input is all in.
/// Its result, and whether the writer went away (its error is its own).
fn filter_strips(
    streamer: &mut Streamer,
    (strip_rx, row_tx): (
        &crossbeam_channel::Receiver<Result<Strip>>,
        &crossbeam_channel::Sender<(usize, OutRows)>,
    ),
    (pool, cancelled): (&rayon::ThreadPool, &dyn Fn() -> bool),
    total: usize,
    progress: Progress<'_>,
    stages: &mut StageSeconds,
) -> (Result<()>, bool) {
    let mut filter_result = Ok(());
    let mut writer_failed = false;
    let mut drained = false;
    for k in 0.. {
        let t = Instant::now();
        let strip = if drained { None } else { strip_rx.recv().ok() };
        stages.filter_waiting_for_input += t.elapsed().as_secs_f64();
        if cancelled() {
            filter_result = Err(Error::Interrupted);
            break;
        }
        let t = Instant::now();
        let pushed = match strip {
            Some(strip) => strip.and_then(|s| {
                pool.install(|| {
                    let _segment = crate::trace::segment("filter", k, &[]);
                    streamer.push(s)
                })
            }),
            // The input is all in: a stage may hand its last rows over
            // a few at a time (restore's rows of blocks).
            None if streamer.rows_out() < total => {
                drained = true;
                match pool.install(|| streamer.drain()) {
                    Ok(None) => break,
                    r => r,
                }
            }
            None => break,
        };
        stages.filter += t.elapsed().as_secs_f64();
        match pushed {
            Ok(Some(rows)) => {
                progress(rows.y0 + rows.rows, total);
                let t = Instant::now();
                let sent = row_tx.send((k, rows));
                stages.filter_waiting_for_output += t.elapsed().as_secs_f64();
                if sent.is_err() {
                    writer_failed = true; // its error is reported below
                    break;
                }
            }
            Ok(None) => {}
            Err(e) => {
                filter_result = Err(e);
                break;
            }
        }
    }
    (filter_result, writer_failed)
}

/// The reader thread: strips of `ahead.strip_rows` from `source` into `tx` (an
/// error ends them); returns its busy seconds. A source that decodes does so
/// ahead, on a thread of its own ([`Source::decoder`]), while this one hands
/// the strips over.
pub(crate) fn read_strips<S: Source>(
    mut source: S,
    pool: &rayon::ThreadPool,
    ahead: ReadAhead<'_>,
    tx: crossbeam_channel::Sender<Result<Strip>>,
) -> f64 {
    let strip_rows = ahead.strip_rows;
    std::thread::scope(|scope| {
        if let Some(decoder) = source.decoder(&ahead, pool) {
            scope.spawn(decoder);
        }
        let mut busy = 0.0;
        for k in 0.. {
            source.wait_ready();
            let t = Instant::now();
            let next = pool.install(|| {
                let _segment = crate::trace::segment("read", k, &[]);
                source.next_strip(strip_rows)
            });
            busy += t.elapsed().as_secs_f64();
            let stop = !matches!(next, Ok(Some(_)));
            let msg = match next {
                Ok(Some(s)) => Ok(s),
                Ok(None) => break,
                Err(e) => Err(e),
            };
            if tx.send(msg).is_err() || stop {
                break;
            }
        }
        // Its channels closed, the decoder ends (the scope waits for it).
        drop(source);
        busy
    })
}

/// The writer thread: the rows from `rx` (each with the strip that finished
/// them) into `sink`, finished once all `total` rows are in, their buffers
/// back to the filter through `back`; its result and busy seconds.
fn write_rows<K: Sink>(
    mut sink: K,
    pool: &rayon::ThreadPool,
    total: usize,
    (rx, back): (
        crossbeam_channel::Receiver<(usize, OutRows)>,
        crossbeam_channel::Sender<Vec<f32>>,
    ),
) -> (Result<()>, f64) {
    let mut written = 0;
    let mut busy = 0.0;
    let mut last = 0;
    for (k, rows) in rx.iter() {
        let t = Instant::now();
        last = k;
        let r = pool.install(|| {
            let _segment = crate::trace::segment("write", k, &[]);
            sink.write_rows(rows.y0, rows.rows, &rows.data)
        });
        busy += t.elapsed().as_secs_f64();
        if let Err(e) = r {
            return (Err(e), busy);
        }
        written += rows.rows;
        // The filter may have gone, or have a buffer waiting: then it goes.
        let _ = back.try_send(rows.data);
    }
    // Finish only a complete image: when the filter stopped early its error
    // is the one reported, and the sink is dropped unfinished (an EXR output
    // then removes its temporary file).
    let t = Instant::now();
    let r = if written == total {
        pool.install(|| {
            let _segment = crate::trace::segment("write", last, &[]);
            sink.finish()
        })
    } else {
        Ok(())
    };
    (r, busy + t.elapsed().as_secs_f64())
}

/// The mean luminance of a source's filtered channels (the first pass of
/// `ep-box`, for `L_ave` of Eq. 9), summed exactly (compensated) in row order;
/// `progress(rows read, rows)`.
pub fn mean_luminance<S: Source>(
    mut source: S,
    job: &StripLayout,
    strip_rows: usize,
    progress: Progress<'_>,
) -> Result<f64> {
    let w = job.grid.in_w;
    let nall = job.strip_channels();
    let strip_rows = match strip_rows {
        0 => job.auto_strip_rows(rayon::current_num_threads()),
        n => n,
    };
    let luminance = &crate::filter::luminance::Luminance::new(&job.luminance);
    let mut total = ledger::CompensatedSum::default();
    let mut count = 0usize;
    while let Some(strip) = source.next_strip(strip_rows)? {
        let sums: Vec<ledger::CompensatedSum> = strip
            .data
            .par_chunks(nall * w)
            .map(|row| {
                let mut s = ledger::CompensatedSum::default();
                for x in 0..w {
                    // Non-finite samples are the filter's to report.
                    s.add(luminance.of_finite(|c| row[c * w + x] as f64));
                }
                s
            })
            .collect();
        for s in &sums {
            total.merge(s);
        }
        count += strip.rows * w;
        progress(strip.y0 + strip.rows, job.grid.in_h);
        source.give_back(strip.data);
    }
    Ok(if count == 0 {
        0.0
    } else {
        total.value() / count as f64
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_thread_shares_its_pool_and_more_get_an_io_pool_of_their_own() {
        assert!(io_pool(1).unwrap().is_none());
        let io = io_pool(3).unwrap().expect("an I/O pool from 2 threads");
        assert_eq!(io.current_num_threads(), 3);
        let name =
            |p: &rayon::ThreadPool| p.install(|| std::thread::current().name().map(String::from));
        assert!(name(&io).unwrap().starts_with("epfilt-io-"));
        assert!(!name(&thread_pool(2).unwrap())
            .unwrap()
            .starts_with("epfilt-io-"));
    }
}
