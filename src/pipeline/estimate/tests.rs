//! The estimate's and the memory fit's rules.

use super::*;
use crate::geometry::Grid;
use crate::pipeline::strips_in_flight;

#[test]
fn a_batch_counts_bytes_two_blocks_at_the_least() {
    // 6144 x 3 samples wide, float RGB, 16-row ZIP blocks: the bytes
    // hold 7.
    let bench = 18432 * 3 * 4 * 16;
    assert_eq!(read_ahead_blocks(bench), 7);
    // Tiles of 64 x 64: bytes decide.
    let tile = 64 * 64 * 3 * 4;
    assert_eq!(read_ahead_blocks(tile), READ_AHEAD_BYTES / tile);
    // 32769 wide: 3 of its blocks.
    let wide = 32769 * 3 * 4 * 16;
    assert_eq!(read_ahead_blocks(wide), 3);
    // Blocks past the cap: two at the least.
    assert_eq!(read_ahead_blocks(READ_AHEAD_BYTES), 2);
    assert_eq!(read_ahead_blocks(0), READ_AHEAD_BYTES);
}

/// A float RGB job of `in_w` x `in_h` samples at S = 3.
fn rgb(in_w: usize, in_h: usize) -> StripLayout {
    let grid = Grid { in_w, in_h, s: 3 };
    let names = ["R", "G", "B"].map(String::from).to_vec();
    StripLayout::new(grid, names, vec![0.2126, 0.7152, 0.0722])
}

#[test]
fn strips_grow_to_sixteen_pixel_rows_where_they_fit() {
    // 12288 wide at S = 3: 28 rows by STRIP_BYTES (9.3 pixel rows); 48
    // fit in TALL_STRIP_BYTES.
    let square = rgb(12288, 12288);
    assert_eq!(square.auto_strip_rows(2), TALL_STRIP_PIXEL_ROWS * 3);
    // 32769 wide: 48 rows would not fit; the least pixel rows stay,
    // two a worker between four and six.
    let wide = rgb(32769, 3600);
    assert_eq!(wide.auto_strip_rows(1), FEWEST_STRIP_PIXEL_ROWS * 3);
    assert_eq!(wide.auto_strip_rows(2), FEWEST_STRIP_PIXEL_ROWS * 3);
    assert_eq!(wide.auto_strip_rows(3), MIN_STRIP_PIXEL_ROWS * 3);
    assert_eq!(wide.auto_strip_rows(4), MIN_STRIP_PIXEL_ROWS * 3);
    // Narrower: STRIP_BYTES already holds more pixel rows (56 rows).
    assert_eq!(rgb(6144, 6144).auto_strip_rows(2), 56);
    // Two pixel rows a worker where they fit: 16 workers get 32 at
    // 12288 wide; up to 8 workers keep 16.
    assert_eq!(square.auto_strip_rows(8), TALL_STRIP_PIXEL_ROWS * 3);
    assert_eq!(square.auto_strip_rows(16), 32 * 3);
    // At 32769 wide 32 pixel rows would not fit: the strip stays.
    assert_eq!(wide.auto_strip_rows(16), MIN_STRIP_PIXEL_ROWS * 3);
    // --strip-rows wins.
    let given = PipelineConfig {
        strip_rows: 7,
        threads: 16,
        ..PipelineConfig::default()
    };
    assert_eq!(square.strip_rows(&given), 7);
    // The estimate counts the taller strips.
    let (block, ep) = (12288 * 3 * 4 * 16, FilterParams::new(Method::EpGauss, 3));
    let short = PipelineConfig {
        strip_rows: 28,
        ..PipelineConfig::default()
    };
    let tall = estimate_bytes(&square, &ep, &PipelineConfig::default(), block);
    assert!(tall > estimate_bytes(&square, &ep, &short, block));
}

#[test]
fn a_write_batch_holds_a_block_for_every_two_workers_or_each() {
    let on = |threads| PipelineConfig {
        threads,
        ..PipelineConfig::default()
    };
    // 8192 pixels wide at S = 1, nine channels, 16-row blocks: a block
    // holds more than a worker's bytes.
    let mut wide = rgb(8192, 4096);
    wide.grid.s = 1;
    wide.channels = (0..9).map(|c| c.to_string()).collect();
    wide.out_block_lines = 16;
    let block = 8192 * 9 * 4 * 16;
    assert_eq!(wide.write_ahead_bytes(&on(1)), block);
    assert_eq!(wide.write_ahead_bytes(&on(2)), block);
    assert_eq!(wide.write_ahead_bytes(&on(3)), 2 * block);
    assert_eq!(wide.write_ahead_bytes(&on(16)), 8 * block);
    // Restore's writer: a block a worker.
    let restore = StripLayout {
        workers_per_write_block: crate::pipeline::restore::RESTORE_WORKERS_PER_WRITE_BLOCK,
        ..wide.clone()
    };
    assert_eq!(restore.write_ahead_bytes(&on(2)), 2 * block);
    assert_eq!(restore.write_ahead_bytes(&on(16)), 16 * block);
    // 4096 pixels of RGB at S = 3: a worker's bytes hold more.
    let mut narrow = rgb(12288, 12288);
    narrow.out_block_lines = 16;
    let per = WRITE_AHEAD_BYTES_PER_THREAD;
    assert_eq!(narrow.write_ahead_bytes(&on(2)), 2 * per);
    assert_eq!(narrow.write_ahead_bytes(&on(16)), 16 * per);
    // A given write-ahead wins.
    let given = PipelineConfig {
        write_ahead: 5,
        ..on(16)
    };
    assert_eq!(wide.write_ahead_bytes(&given), 5);
}

#[test]
fn the_window_holds_eight_blocks_where_the_threads_ask() {
    let on = |threads| PipelineConfig {
        threads,
        ..PipelineConfig::default()
    };
    // 32769 wide, 16-row ZIP blocks: two batches hold 6; 16 threads
    // get 8, and 2 threads their 4.
    let block = 32769 * 3 * 4 * 16;
    assert_eq!(READ_AHEAD_BATCHES * read_ahead_blocks(block), 6);
    assert_eq!(window_blocks(&on(16), block), WINDOW_MIN_BLOCKS);
    assert_eq!(window_blocks(&on(2), block), 4);
    // Nine channels: a worker's second block no longer fits the
    // batches' bytes at 2 threads; 16 threads keep their 8.
    let nine = 32769 * 9 * 4 * 16;
    assert_eq!(window_blocks(&on(2), nine), 2);
    assert_eq!(window_blocks(&on(16), nine), WINDOW_MIN_BLOCKS);
    // The estimate counts the whole window, for every method.
    let wide = rgb(32769, 3600);
    for m in [Method::Box, Method::Gauss, Method::EpGauss] {
        let p = FilterParams::new(m, 3);
        let eight = estimate_bytes(&wide, &p, &on(16), block);
        let two = estimate_bytes(
            &wide,
            &p,
            &PipelineConfig {
                window_blocks: 2,
                ..on(16)
            },
            block,
        );
        assert!(eight >= two + 6 * block, "{m:?}");
    }
    // Narrower: two batches already hold more than 8 blocks.
    let block = 12288 * 3 * 4 * 16;
    let by_bytes = READ_AHEAD_BATCHES * read_ahead_blocks(block);
    assert!(by_bytes > WINDOW_MIN_BLOCKS);
    assert_eq!(window_blocks(&on(16), block), by_bytes);
}

#[test]
fn a_smaller_budget_runs_shorter_strips_and_fewer_blocks_down_to_a_floor() {
    let job = rgb(6144, 6144);
    let block = 6144 * 3 * 4 * 16;
    let cfg = PipelineConfig::default();
    for m in [Method::EpGauss, Method::Box] {
        let p = FilterParams::new(m, 3);
        let full = estimate_bytes(&job, &p, &cfg, block);
        // Within the default estimate: nothing changes.
        let same = fit_memory(&job, &p, &cfg, block, full).unwrap().0;
        assert_eq!((same.strip_rows, same.window_blocks), (0, 0), "{m:?}");
        // The floor: strips of one pixel row, the fewest blocks.
        let floor = fit_memory(&job, &p, &cfg, block, 0).unwrap_err();
        assert!(floor < full, "{m:?}: {floor} vs {full}");
        let at_floor = fit_memory(&job, &p, &cfg, block, floor).unwrap().0;
        assert_eq!(at_floor.strip_rows, 3, "{m:?}");
        assert_eq!(at_floor.window_blocks, FEWEST_WINDOW_BLOCKS, "{m:?}");
        // Between: whatever is chosen fits, and a larger budget never
        // gets shorter strips.
        let mut last = 0;
        for k in 0..=8 {
            let limit = floor + (full - floor) * k / 8;
            let c = fit_memory(&job, &p, &cfg, block, limit).unwrap().0;
            assert!(estimate_bytes(&job, &p, &c, block) <= limit, "{m:?} {k}");
            let rows = job.strip_rows(&c);
            assert!(rows >= last, "{m:?} {k}: {rows} after {last}");
            last = rows;
        }
    }
    // Strips the user set stay as set.
    let given = PipelineConfig {
        strip_rows: 12,
        ..PipelineConfig::default()
    };
    let p = FilterParams::new(Method::EpGauss, 3);
    let floor = fit_memory(&job, &p, &given, block, 0).unwrap_err();
    assert_eq!(
        fit_memory(&job, &p, &given, block, floor)
            .unwrap()
            .0
            .strip_rows,
        12
    );
}

#[test]
fn two_strips_in_flight_hold_a_strip_more_and_go_first_under_a_budget() {
    let job = rgb(6144, 6144);
    let block = 6144 * 3 * 4 * 16;
    let two = PipelineConfig {
        threads: 2,
        strips_in_flight: 2,
        ..PipelineConfig::default()
    };
    let one = PipelineConfig {
        strips_in_flight: 1,
        ..two.clone()
    };
    let strip = job.strip_rows(&two);
    for m in [Method::EpGauss, Method::Gauss, Method::Box] {
        let p = FilterParams::new(m, 3);
        let (e2, e1) = (
            estimate_bytes(&job, &p, &two, block),
            estimate_bytes(&job, &p, &one, block),
        );
        // A strip more of the horizontal pass at the least (f64 rows
        // of the output width, three channels).
        assert!(e2 >= e1 + (strip * 2048 * 3 * 8) as u64, "{m:?}: {e2} {e1}");
        // Between the two: the same strips, one in flight.
        let c = fit_memory(&job, &p, &two, block, e1).unwrap().0;
        assert_eq!(
            (c.strips_in_flight(), job.strip_rows(&c)),
            (1, strip),
            "{m:?}"
        );
    }
    // One worker, and the stages of other methods: one strip.
    let lone = PipelineConfig {
        threads: 1,
        ..PipelineConfig::default()
    };
    assert_eq!(lone.strips_in_flight(), 1);
    assert_eq!(strips_in_flight(&two, Method::Gauss, 3), 2);
    for (m, s) in [
        (Method::EpBox, 1),
        (Method::EpGauss, 1),
        (Method::Median, 3),
    ] {
        assert_eq!(strips_in_flight(&two, m, s), 1, "{m:?}");
    }
}

#[test]
fn the_window_holds_two_blocks_a_thread_at_most() {
    let job = rgb(6144, 6144);
    let block = 6144 * 3 * 4 * 16;
    let p = FilterParams::new(Method::EpGauss, 3);
    let at = |threads| {
        // Sized for `threads`, run on 2; the strips and the sink's rows
        // as on 2 threads (they follow the threads too).
        let cfg = PipelineConfig {
            threads: 2,
            geometry_threads: threads,
            strip_rows: 56,
            write_ahead: 2 << 20,
            ..PipelineConfig::default()
        };
        (
            window_blocks(&cfg, block),
            estimate_bytes(&job, &p, &cfg, block),
        )
    };
    let by_bytes = READ_AHEAD_BATCHES * read_ahead_blocks(block);
    assert_eq!(at(1).0, 2);
    assert_eq!(at(2).0, 4);
    assert_eq!(at(64).0, by_bytes);
    // Fewer blocks are less memory, by the blocks' bytes: decoded, and
    // their compressed pages (counted at most as much).
    assert_eq!(at(64).1 - at(1).1, 2 * (by_bytes - 2) * block);
}

#[test]
fn blocks_inflated_in_place_hold_no_scratch() {
    let block = 32769 * 3 * 4 * 16;
    let cfg = PipelineConfig {
        threads: 16,
        ..PipelineConfig::default()
    };
    let mut job = rgb(32769, 3600);
    for m in [Method::Box, Method::Gauss, Method::EpGauss] {
        let p = FilterParams::new(m, 3);
        job.block_scratch = true;
        let exr = estimate_bytes(&job, &p, &cfg, block);
        job.block_scratch = false;
        let zip = estimate_bytes(&job, &p, &cfg, block);
        assert_eq!(exr - zip, 16 * block, "{m:?}");
    }
}

#[test]
fn the_accumulators_count_their_own_kernels_reach() {
    // ep-gauss at S = 3: the output grid's kernels reach a few rows
    // (the wider ones go on the coarse grids), so its accumulator holds
    // fewer rows than the widest kernel's reach twice over.
    let (job, block) = (rgb(6144, 6144), 6144 * 3 * 4 * 16);
    let mut p = FilterParams::new(Method::EpGauss, 3);
    let cfg = PipelineConfig::default();
    let [fine, r2, r4] = crate::filter::grid_reaches(&p);
    let spread = crate::filter::halo(&p).spread_reach;
    assert!(fine < spread / 4 && r2 > 0 && r4 > 0, "{fine} {r2} {r4}");
    let coarse = estimate_bytes(&job, &p, &cfg, block);
    // Without the coarse grids every width is on the output grid.
    p.coarse_from = 0.0;
    assert_eq!(crate::filter::grid_reaches(&p), [spread, 0, 0]);
    // The wide kernels' rows on coarse grids of half and a quarter the
    // rows and width cost less than on the output grid.
    assert!(estimate_bytes(&job, &p, &cfg, block) > coarse);
}

#[test]
fn own_pages_are_at_least_the_mapping_threshold_and_hold_nothing() {
    let small: Vec<f32> = own_pages(10);
    assert!(small.is_empty());
    assert!(small.capacity() * 4 >= MAPPED_ALLOCATION_BYTES);
    let rows: Vec<f64> = own_pages(MAPPED_ALLOCATION_BYTES);
    assert!(rows.is_empty() && rows.capacity() >= MAPPED_ALLOCATION_BYTES);
}

#[test]
fn the_mapped_input_counts_each_block_as_stored_at_most_as_decoded() {
    let (mut job, block) = (rgb(6144, 6144), 6144 * 3 * 4 * 16);
    let p = FilterParams::new(Method::Box, 3);
    let cfg = PipelineConfig {
        window_blocks: 4,
        ..Default::default()
    };
    let decoded = estimate_bytes(&job, &p, &cfg, block);
    job.stored_block_bytes = block / 3;
    let stored = estimate_bytes(&job, &p, &cfg, block);
    // The window's four blocks' mapped pages, a third of their size.
    assert_eq!(decoded - stored, 4 * (block - block / 3));
    // A block stored larger than it decodes (a chunk's header, or other
    // parts' chunks between) counts as decoded.
    job.stored_block_bytes = 2 * block;
    assert_eq!(estimate_bytes(&job, &p, &cfg, block), decoded);
}
