//! Open and filter arbitrary bytes as an EXR or a Radiance picture (the
//! reader goes by the magic bytes): any panic or abort is a bug.
//! Run with `scripts/fuzz SECONDS` (not in CI).
#![no_main]

use epfilt::{filter_file, FilterJob, FilterParams, Method, PipelineConfig, Precision};
use libfuzzer_sys::fuzz_target;

fuzz_target!(
    // libFuzzer aborts on any panic, even one epfilt catches: let through only
    // those outside a codec (a codec's panic on damaged data is caught and
    // reported as an error, as the binary does).
    init: epfilt::io::reader::quiet_decoder_panics(),
    |data: &[u8]| {
    let Ok(dir) = tempfile::tempdir() else { return };
    let input = dir.path().join("in.exr");
    if std::fs::write(&input, data).is_err() {
        return;
    }
    // The first byte picks the method and super-sampling, so one corpus
    // exercises every path.
    let pick = data.first().copied().unwrap_or(0);
    let method = Method::ALL[(pick % 7) as usize];
    let s = if method == Method::EpBox { 1 } else { 1 + (pick as usize / 7) % 3 };
    let mut job = FilterJob::new(input, dir.path().join("out.exr"), FilterParams::new(method, s));
    job.pipeline = PipelineConfig { threads: 1, ..Default::default() };
    job.output_settings.precision = Some(Precision::F32);
    // Multi-part files: part 0 (the others copied at S = 1) or every part.
    job.part = Some(if pick & 0x20 == 0 {
        epfilt::io::PartSelect::Index(0)
    } else {
        epfilt::io::PartSelect::All
    });
    job.max_memory = Some(256 << 20);
    // ep-box: the first colour channel doubles as a luminance variance,
    // so any file with colour reaches the engine.
    job.stats = epfilt::io::StatsRequest {
        variance_channel: Some(if pick & 0x80 == 0 { "R" } else { "Y" }.into()),
        spp: Some(16),
        ..Default::default()
    };
    // Sizes that are not a multiple of S are cropped or padded, so more
    // files filter.
    job.edge = if pick & 0x40 == 0 {
        epfilt::job::Edge::Crop
    } else {
        epfilt::job::Edge::Pad
    };
    let _ = filter_file(&job, &|_, _| {});
    }
);
