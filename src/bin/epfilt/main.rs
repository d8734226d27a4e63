//! The `epfilt` command: parse, call the library, report, exit.
//! Errors print as one line (`epfilt: <file>: <cause>`). Exit status: 0 done
//! (also when the reader of standard output closed it early), 1 the work
//! failed, 2 a usage error, 128 + the signal when interrupted (130 SIGINT,
//! 143 SIGTERM).

mod args;
mod filter;
mod options;

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{Context, Result};
use clap::{CommandFactory, FromArgMatches};
use epfilt::io::{parse_compression, Format, PartSelect, Selection};
use epfilt::synth::{Sampling, Scene, SceneKind, SynthJob};
use indicatif::{ProgressBar, ProgressStyle};

use args::{Cli, Command, CompareArgs, LookArgs, PreviewArgs, RestoreArgs, SelectArgs, SynthArgs};

fn main() {
    tune_allocator();
    ignore_file_size_signal();
    epfilt::io::reader::quiet_decoder_panics();
    let cancel = Arc::new(AtomicBool::new(false));
    watch_signals(cancel.clone());
    // clap prints usage errors itself and exits with status 2.
    let matches = Cli::command().get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    let code = match dispatch(cli, cancel) {
        Ok(()) => 0,
        // The reader of standard output went away: what it wanted it has.
        Err(Exit::Failure(e) | Exit::Usage(e) | Exit::Status(_, e)) if is_broken_pipe(&e) => 0,
        Err(Exit::Usage(e)) => {
            eprintln!("epfilt: {}", one_line(&e));
            2
        }
        Err(Exit::Status(code, e)) => {
            eprintln!("epfilt: {}", one_line(&e));
            code
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

fn dispatch(cli: Cli, cancel: Arc<AtomicBool>) -> Result<(), Exit> {
    match cli.command {
        Command::Filter(args) => filter::run(*args, cancel),
        Command::Info {
            input,
            json,
            attributes,
        } => {
            let info = epfilt::io::info::describe(&input).map_err(fail)?;
            if json {
                emit(&(serde_json::to_string_pretty(&info).map_err(fail)? + "\n"))
            } else {
                emit(&info.text(attributes))
            }
        }
        Command::Synth(args) => synth(*args),
        Command::Compare(a) => compare(*a),
        Command::Restore(a) => restore(*a, cancel),
        Command::Preview(a) => preview(*a),
        Command::Plan(a) => {
            let (opts, _) =
                epfilt::job::FilterOptions::from_settings(a.stats.settings).map_err(usage)?;
            let request = opts.stats_request();
            let (params, _) = (opts.params_for(epfilt::Method::EpBox, 1, &[]))
                .and_then(|(p, w)| Ok((p.validated()?, w)))
                .map_err(usage)?;
            let select = selection(&a.select);
            let plan = epfilt::plan::plan_file(
                &a.input,
                select.part.as_ref(),
                select.layer.as_deref(),
                &request,
                &params,
                a.lmax,
            )
            .map_err(fail)?;
            if a.json {
                emit(&(serde_json::to_string_pretty(&plan).map_err(fail)? + "\n"))
            } else {
                emit(&plan.table())
            }
        }
        Command::Merge {
            paths,
            format,
            report,
            json,
            quiet,
        } => merge(paths, format, report.or(json.then(|| "-".into())), quiet),
        Command::Demo { dir, size } => {
            let (w, h) = parse_size(&size).map_err(usage)?;
            let text = epfilt::demo::run(&dir, w, h, &|line| eprintln!("{line}")).map_err(fail)?;
            emit(&text)
        }
        Command::Completions { shell } => {
            let mut out = Vec::new();
            clap_complete::generate(shell, &mut Cli::command(), "epfilt", &mut out);
            emit_bytes(&out)
        }
        Command::Man { dir: Some(dir) } => {
            let written = std::fs::create_dir_all(&dir)
                .and_then(|()| clap_mangen::generate_to(Cli::command(), &dir));
            written.map_err(|e| fail(epfilt::Error::io(dir.clone(), e)))?;
            eprintln!("epfilt: manual pages written to {}", dir.display());
            Ok(())
        }
        Command::Man { dir: None } => {
            let mut out = Vec::new();
            clap_mangen::Man::new(Cli::command())
                .render(&mut out)
                .map_err(fail)?;
            emit_bytes(&out)
        }
    }
}

fn selection(a: &SelectArgs) -> Selection {
    Selection {
        part: a.part.as_deref().map(PartSelect::parse),
        layer: a.layer.clone(),
    }
}

/// `compare`'s statuses, as OpenImageIO's idiff has them.
mod compare_status {
    /// Beyond a `--warn-*` limit, within every `--max-*` one.
    pub const WARN: i32 = 1;
    /// Beyond a `--max-*` limit.
    pub const FAIL: i32 = 2;
    /// The images differ in size or channels.
    pub const MISMATCH: i32 = 3;
    /// A file could not be read.
    pub const FILE: i32 = 4;
}

/// `merge`: the band files, then the output.
fn merge(
    mut paths: Vec<PathBuf>,
    format: Option<String>,
    report: Option<PathBuf>,
    quiet: bool,
) -> Result<(), Exit> {
    let out = paths
        .pop()
        .context("merge needs an output")
        .map_err(usage)?;
    let format = format
        .as_deref()
        .map(Format::parse)
        .transpose()
        .map_err(usage)?;
    check_binary_stdout(&out)?;
    // The bands' pixels together are the image's.
    let pixels = || {
        let select = epfilt::io::Selection::default();
        (paths.iter())
            .map(|p| image_pixels(p, &select))
            .sum::<Option<f64>>()
    };
    let merged = with_progress(quiet, pixels, |p| {
        epfilt::merge::merge(&paths, &out, format, p)
    });
    let r = merged.map_err(fail)?;
    if let Some(path) = &report {
        write_report(path, &r)?;
    }
    if !quiet {
        eprint!("{}", r.summary());
    }
    Ok(())
}

fn compare(a: CompareArgs) -> Result<(), Exit> {
    read_stdin(a.quiet, [a.a.as_path(), a.b.as_path()]);
    let select = selection(&a.select);
    let pixels = || image_pixels(&a.a, &select).map(|px| 2.0 * px);
    let compared = with_progress(a.quiet, pixels, |p| {
        epfilt::compare::compare_files(&a.a, &a.b, &select, p)
    });
    let cmp = compared.map_err(|e| {
        let code = match e {
            epfilt::Error::Mismatch { .. } => compare_status::MISMATCH,
            _ => compare_status::FILE,
        };
        Exit::Status(code, e.into())
    })?;
    if let Some(png) = &a.diff {
        check_binary_stdout(png)?;
        let mut settings = look(&a.look, true)?;
        settings.select = select.clone();
        let pixels = || image_pixels(&a.a, &select).map(|px| 2.0 * px);
        with_progress(a.quiet, pixels, |p| {
            epfilt::preview::write_diff_png(&a.a, &a.b, png, &settings, p)
        })
        .map_err(|e| Exit::Status(compare_status::FILE, e.into()))?;
    }
    if a.json {
        emit(&(serde_json::to_string_pretty(&cmp).map_err(fail)? + "\n"))?;
    } else {
        let names = (select.open(&a.b))
            .map_err(|e| Exit::Status(compare_status::FILE, e.into()))?
            .channels();
        emit(&cmp.table(&names))?;
    }
    let limits = |rmse, rel_mse, energy| epfilt::compare::Thresholds {
        max_rmse: rmse,
        max_rel_mse: rel_mse,
        max_energy_error: energy,
    };
    let fail_at = limits(a.max_rmse, a.max_rel_mse, a.max_energy_error);
    let warn_at = limits(a.warn_rmse, a.warn_rel_mse, a.warn_energy_error);
    for (over, code) in [
        (cmp.exceeded(&fail_at), compare_status::FAIL),
        (cmp.exceeded(&warn_at), compare_status::WARN),
    ] {
        if !over.is_empty() {
            let what = format!(
                "{} against {}: {}",
                a.a.display(),
                a.b.display(),
                over.join("; ")
            );
            return Err(Exit::Status(code, anyhow::anyhow!(what)));
        }
    }
    Ok(())
}

fn restore(mut a: RestoreArgs, cancel: Arc<AtomicBool>) -> Result<(), Exit> {
    read_stdin(a.quiet, [a.energy.as_path(), a.denoised.as_path()]);
    if a.json {
        a.report = Some("-".into());
    }
    let opts = epfilt::job::FilterOptions::for_restore(a.opts.settings.clone()).map_err(usage)?;
    let files = (a.denoised.clone(), a.energy.clone(), a.output.clone());
    let (job, capped) = opts.restore_job(files, Some(cancel)).map_err(usage)?;
    if let Some(w) = capped {
        warn(&w);
    }
    let plan = epfilt::job::restore::RestorePlan::build(&job).map_err(fail)?;
    let (w, h) = plan.size();
    let pixels = || Some(w as f64 * h as f64);
    let r = with_progress(a.quiet, pixels, |p| plan.run(&job, p)).map_err(fail)?;
    if let Some(path) = &a.report {
        write_report(path, &r)?;
    }
    if r.nonfinite_zeroed > 0 {
        warn(&format!(
            "{}: {} non-finite energy values taken as zero",
            a.energy.display(),
            r.nonfinite_zeroed
        ));
    }
    if !r.views_left_out.is_empty() {
        warn(&format!(
            "{}: the other views left out of the output ({}): restore reads the default view",
            a.energy.display(),
            named(&r.views_left_out)
        ));
    }
    if r.counts.denoised_nonfinite > 0 {
        warn(&format!(
            "{}: {} non-finite values taken as zero",
            a.denoised.display(),
            r.counts.denoised_nonfinite
        ));
    }
    if !a.quiet {
        let worst = r.ledger.iter().map(|l| l.rel_error).fold(0.0, f64::max);
        let finest = r.levels.first().copied().unwrap_or_default();
        let c = &r.counts;
        eprintln!(
            "{}: {}x{} restored in {:.2} s; energy exact to {worst:.1e} over {}; of the {}-pixel blocks' targets {:.0}% follow the render, the rest the denoiser (uncertainty: {}); {:.2}% of the energy kept in place on evidence ({} guide, {} agreeing samples, {} the denoiser's peaks{})",
            r.output,
            r.width,
            r.height,
            r.seconds,
            exact_scales(&r),
            r.scale,
            100.0 * finest.following_render as f64 / finest.blocks.max(1) as f64,
            if r.variance_pass.is_empty() {
                "its residual against the denoiser".to_string()
            } else {
                format!("the variance pass, {}", r.variance_pass)
            },
            100.0 * r.kept_share,
            c.kept_guide,
            c.kept_variance,
            c.kept_denoiser,
            match r.keep_gain {
                Some(g) => format!(", {} over {g} times the denoiser's share: {}", c.kept_gain, r.keep_gain_from),
                None => String::new(),
            }
        );
        if let Some((noisy, combined)) = &r.blender_layers {
            eprintln!(
                "{}: the energy is Blender's render, {noisy}; the result takes the place and names of its denoised {combined}",
                r.output
            );
        }
        if !r.copied_channels.is_empty() {
            eprintln!(
                "{}: {} kept as {} has it (not in the denoiser's output)",
                r.output,
                r.copied_channels.join(", "),
                a.energy.display()
            );
        }
        if !r.carried_channels.is_empty() {
            eprintln!(
                "{}: {} channels beside the beauty carried as {} has them ({})",
                r.output,
                r.carried_channels.len(),
                a.energy.display(),
                named(&r.carried_channels)
            );
        }
    }
    Ok(())
}

/// Where a restore's energy is exact, in words: the whole image, and the
/// block sides below it where every block is the render's.
fn exact_scales(r: &epfilt::job::restore::RestoreReport) -> String {
    let top = r.levels.last().map_or(0, |l| l.side);
    let below: Vec<String> = (r.exact_scales.iter())
        .filter(|&&s| s != top)
        .map(|s| format!("{s}-pixel blocks"))
        .collect();
    if below.is_empty() {
        "the whole image".into()
    } else {
        format!("the whole image and its {}", below.join(", "))
    }
}

fn preview(a: PreviewArgs) -> Result<(), Exit> {
    read_stdin(a.quiet, a.paths.iter().rev().skip(1).map(|p| p.as_path()));
    let mut paths = a.paths;
    let out = paths
        .pop()
        .context("preview needs an output PNG")
        .map_err(usage)?;
    if paths.len() > 1 && !a.montage {
        return Err(usage(anyhow::anyhow!("several inputs need --montage")));
    }
    let format = a
        .format
        .as_deref()
        .map(Format::parse)
        .transpose()
        .map_err(usage)?;
    check_binary_stdout(&out)?;
    let labels: Vec<String> = match &a.labels {
        Some(l) => l.split(',').map(|s| s.trim().to_string()).collect(),
        None if a.montage => paths
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
    let mut settings = look(&a.look, a.false_color)?;
    settings.exposure = a.exposure;
    settings.select = selection(&a.select);
    settings.format = format;
    let pixels = || image_pixels(&inputs[0].0, &settings.select).map(|px| 2.0 * px);
    with_progress(a.quiet, pixels, |p| {
        epfilt::preview::write_png(&inputs, &out, &settings, p)
    })
    .map_err(fail)
}

/// The preview settings `--width`, `--crop` and the false-colour flags
/// give (`false_color`: whether false colour is on).
fn look(a: &LookArgs, false_color: bool) -> Result<epfilt::preview::PreviewSettings, Exit> {
    let crop = (a.crop.as_deref())
        .map(epfilt::preview::Crop::parse)
        .transpose()
        .map_err(usage)?;
    Ok(epfilt::preview::PreviewSettings {
        width: a.width,
        crop,
        false_color: false_color.then_some(epfilt::preview::FalseColor {
            top: a.fc_top,
            decades: a.fc_decades,
        }),
        ..Default::default()
    })
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
    if a.truth.as_deref() == Some(Path::new("-")) && a.output.as_os_str() == "-" {
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
        threads: capped_threads(a.threads),
        format: a
            .format
            .as_deref()
            .map(Format::parse)
            .transpose()
            .map_err(usage)?,
    };
    let samples = match job.sampling {
        Sampling::Supersample(s) => s * s,
        Sampling::Spp(_) => 1,
    };
    let pixels = || Some((w * h * samples) as f64);
    let r = with_progress(a.quiet, pixels, |p| epfilt::synth::synth(&job, p)).map_err(fail)?;
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

/// ep-box's statistics request from the flags.
/// `--threads`, capped to the machine's cores with a warning.
fn capped_threads(n: usize) -> usize {
    let (n, warning) = epfilt::job::options::cap_threads(n);
    if let Some(w) = warning {
        warn(&w);
    }
    n
}

/// A warning about the user's data or settings: printed even under `-q`.
fn warn(text: &str) {
    eprintln!("epfilt: warning: {text}");
}

/// Run `work` with a progress bar (none under `-q` or off a terminal),
/// cleared when it ends; `pixels`: the image's, for the rate.
fn with_progress<T>(
    quiet: bool,
    pixels: impl FnOnce() -> Option<f64>,
    work: impl FnOnce(epfilt::pipeline::Progress<'_>) -> T,
) -> T {
    let bar = progress_bar(quiet, pixels);
    let result = work(&|done, total| {
        if let Some(b) = &bar {
            b.set_length(total as u64);
            b.set_position(done as u64);
        }
    });
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    result
}

/// A progress bar on standard error when it is a terminal: the share done,
/// the rate in megapixels a second of `pixels` (the whole work's, when
/// known; asked only where a bar is shown), the time spent and the time
/// left. It ticks between updates: a wide strip takes seconds.
fn progress_bar(quiet: bool, pixels: impl FnOnce() -> Option<f64>) -> Option<ProgressBar> {
    if quiet || !std::io::stderr().is_terminal() {
        return None;
    }
    let pixels = pixels();
    let b = ProgressBar::new(0);
    let rate = move |s: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
        let secs = s.elapsed().as_secs_f64();
        if let (Some(px), true) = (pixels, secs > 0.5) {
            let _ = write!(w, "{:6.1} Mpx/s", s.fraction() as f64 * px / secs / 1e6);
        }
    };
    b.set_style(
        ProgressStyle::with_template(
            "{spinner} {msg} {wide_bar} {percent:>3}% {rate}  {elapsed_precise} eta {eta}",
        )
        .map(|s| s.with_key("rate", rate))
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    b.enable_steady_tick(std::time::Duration::from_millis(250));
    Some(b)
}

/// Where one of `inputs` is standard input, read it now with a spinner
/// that counts what came (none under `-q` or off a terminal): a pipe gives
/// no sign of its size, and the reading can take minutes.
fn read_stdin<'a>(quiet: bool, inputs: impl IntoIterator<Item = &'a Path>) {
    if !inputs.into_iter().any(epfilt::io::stdin::is_stdin) {
        return;
    }
    let bar = (!quiet && std::io::stderr().is_terminal()).then(|| {
        let b = ProgressBar::new_spinner();
        b.enable_steady_tick(std::time::Duration::from_millis(250));
        b
    });
    epfilt::io::stdin::read_now(&|bytes| {
        if let Some(b) = &bar {
            b.set_message(format!("reading standard input: {} MiB", bytes >> 20));
        }
    });
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
}

/// The pixels of the image `select` names in `path` (`None` where it
/// cannot be opened: the command says why).
fn image_pixels(path: &Path, select: &epfilt::io::Selection) -> Option<f64> {
    let input = select.open(path).ok()?;
    let (w, h) = input.size();
    Some(w as f64 * h as f64)
}

/// Write `--report`'s JSON (`-`: standard output).
fn write_report(path: &Path, value: &impl serde::Serialize) -> Result<(), Exit> {
    let json = serde_json::to_string_pretty(value).map_err(fail)? + "\n";
    epfilt::io::write_file(path, json.as_bytes()).map_err(fail)
}

/// Text on standard output; a reader that closed it ends the command
/// quietly (status 0), as `head` expects.
fn emit(text: &str) -> Result<(), Exit> {
    emit_bytes(text.as_bytes())
}

fn emit_bytes(bytes: &[u8]) -> Result<(), Exit> {
    let mut out = std::io::stdout().lock();
    out.write_all(bytes)
        .and_then(|_| out.flush())
        .map_err(|e| fail(epfilt::Error::io("-", e)))
}

/// Whether the error is standard output's reader going away.
fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// Refuse to write binary data (an EXR or a PNG) to a terminal.
fn check_binary_stdout(path: &Path) -> Result<(), Exit> {
    if path.as_os_str() == "-" && std::io::stdout().is_terminal() {
        return Err(usage(anyhow::anyhow!(
            "standard output is a terminal: redirect it (epfilt ... - > out.exr) or name an output file"
        )));
    }
    Ok(())
}

/// How a command ends when it does not succeed.
enum Exit {
    /// The command line asks for something that cannot be done: status 2.
    Usage(anyhow::Error),
    /// The work failed: status 1 (or the signal's status when interrupted).
    Failure(anyhow::Error),
    /// A status of the command's own (`compare`'s, as idiff's).
    Status(i32, anyhow::Error),
}

/// Up to eight names, then how many more: a Blender render carries dozens.
fn named(names: &[String]) -> String {
    const SHOWN: usize = 8;
    match names.len().checked_sub(SHOWN) {
        Some(more) if more > 0 => format!("{}, and {more} more", names[..SHOWN].join(", ")),
        _ => names.join(", "),
    }
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

/// glibc keeps freed multi-megabyte row buffers in per-thread arenas (its
/// mmap threshold grows with each such free), so on wide inputs peak RSS sat
/// far above the live heap. Large buffers go straight back to the system.
/// Each arena keeps up to the trim threshold of freed memory at its top, so
/// which thread freed last moved the peak by up to an arena's threshold from
/// run to run; 4 MiB keeps that within what `PROGRAM_BYTES` counts
/// (docs/bench/memory-gigapixel.md: the floor's peak within its budget).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn tune_allocator() {
    const MAPPED: usize = epfilt::pipeline::MAPPED_ALLOCATION_BYTES;
    // SAFETY: mallopt only changes glibc's allocation thresholds; it is called
    // once, first thing in main, before any other thread exists.
    #[allow(unsafe_code)]
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MAPPED as i32);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 4 * 1024 * 1024);
        // glibc gives threads up to 8 arenas per core, each keeping up to
        // the trim threshold of freed memory, so peak memory grew with the
        // thread count. Four arenas bound that, no slower on 2 cores.
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
