//! Filter an EXR file with the library, as the `epfilt filter` command does:
//!
//! `cargo run --release --example filter_file -- IN.exr OUT.exr [S]`
//!
//! The whole job streams: memory depends on the width, not the height, so the
//! same code filters a gigapixel render on a small server (make one with the
//! `fireflies` example: `fireflies big.exr 32769 30000`).

use epfilt::{filter_file, FilterJob, FilterParams, Method};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: filter_file IN.exr OUT.exr [SUPERSAMPLE]");
        std::process::exit(2);
    }
    let s: usize = args.get(3).and_then(|v| v.parse().ok()).unwrap_or(3);
    let job = FilterJob::new(&args[1], &args[2], FilterParams::new(Method::EpGauss, s));
    match filter_file(&job, &|done, total| eprint!("\r{done}/{total} rows")) {
        Ok(report) => eprint!("\n{}", report.summary()),
        Err(e) => {
            eprintln!("\nfilter_file: {e}");
            std::process::exit(2);
        }
    }
}
