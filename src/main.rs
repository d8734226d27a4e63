//! The `epfilt` command: parse, call the library, report, exit.
//! Errors print as one line (`epfilt: <file>: <cause>`). Exit status: 0 done,
//! 1 the work failed, 2 a usage error, 128 + the signal when interrupted
//! (130 SIGINT, 143 SIGTERM).

use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};
use epfilt::filter::channels::RuleOverride;
use epfilt::io::{parse_compression, OutputSettings, PartSelect};
use epfilt::pipeline::NonFinite;
use epfilt::synth::{Sampling, Scene, SceneKind, SynthJob};
use epfilt::{FilterJob, FilterParams, Method, PipelineConfig, Precision};
use indicatif::{ProgressBar, ProgressStyle};

/// The exit statuses, in every `--help`.
const EXIT_HELP: &str =
    "Outputs: a file is written whole or not at all (a temporary file renamed into \
place); a symbolic link is written through; - is standard output; directories, devices and FIFOs \
are refused.\n\nExit status: 0 done; 1 the work failed (a damaged or unsupported input, an I/O \
error, an unbalanced ledger); 2 a usage error (bad arguments); 130 / 143 interrupted by SIGINT / \
SIGTERM (unfinished outputs removed).";

#[derive(Parser)]
#[command(
    name = "epfilt",
    version,
    about = "Energy-preserving non-linear filters for HDR renders (Rushmeier & Ward 1994)",
    after_help = EXIT_HELP
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Filter a super-sampled EXR into an output-resolution EXR.
    Filter(Box<FilterArgs>),
    /// Show an EXR's size, channels, compression and layout.
    Info {
        /// EXR file.
        input: PathBuf,
    },
    /// Render a noisy synthetic scene with exact ground truth (streamed: any size).
    Synth(Box<SynthArgs>),
    /// Compare an image with a reference: RMSE, relative MSE, PSNR, energy ratio.
    Compare {
        /// The image.
        a: PathBuf,
        /// The reference.
        b: PathBuf,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Write an sRGB PNG of one EXR, or a labelled montage of several
    /// (`preview A.exr B.exr ... OUT.png --montage`).
    Preview {
        /// Input EXR file(s), then the output PNG.
        #[arg(required = true, num_args = 2..)]
        paths: Vec<PathBuf>,
        /// Exposure in stops on top of the average-to-mid-grey mapping.
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        exposure: f64,
        /// Place the inputs side by side with labels (file names, or --labels).
        #[arg(long)]
        montage: bool,
        /// Comma-separated labels for the montage.
        #[arg(long)]
        labels: Option<String>,
    },
    /// Put the bands of `filter --band K/N` together into one EXR (copying
    /// their compressed blocks): the file one run over the whole image gives.
    Merge {
        /// The band files (any order), then the output EXR.
        #[arg(required = true, num_args = 2..)]
        paths: Vec<PathBuf>,
        /// Write the summary as JSON to this file.
        #[arg(long)]
        report: Option<PathBuf>,
        /// No summary.
        #[arg(long, short = 'q')]
        quiet: bool,
    },
    /// Plan a render from a pilot with variance (§5.1, Eqs. 8-10): L_tvis, the
    /// mean standard error, and the samples per pixel needed for ±D.
    Plan(Box<PlanArgs>),
    /// Build a noisy scene with known truth, filter it with every method, and
    /// print how close each comes to the truth.
    Demo {
        /// Folder for the demo's files.
        #[arg(default_value = "demo-out")]
        dir: PathBuf,
        /// Output size in pixels, WxH.
        #[arg(long, default_value = "320x200")]
        size: String,
    },
}

#[derive(Args)]
struct SynthArgs {
    /// Noisy output EXR.
    #[arg(short = 'o', long)]
    output: PathBuf,
    /// Truth output EXR (output resolution, f32).
    #[arg(long)]
    truth: Option<PathBuf>,
    /// light-edge, penumbra, glossy, caustic or mixed.
    #[arg(long, default_value = "mixed")]
    scene: String,
    /// Output size in pixels, WxH.
    #[arg(long, default_value = "512x512")]
    size: String,
    /// Samples per pixel along each axis: writes S*W x S*H, one sample each.
    #[arg(long, short = 's', default_value_t = 3)]
    supersample: usize,
    /// Instead: the mean of N samples per pixel (W x H), for the ep-box filter.
    #[arg(long)]
    spp: Option<usize>,
    /// With --spp: also write per-pixel sample variance (variance.R/G/B) and N
    /// in the header attribute `spp`.
    #[arg(long)]
    variance: bool,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Hot radiance over the base (dynamic range), e.g. 1e3..1e5.
    #[arg(long, default_value_t = 1e4)]
    hot: f64,
    /// Compression of the files.
    #[arg(long, default_value = "zip")]
    compression: String,
    /// Worker threads, 0 = one per core (does not change the bytes).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// No progress bar and no summary.
    #[arg(long, short = 'q')]
    quiet: bool,
}

/// Statistics and noise test of ep-box, shared by `filter` and `plan`.
#[derive(Args)]
struct StatsArgs {
    /// ep-box (and ep-gauss at S = 1, whose carriers rule reads it when found):
    /// variance channel (luminance) or layer with .R/.G/.B [default: found by name].
    #[arg(long)]
    variance_channel: Option<String>,
    /// ep-box: what the variance holds: sample (of single samples), mean (of the
    /// pixel mean) or moment (E[Y^2]) [default: guessed from the name].
    #[arg(long)]
    variance_kind: Option<String>,
    /// ep-box: samples per pixel [default: the header's spp/samples attribute].
    #[arg(long)]
    spp: Option<u32>,
    /// ep-box: channel holding each pixel's sample count.
    #[arg(long)]
    spp_channel: Option<String>,
    /// ep-box: allowed interval ±D, in units of L_tvis.
    #[arg(long, default_value_t = 5.0)]
    d: f64,
    /// ep-box: N_MID, the display level the mean luminance maps to (Eq. 9).
    #[arg(long, default_value_t = 128.0)]
    nmid: f64,
    /// ep-box: confidence of the noise test (0.8, 80 or 80%).
    #[arg(long, default_value = "80%")]
    confidence: String,
}

impl StatsArgs {
    fn request(&self) -> Result<epfilt::io::StatsRequest> {
        Ok(epfilt::io::StatsRequest {
            variance_channel: self.variance_channel.clone(),
            kind: self
                .variance_kind
                .as_deref()
                .map(epfilt::filter::ep_box::VarianceKind::parse)
                .transpose()?,
            spp: self.spp,
            spp_channel: self.spp_channel.clone(),
        })
    }

    fn params(&self) -> Result<epfilt::filter::ep_box::EpBoxParams> {
        let c = self.confidence.trim();
        let (num, pct) = match c.strip_suffix('%') {
            Some(n) => (n, true),
            None => (c, false),
        };
        let v: f64 = num
            .trim()
            .parse()
            .with_context(|| format!("--confidence {c:?} is not a number"))?;
        let confidence = if pct || v > 1.0 { v / 100.0 } else { v };
        let p = epfilt::filter::ep_box::EpBoxParams {
            d: self.d,
            nmid: self.nmid,
            confidence,
            ..Default::default()
        };
        p.validate()?;
        Ok(p)
    }
}

#[derive(Args)]
struct PlanArgs {
    /// Pilot render with variance (e.g. 100x100 at 16 samples per pixel).
    input: PathBuf,
    #[command(flatten)]
    stats: StatsArgs,
    /// Largest radiance, for Purgathofer's worst case (Eq. 8) [default: the pilot's brightest pixel].
    #[arg(long)]
    lmax: Option<f64>,
    /// Part of a multi-part input, by name or index.
    #[arg(long)]
    part: Option<String>,
    /// Layer whose R,G,B (or Y) channels are filtered, e.g. ViewLayer.Combined
    /// [default: the unlayered channels, else a beauty-named layer, else the only one].
    #[arg(long)]
    layer: Option<String>,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
struct FilterArgs {
    /// Input EXR (super-sampled render), or a frame sequence: render.####.exr
    /// (one padded digit per #) or render.%04d.exr.
    input: PathBuf,
    /// Output EXR (written to a temporary file, renamed on success); for a
    /// sequence, a pattern with a frame field too.
    output: PathBuf,
    /// Sequence: the frames to filter, e.g. 1-240, 1-100x2, 3,4,10-20x5
    /// [default: the input frames on disk].
    #[arg(long)]
    frames: Option<String>,
    /// Sequence: this task's 0-based index; it filters the index-th of
    /// --task-count contiguous chunks of the frames [default: from the
    /// environment: SLURM_ARRAY_TASK_ID, JOB_COMPLETION_INDEX, AWS_BATCH_JOB_ARRAY_INDEX].
    #[arg(long)]
    task_index: Option<usize>,
    /// Sequence: how many tasks share the frames [default: SLURM_ARRAY_TASK_COUNT,
    /// AWS_BATCH_JOB_ARRAY_SIZE; needed for Kubernetes Indexed Jobs].
    #[arg(long)]
    task_count: Option<usize>,
    /// Leave outputs that already exist (a retried farm task redoes only what is missing).
    #[arg(long)]
    skip_existing: bool,
    /// Sequence: stop at the first failed frame.
    #[arg(long, conflicts_with = "keep_going")]
    fail_fast: bool,
    /// Sequence: go on past a failed frame and exit 1 at the end (the default).
    #[arg(long)]
    keep_going: bool,
    /// Method: ep-gauss (§5.2), ep-box (§5.1, pixels with variance), gauss
    /// (linear foil), box (S x S average), or the energy-losing foils clamp,
    /// median and alpha-trim.
    #[arg(long, default_value = "ep-gauss")]
    method: String,
    /// Input samples per output pixel along each axis (1..=8) [default: 3; 1 for ep-box].
    #[arg(long, short = 's')]
    supersample: Option<usize>,
    /// Filter only band K of N of the output rows (e.g. 3/8), reading the input
    /// rows they need; `epfilt merge` puts the bands together, identical to one run.
    #[arg(long)]
    band: Option<String>,
    /// A size that is not a multiple of S: crop drops the last partial output
    /// column and row (the samples beyond the last whole output pixel); pad
    /// keeps them as pixels of fewer samples, each kernel normalised over
    /// what exists, energy exact [default: refuse, naming the options].
    #[arg(long)]
    edge: Option<String>,
    /// Relation 14 tolerance [default: 0.25 at S=3, 0.15 at S=4; 0.25*(3/S)^1.776 otherwise].
    #[arg(long)]
    tolerance: Option<f64>,
    /// Base Gaussian radius in output pixels (weight exp(-(d/r)^2)).
    #[arg(long, default_value_t = 0.6)]
    radius: f64,
    /// Largest Gaussian radius a noisy sample may get, in output pixels
    /// (ep-box: the largest spread radius, in pixels) [default: 16; ep-box: 8].
    #[arg(long)]
    max_radius: Option<f64>,
    #[command(flatten)]
    stats: StatsArgs,
    /// clamp: the largest sample value kept, per channel (then the base Gaussian).
    #[arg(long, default_value_t = 10.0)]
    clamp: f64,
    /// alpha-trim: the fraction of the sorted samples trimmed from each end (0..0.5).
    #[arg(long, default_value_t = 0.25)]
    alpha: f64,
    /// ep-box: the visibility threshold L_tvis [default: mean luminance / N_MID, Eq. 9].
    #[arg(long)]
    ltvis: Option<f64>,
    /// ep-box: most passes over clusters of noisy pixels.
    #[arg(long, default_value_t = 8)]
    passes: usize,
    /// Guard against taking real features for noise. ep-box: all (default:
    /// carriers + range + stderr), carriers (noise only when few samples carry
    /// the mean), range (not above a converged neighbour), stderr (spread no
    /// more than noise can explain), both (range + stderr), none (§5.1 as
    /// written). ep-gauss: none (§5.2 as written) turns off its --support
    /// rule (and at S = 1 its carriers rule); any other value keeps them.
    #[arg(long, default_value = "all")]
    guard: String,
    /// ep-box, carriers guard: a pixel whose mean rests on at least this many
    /// samples (n Y^2 / (var + Y^2)) is not noise...
    #[arg(long, default_value_t = 16.0)]
    carriers: f64,
    /// ... nor one whose mean rests on at least this fraction of its samples
    /// and whose relative standard error is at most --carriers-rse.
    #[arg(long, default_value_t = 0.2)]
    carriers_fraction: f64,
    /// See --carriers-fraction.
    #[arg(long, default_value_t = 0.5)]
    carriers_rse: f64,
    /// ep-gauss: a noisy sample with at least this many noisy neighbouring
    /// super-samples (within --support-ratio of it) is a feature and keeps the
    /// base kernel; at S = 1 on a file with variance, so does a pixel whose
    /// mean enough samples carry (ep-box's carriers rule and --carriers*
    /// settings). 0 = the paper's rule, neither.
    #[arg(long, default_value_t = 1)]
    support: usize,
    /// ep-gauss: neighbours support a sample when within this factor of its luminance.
    #[arg(long, default_value_t = 16.0)]
    support_ratio: f64,
    /// ep-box: confidence of the stderr guard's bound on the excess noise can explain.
    #[arg(long, default_value_t = 0.99)]
    guard_confidence: f64,
    /// Kernel cut-off in radii.
    #[arg(long, default_value_t = 3.0)]
    cutoff: f64,
    /// Relative step of the ladder of widths the search picks from (its precision).
    #[arg(long, default_value_t = 0.1)]
    width_step: f64,
    /// ep-gauss: spread widths of this radius (output pixels) and more on a 2x
    /// coarser grid, and from twice it on a 4x coarser grid, brought back with
    /// a tent per halving: a quarter (a sixteenth) of the taps, energy exact,
    /// no pixel given more than the full-resolution kernel would; 0 = off.
    #[arg(long, default_value_t = epfilt::filter::DEFAULT_COARSE_FROM)]
    coarse_from: f64,
    /// Output compression (none rle zips zip piz pxr24 b44 b44a dwaa dwab) [default: as input, but zip
    /// where the input's is lossy].
    #[arg(long)]
    compression: Option<String>,
    /// Accept a lossy output compression (dwaa, dwab; b44, b44a for f16; pxr24 for f32): the energy on
    /// disk is then measured by decoding the file, and reported.
    #[arg(long)]
    allow_lossy: bool,
    /// Output sample type: same (each channel its input type: f16 stays f16,
    /// the others f32), f32 or f16 for all (f16 refuses values it cannot hold).
    #[arg(long, default_value = "same")]
    pixel_type: String,
    /// Part of a multi-part input, by name or index, or `all` (every part
    /// filtered into one multi-part output). With one part, at S = 1 the
    /// others are copied bit for bit; at S > 1 they are left out, with a warning.
    #[arg(long)]
    part: Option<String>,
    /// Layer whose R,G,B (or Y) channels are filtered, e.g. ViewLayer.Combined
    /// [default: the unlayered channels, else a beauty-named layer, else the only one].
    #[arg(long)]
    layer: Option<String>,
    /// What a channel beside the beauty gets, PATTERN=RULE (glob on the full name; repeatable, the
    /// last match wins): additive (spread with the beauty's kernels: light AOVs that sum to it),
    /// average (the base filter; copied at S = 1: depth, normals, albedo), nearest (the centre
    /// sample: ids, masks), drop [default: by name; `epfilt info` shows each channel's rule].
    #[arg(long = "channel-rule", value_name = "PATTERN=RULE")]
    channel_rule: Vec<String>,
    /// NaN and infinite input samples: error (refuse, naming the first) or zero (count them).
    #[arg(long, default_value = "error")]
    nonfinite: String,
    /// Refuse jobs estimated to need more memory than this, in MiB [default: half the machine's memory].
    #[arg(long)]
    max_memory: Option<u64>,
    /// Accumulator tile width in output pixels (does not change the result).
    #[arg(long, default_value_t = 256)]
    tile: usize,
    /// Input rows per strip, 0 = automatic (about 4 MiB of input; does not change the result).
    #[arg(long, default_value_t = 0)]
    strip_rows: usize,
    /// Worker threads, 0 = one per core (does not change the result).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Write the summary as JSON to this file.
    #[arg(long)]
    report: Option<PathBuf>,
    /// No progress bar and no summary.
    #[arg(long, short = 'q')]
    quiet: bool,
}

/// glibc keeps freed multi-megabyte row buffers in per-thread arenas (its
/// mmap threshold grows with each such free), so at 32k-wide inputs peak RSS
/// was ~60 MiB above the live heap. Buffers of 4 MiB and more now go straight
/// back to the system; a 32 MiB trim threshold keeps the heap from shrinking
/// and regrowing on every strip. Measured (32769-wide S=3, ep-gauss): peak RSS
/// 284 -> 223 MiB; 6144^2 runs as fast as without tuning (2.1 s).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn tune_allocator() {
    // SAFETY: mallopt only changes glibc's allocation thresholds; it is called
    // once, first thing in main, before any other thread exists.
    #[allow(unsafe_code)]
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 4 * 1024 * 1024);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 32 * 1024 * 1024);
        // glibc gives threads up to 8 arenas per core, each keeping up to
        // the trim threshold of freed memory, so peak memory grew with the
        // thread count. Four arenas, measured on a 12288x12288 ZIP input at
        // 16 threads: box 243 -> 163 MiB (62 at 2 threads), no slower on
        // 2 cores.
        libc::mallopt(libc::M_ARENA_MAX, 4);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn tune_allocator() {}

/// A file-size limit (`ulimit -f`) must be an ordinary write error, so the
/// temporary file is removed and the user gets one line: by default SIGXFSZ
/// kills the process and leaves the temporary file behind.
#[cfg(unix)]
fn ignore_file_size_signal() {
    // SAFETY: setting a signal's disposition to SIG_IGN installs no handler
    // code; done once, first thing in main.
    #[allow(unsafe_code)]
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
}

#[cfg(not(unix))]
fn ignore_file_size_signal() {}

/// How a command ends when it does not succeed.
enum Exit {
    /// The command line asks for something that cannot be done: status 2.
    Usage(anyhow::Error),
    /// The work failed: status 1 (or the signal's status when interrupted).
    Failure(anyhow::Error),
}

fn usage(e: impl Into<anyhow::Error>) -> Exit {
    Exit::Usage(e.into())
}

fn fail(e: impl Into<anyhow::Error>) -> Exit {
    Exit::Failure(e.into())
}

/// The error and the causes it does not already spell out, as one line.
fn one_line(e: &anyhow::Error) -> String {
    epfilt::error::one_line(e.as_ref())
}

/// SIGINT and SIGTERM: raise `cancel` for the library, remove the temporary
/// files of unfinished outputs, say so in one line and exit with 128 + the
/// signal. A thread, not a handler: it may do all of that safely.
fn watch_signals(cancel: Arc<AtomicBool>) {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM]) else {
        return;
    };
    let _ = std::thread::Builder::new()
        .name("epfilt-signals".into())
        .spawn(move || {
            if let Some(sig) = signals.forever().next() {
                cancel.store(true, Ordering::Relaxed);
                epfilt::io::destination::remove_unfinished();
                let name = if sig == SIGINT { "SIGINT" } else { "SIGTERM" };
                // Off the progress bar's line, where there is one.
                let nl = if std::io::stderr().is_terminal() {
                    "\n"
                } else {
                    ""
                };
                eprintln!("{nl}epfilt: interrupted by {name}; unfinished outputs removed");
                std::process::exit(128 + sig);
            }
        });
}

fn main() {
    tune_allocator();
    ignore_file_size_signal();
    epfilt::io::reader::quiet_decoder_panics();
    let cancel = Arc::new(AtomicBool::new(false));
    watch_signals(cancel.clone());
    // clap prints usage errors itself and exits with status 2.
    let cli = Cli::parse();
    let code = match dispatch(cli, cancel) {
        Ok(()) => 0,
        Err(Exit::Usage(e)) => {
            eprintln!("epfilt: {}", one_line(&e));
            2
        }
        Err(Exit::Failure(e)) => {
            eprintln!("epfilt: {}", one_line(&e));
            // The library's configuration and output-path refusals are usage
            // errors too: the arguments do not fit the files.
            match e.downcast_ref::<epfilt::Error>() {
                Some(epfilt::Error::Interrupted) => 130,
                Some(epfilt::Error::Config(_) | epfilt::Error::Output { .. }) => 2,
                _ => 1,
            }
        }
    };
    std::process::exit(code);
}

/// Refuse to write binary data (an EXR or a PNG) to a terminal.
fn check_binary_stdout(path: &std::path::Path) -> Result<(), Exit> {
    if path.as_os_str() == "-" && std::io::stdout().is_terminal() {
        return Err(usage(anyhow::anyhow!(
            "standard output is a terminal: redirect it (epfilt ... - > out.exr) or name an output file"
        )));
    }
    Ok(())
}

fn dispatch(cli: Cli, cancel: Arc<AtomicBool>) -> Result<(), Exit> {
    match cli.command {
        Command::Filter(args) => filter(*args, cancel),
        Command::Info { input } => {
            print!("{}", epfilt::io::info(&input).map_err(fail)?);
            Ok(())
        }
        Command::Synth(args) => synth(*args),
        Command::Compare { a, b, json } => {
            let cmp = epfilt::compare::compare_files(&a, &b).map_err(fail)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&cmp).map_err(fail)?);
            } else {
                let names = epfilt::io::ExrInput::open(&b, None)
                    .map_err(fail)?
                    .channels();
                print!("{}", cmp.table(&names));
            }
            Ok(())
        }
        Command::Preview {
            mut paths,
            exposure,
            montage,
            labels,
        } => {
            let out = paths
                .pop()
                .context("preview needs an output PNG")
                .map_err(usage)?;
            if paths.len() > 1 && !montage {
                return Err(usage(anyhow::anyhow!("several inputs need --montage")));
            }
            check_binary_stdout(&out)?;
            let labels: Vec<String> = match &labels {
                Some(l) => l.split(',').map(|s| s.trim().to_string()).collect(),
                None if montage => paths
                    .iter()
                    .map(|p| {
                        p.file_stem()
                            .map(|s| s.to_string_lossy().into_owned())
                            .unwrap_or_default()
                    })
                    .collect(),
                None => vec![String::new()],
            };
            if labels.len() != paths.len() {
                return Err(usage(anyhow::anyhow!(
                    "{} labels for {} inputs",
                    labels.len(),
                    paths.len()
                )));
            }
            let inputs: Vec<_> = paths.into_iter().zip(labels).collect();
            epfilt::preview::write_png(&inputs, &out, exposure).map_err(fail)?;
            Ok(())
        }
        Command::Plan(a) => {
            let request = a.stats.request().map_err(usage)?;
            let params = a.stats.params().map_err(usage)?;
            let plan = epfilt::plan::plan_file(
                &a.input,
                a.part.as_deref().map(PartSelect::parse).as_ref(),
                a.layer.as_deref(),
                &request,
                &params,
                a.lmax,
            )
            .map_err(fail)?;
            if a.json {
                println!("{}", serde_json::to_string_pretty(&plan).map_err(fail)?);
            } else {
                print!("{}", plan.table());
            }
            Ok(())
        }
        Command::Merge {
            mut paths,
            report,
            quiet,
        } => {
            let out = paths
                .pop()
                .context("merge needs an output")
                .map_err(usage)?;
            check_binary_stdout(&out)?;
            let r = epfilt::merge::merge(&paths, &out).map_err(fail)?;
            if let Some(path) = &report {
                let json = serde_json::to_string_pretty(&r).map_err(fail)? + "\n";
                epfilt::io::write_file(path, json.as_bytes()).map_err(fail)?;
            }
            if !quiet {
                eprint!("{}", r.summary());
            }
            Ok(())
        }
        Command::Demo { dir, size } => {
            let (w, h) = parse_size(&size).map_err(usage)?;
            let text = epfilt::demo::run(&dir, w, h, &|line| eprintln!("{line}")).map_err(fail)?;
            print!("{text}");
            Ok(())
        }
    }
}

fn parse_size(s: &str) -> Result<(usize, usize)> {
    let (w, h) = s
        .split_once('x')
        .with_context(|| format!("size {s:?} is not WxH"))?;
    Ok((w.parse().context("width")?, h.parse().context("height")?))
}

fn synth(a: SynthArgs) -> Result<(), Exit> {
    let (w, h) = parse_size(&a.size).map_err(usage)?;
    let sampling = match a.spp {
        Some(n) => Sampling::Spp(n),
        None if a.variance => return Err(usage(anyhow::anyhow!("--variance goes with --spp N"))),
        None => Sampling::Supersample(a.supersample),
    };
    check_binary_stdout(&a.output)?;
    if a.truth.as_deref() == Some(std::path::Path::new("-")) && a.output.as_os_str() == "-" {
        return Err(usage(anyhow::anyhow!(
            "the output and --truth cannot both be standard output"
        )));
    }
    let job = SynthJob {
        scene: Scene {
            kind: SceneKind::parse(&a.scene).map_err(usage)?,
            w,
            h,
            seed: a.seed,
            hot: a.hot,
        },
        sampling,
        output: a.output,
        truth: a.truth,
        variance: a.variance,
        compression: parse_compression(&a.compression)
            .with_context(|| format!("unknown --compression {:?}", a.compression))
            .map_err(usage)?,
        threads: a.threads,
    };
    let bar = progress_bar(a.quiet);
    let report = epfilt::synth::synth(&job, &|done, total| {
        if let Some(b) = &bar {
            b.set_length(total as u64);
            b.set_position(done as u64);
        }
    });
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let r = report.map_err(fail)?;
    if !a.quiet {
        eprintln!(
            "{}: {}x{}{} in {:.2} s{}",
            r.output,
            r.width,
            r.height,
            r.truth
                .as_ref()
                .map(|t| format!(", truth {t}"))
                .unwrap_or_default(),
            r.seconds,
            r.peak_rss_bytes
                .map(|b| format!(", peak RSS {:.0} MiB", b as f64 / (1 << 20) as f64))
                .unwrap_or_default()
        );
    }
    Ok(())
}

fn progress_bar(quiet: bool) -> Option<ProgressBar> {
    if quiet || !std::io::stderr().is_terminal() {
        return None;
    }
    let b = ProgressBar::new(0);
    b.set_style(
        ProgressStyle::with_template(
            "{spinner} {msg} {wide_bar} {pos}/{len} rows  {elapsed_precise} eta {eta}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    Some(b)
}

/// The filter job the arguments describe (every check that needs no file).
fn filter_job(a: &FilterArgs, cancel: Arc<AtomicBool>) -> Result<FilterJob> {
    let method = Method::parse(&a.method)?;
    let s = a
        .supersample
        .unwrap_or(if method == Method::EpBox { 1 } else { 3 });
    let mut params = FilterParams::new(method, s);
    params.ep_box = epfilt::filter::ep_box::EpBoxParams {
        ltvis: a.ltvis,
        passes: a.passes,
        guard: epfilt::filter::ep_box::Guard::parse(&a.guard)?,
        guard_confidence: a.guard_confidence,
        carriers: a.carriers,
        carriers_fraction: a.carriers_fraction,
        carriers_rse: a.carriers_rse,
        ..a.stats.params()?
    };
    params.radius = a.radius;
    params.support = if a.guard == "none" { 0 } else { a.support };
    params.support_ratio = a.support_ratio;
    params.clamp = a.clamp;
    params.alpha = a.alpha;
    if let Some(r) = a.max_radius {
        params.max_radius = r;
    }
    params.cutoff = a.cutoff;
    params.width_step = a.width_step;
    params.coarse_from = a.coarse_from;
    if let Some(t) = a.tolerance {
        params.tolerance = t;
    }
    params.validate()?;
    let precision = match a.pixel_type.as_str() {
        "same" => None,
        "f32" | "float" => Some(Precision::F32),
        "f16" | "half" => Some(Precision::F16),
        other => anyhow::bail!("--pixel-type must be same, f32 or f16, not {other:?}"),
    };
    let compression = match &a.compression {
        Some(c) => {
            Some(parse_compression(c).with_context(|| format!("unknown --compression {c:?}"))?)
        }
        None => None,
    };
    if a.output.as_os_str() == "-" && a.report.as_deref() == Some(std::path::Path::new("-")) {
        anyhow::bail!("the output and --report cannot both be standard output");
    }
    Ok(FilterJob {
        input: a.input.clone(),
        output: a.output.clone(),
        params,
        pipeline: PipelineConfig {
            tile: a.tile,
            strip_rows: a.strip_rows,
            threads: a.threads,
            cancel: Some(cancel),
            nonfinite: match a.nonfinite.as_str() {
                "error" => NonFinite::Error,
                "zero" => NonFinite::Zero,
                other => anyhow::bail!("--nonfinite must be error or zero, not {other:?}"),
            },
        },
        output_settings: OutputSettings {
            compression,
            precision,
            allow_lossy: a.allow_lossy,
            provenance: None,
            extra: Vec::new(),
        },
        part: a.part.as_deref().map(PartSelect::parse),
        layer: a.layer.clone(),
        max_memory: a.max_memory.map(|m| m.saturating_mul(1 << 20)),
        stats: a.stats.request()?,
        edge: match &a.edge {
            Some(e) => epfilt::job::Edge::parse(e)?,
            None => epfilt::job::Edge::Exact,
        },
        supersample_assumed: a.supersample.is_none() && s > 1,
        band: a
            .band
            .as_deref()
            .map(|b| -> Result<(usize, usize)> {
                let (k, n) = b
                    .split_once('/')
                    .with_context(|| format!("--band {b:?} is not K/N"))?;
                Ok((
                    k.trim()
                        .parse()
                        .with_context(|| format!("--band {b:?}: K"))?,
                    n.trim()
                        .parse()
                        .with_context(|| format!("--band {b:?}: N"))?,
                ))
            })
            .transpose()?,
        channel_rules: a
            .channel_rule
            .iter()
            .map(|r| RuleOverride::parse(r))
            .collect::<Result<_, _>>()?,
    })
}

fn filter(a: FilterArgs, cancel: Arc<AtomicBool>) -> Result<(), Exit> {
    use epfilt::sequence::FramePattern;
    let input_pattern = FramePattern::parse(&a.input).map_err(usage)?;
    let output_pattern = FramePattern::parse(&a.output).map_err(usage)?;
    match (input_pattern, output_pattern) {
        (Some(i), Some(o)) => return filter_sequence(&a, i, o, cancel),
        (Some(i), None) => {
            return Err(usage(anyhow::anyhow!(
                "the input {i} is a frame sequence: give the output a frame field too (e.g. out/render.####.exr)"
            )))
        }
        (None, Some(o)) => {
            return Err(usage(anyhow::anyhow!(
                "the output {o} has a frame field but the input {} does not",
                a.input.display()
            )))
        }
        (None, None) => {}
    }
    if a.frames.is_some() || a.task_index.is_some() || a.task_count.is_some() {
        return Err(usage(anyhow::anyhow!(
            "--frames, --task-index and --task-count need a frame sequence (render.####.exr)"
        )));
    }
    let job = filter_job(&a, cancel).map_err(usage)?;
    check_binary_stdout(&a.output)?;
    if a.skip_existing && std::fs::metadata(&a.output).is_ok_and(|m| m.is_file()) {
        if !a.quiet {
            eprintln!("{}: exists, skipped (--skip-existing)", a.output.display());
        }
        return Ok(());
    }
    // Check the report's path now, not after a long run.
    if let Some(path) = &a.report {
        epfilt::io::Destination::resolve(path).map_err(fail)?;
    }
    let bar = progress_bar(a.quiet);
    let progress = |done: usize, total: usize| {
        if let Some(b) = &bar {
            b.set_length(total as u64);
            b.set_position(done as u64);
        }
    };
    let report = epfilt::filter_file(&job, &progress);
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let report = report.map_err(fail)?;
    for w in &report.warnings {
        eprintln!("epfilt: warning: {w}");
    }
    if let Some(path) = &a.report {
        let json = serde_json::to_string_pretty(&report).map_err(fail)? + "\n";
        epfilt::io::write_file(path, json.as_bytes()).map_err(fail)?;
    }
    if !a.quiet {
        eprint!("{}", report.summary());
    }
    Ok(())
}

/// A frame sequence, or this task's share of it: each frame as `filter`
/// would do it, a line per frame, a summary, and exit 1 when any failed.
fn filter_sequence(
    a: &FilterArgs,
    input: epfilt::sequence::FramePattern,
    output: epfilt::sequence::FramePattern,
    cancel: Arc<AtomicBool>,
) -> Result<(), Exit> {
    use epfilt::sequence::{parse_frames, run_sequence, task_from, FrameStatus, SequenceJob};
    if input.to_string() == output.to_string() {
        return Err(usage(anyhow::anyhow!(
            "the output pattern {output} is the input's: each frame would overwrite its input"
        )));
    }
    let template = filter_job(a, cancel).map_err(usage)?;
    let frames = match &a.frames {
        Some(spec) => parse_frames(spec).map_err(usage)?,
        None => input.on_disk().map_err(usage)?,
    };
    let task = task_from(a.task_index, a.task_count, &|k| std::env::var(k).ok()).map_err(usage)?;
    if let Some(&first) = frames.first() {
        let folder = output.path(first);
        if let Some(dir) = folder.parent().filter(|d| !d.as_os_str().is_empty()) {
            if !dir.is_dir() {
                return Err(usage(anyhow::anyhow!(
                    "{}: the output folder does not exist",
                    dir.display()
                )));
            }
        }
    }
    if let Some(path) = &a.report {
        epfilt::io::Destination::resolve(path).map_err(fail)?;
    }
    let job = SequenceJob {
        template,
        input,
        output,
        frames,
        task,
        skip_existing: a.skip_existing,
        fail_fast: a.fail_fast,
    };
    let bar = progress_bar(a.quiet);
    let progress = |done: usize, total: usize| {
        if let Some(b) = &bar {
            b.set_length(total as u64);
            b.set_position(done as u64);
        }
    };
    let quiet = a.quiet;
    let on_frame = |e: epfilt::sequence::FrameEvent<'_>| {
        let (k, n, frame) = (e.position, e.of, e.frame);
        let Some(o) = e.outcome else {
            if let Some(b) = &bar {
                b.set_message(format!("frame {frame} [{}/{n}]", k + 1));
            }
            return;
        };
        let line = match o.status {
            FrameStatus::Failed => {
                format!(
                    "epfilt: frame {frame}: {}",
                    o.error.as_deref().unwrap_or("failed")
                )
            }
            _ if quiet => return,
            FrameStatus::Skipped => format!(
                "frame {frame} [{}/{n}]: {} exists, skipped",
                k + 1,
                o.output
            ),
            FrameStatus::Done => {
                let worst = o.report.as_ref().map_or(0.0, |r| {
                    r.energy_rel_error
                        .iter()
                        .fold(0.0f64, |m, e| m.max(e.abs()))
                });
                format!(
                    "frame {frame} [{}/{n}]: {} in {:.2} s, ledger {worst:.1e}",
                    k + 1,
                    o.output,
                    o.seconds
                )
            }
            FrameStatus::NotRun => return,
        };
        match &bar {
            Some(b) => b.println(line),
            None => eprintln!("{line}"),
        }
    };
    let report = run_sequence(&job, &on_frame, &progress);
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let report = report.map_err(fail)?;
    if let Some(path) = &a.report {
        let json = serde_json::to_string_pretty(&report).map_err(fail)? + "\n";
        epfilt::io::write_file(path, json.as_bytes()).map_err(fail)?;
    }
    if !a.quiet {
        eprint!("{}", report.summary());
    }
    if report.failed > 0 {
        return Err(fail(anyhow::anyhow!(
            "{} of {} frames failed{}",
            report.failed,
            report.frames.len(),
            if report.not_run > 0 {
                format!(" ({} not run: --fail-fast)", report.not_run)
            } else {
                String::new()
            }
        )));
    }
    Ok(())
}
