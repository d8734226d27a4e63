//! The command line as clap sees it: raw flags, no side effects. `main.rs`
//! turns them into the library's validated jobs.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

/// The exit statuses, in every `--help`.
pub const EXIT_HELP: &str =
    "Outputs: a file is written whole or not at all (a temporary file renamed into \
place); a symbolic link is written through; - is standard output; directories, devices and FIFOs \
are refused. The format is the name's extension's (.exr; .hdr or .pic; .png for preview), or \
--format's for - and names without one.\n\nInputs: - is standard input (an OpenEXR file or a \
Radiance picture, told apart by its first bytes). It is spooled to an unnamed temporary file in \
$TMPDIR first, since an EXR's offset table may point anywhere in it; the file disappears when \
epfilt ends. A reader that closes the pipe early ends the run quietly with status 0.\n\n\
Exit status: 0 done; 1 the work failed (a damaged or unsupported input, an I/O error, an \
unbalanced ledger, a compare threshold exceeded); 2 a usage error (bad arguments); 130 / 143 \
interrupted by SIGINT / SIGTERM (unfinished outputs removed).";

/// Examples of `filter`, under its `--help`.
const FILTER_EXAMPLES: &str = "Examples:
  epfilt filter render_3x.exr out.exr                     ep-gauss at S = 3, the defaults
  epfilt filter in.exr out.exr -s 4 --tolerance 0.1       a stricter Relation 14
  epfilt filter pt.exr out.exr --method ep-box --d 5      per-pixel variance (§5.1)
  cat in.hdr | epfilt filter - - > out.hdr                a pipe, as pfilt is used
  epfilt filter 'in/r.####.exr' 'out/r.####.exr' --skip-existing   a sequence, retried
  epfilt filter huge.exr part.exr --band env --band-count 8         one band of an array job
  epfilt filter stereo.exr out.exr --view all             every view of a stereo file";

#[derive(Parser)]
#[command(
    name = "epfilt",
    version,
    about = "Energy-preserving non-linear filters for HDR renders (Rushmeier & Ward 1994)",
    after_help = EXIT_HELP
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand)]
pub enum Command {
    /// Filter a super-sampled EXR (or Radiance picture) into an output-resolution one.
    #[command(after_long_help = FILTER_EXAMPLES)]
    Filter(Box<FilterArgs>),
    /// Show what an EXR file or Radiance picture holds: size, channels, compression, layout.
    Info {
        /// The file (- for standard input).
        input: PathBuf,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        /// Also list every header attribute as stored (as `oiiotool --info -v`).
        #[arg(long)]
        attributes: bool,
    },
    /// Render a noisy synthetic scene with exact ground truth (streamed: any size).
    Synth(Box<SynthArgs>),
    /// Compare an image with a reference: RMSE, relative MSE, PSNR, energy
    /// ratio; with --max-*, exit 1 when a threshold is exceeded (as idiff does).
    Compare(Box<CompareArgs>),
    /// Write an sRGB PNG of one image, or a labelled montage of several
    /// (`preview A.exr B.exr ... OUT.png --montage`).
    Preview(Box<PreviewArgs>),
    /// Put the bands of `filter --band K/N` together into one EXR (copying
    /// their compressed blocks): the file one run over the whole image gives.
    Merge {
        /// The band files (any order), then the output EXR.
        #[arg(required = true, num_args = 2..)]
        paths: Vec<PathBuf>,
        /// The output's format where its name does not end in .exr: exr.
        #[arg(long)]
        format: Option<String>,
        /// Write the summary as JSON to this file.
        #[arg(long)]
        report: Option<PathBuf>,
        /// No summary.
        #[arg(long, short = 'q')]
        quiet: bool,
    },
    /// Predict a run on more cores from its `filter --trace` file: work T1,
    /// span T∞, and the wall time and speed-up on each number of cores.
    ScalingModel {
        /// The trace (`filter --trace FILE`).
        trace: PathBuf,
        /// Numbers of cores to predict.
        #[arg(long, value_delimiter = ',', default_value = "1,2,4,8,16,32,64")]
        cores: Vec<usize>,
        /// Print JSON: {"work_s", "span_s", "predicted_s": {"1": .., ...}, ...}.
        #[arg(long)]
        json: bool,
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
    /// Print a shell completion script: `epfilt completions bash > /etc/bash_completion.d/epfilt`.
    Completions {
        /// bash, zsh, fish, elvish or powershell.
        shell: clap_complete::Shell,
    },
    /// Print the manual page (roff): `epfilt man > epfilt.1`.
    Man,
}

#[derive(Args)]
pub struct SynthArgs {
    /// Noisy output (.exr or .hdr; - for standard output).
    #[arg(short = 'o', long)]
    pub output: PathBuf,
    /// Truth output (output resolution, f32).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// The files' format where their names do not say: exr or hdr [default for -: exr].
    #[arg(long)]
    pub format: Option<String>,
    /// light-edge, penumbra, glossy, caustic, mixed or lights.
    #[arg(long, default_value = "mixed")]
    pub scene: String,
    /// Output size in pixels, WxH.
    #[arg(long, default_value = "512x512")]
    pub size: String,
    /// Samples per pixel along each axis: writes S*W x S*H, one sample each.
    #[arg(long, short = 's', default_value_t = 3)]
    pub supersample: usize,
    /// Instead: the mean of N samples per pixel (W x H), for the ep-box filter.
    #[arg(long)]
    pub spp: Option<usize>,
    /// With --spp: also write per-pixel sample variance (variance.R/G/B) and N
    /// in the header attribute `spp`.
    #[arg(long)]
    pub variance: bool,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Hot radiance over the base (dynamic range), e.g. 1e3..1e5.
    #[arg(long, default_value_t = 1e4)]
    pub hot: f64,
    /// Compression of the files.
    #[arg(long, default_value = "zip")]
    pub compression: String,
    /// Worker threads, 0 = one per core (does not change the bytes).
    #[arg(long, default_value_t = 0, env = "EPFILT_THREADS")]
    pub threads: usize,
    /// No progress bar and no summary.
    #[arg(long, short = 'q')]
    pub quiet: bool,
}

/// Which image of a file: shared by compare and preview.
#[derive(Args)]
pub struct SelectArgs {
    /// Part of a multi-part file, by name or index.
    #[arg(long)]
    pub part: Option<String>,
    /// Layer whose R,G,B (or Y) channels are the image, e.g. ViewLayer.Combined
    /// [default: the unlayered channels, else a beauty-named layer, else the only one].
    #[arg(long)]
    pub layer: Option<String>,
}

#[derive(Args)]
pub struct CompareArgs {
    /// The image (- for standard input).
    pub a: PathBuf,
    /// The reference.
    pub b: PathBuf,
    #[command(flatten)]
    pub select: SelectArgs,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Exit 1 when the RMSE is above this.
    #[arg(long)]
    pub max_rmse: Option<f64>,
    /// Exit 1 when the relative MSE is above this.
    #[arg(long)]
    pub max_rel_mse: Option<f64>,
    /// Exit 1 when any channel's energy ratio is further than this from 1.
    #[arg(long)]
    pub max_energy_error: Option<f64>,
}

#[derive(Args)]
pub struct PreviewArgs {
    /// Input image(s) (- for standard input), then the output PNG (- for standard output).
    #[arg(required = true, num_args = 2..)]
    pub paths: Vec<PathBuf>,
    #[command(flatten)]
    pub select: SelectArgs,
    /// The output's format where its name does not end in .png: png.
    #[arg(long)]
    pub format: Option<String>,
    /// Exposure in stops on top of the average-to-mid-grey mapping.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub exposure: f64,
    /// Place the inputs side by side with labels (file names, or --labels).
    #[arg(long)]
    pub montage: bool,
    /// Comma-separated labels for the montage.
    #[arg(long)]
    pub labels: Option<String>,
}

/// Statistics and noise test of ep-box, shared by `filter` and `plan`.
#[derive(Args)]
pub struct StatsArgs {
    /// Variance channel (luminance) or layer with .R/.G/.B [default: found by
    /// name] (ep-box; ep-gauss at S = 1, whose carriers rule reads it when found).
    #[arg(long)]
    pub variance_channel: Option<String>,
    /// What the variance holds: sample (of single samples), mean (of the
    /// pixel mean) or moment (E[Y^2]) [default: guessed from the name].
    #[arg(long)]
    pub variance_kind: Option<String>,
    /// Samples per pixel [default: the header's spp/samples attribute].
    #[arg(long)]
    pub spp: Option<u32>,
    /// Channel holding each pixel's sample count.
    #[arg(long)]
    pub spp_channel: Option<String>,
    /// Allowed interval ±D, in units of L_tvis.
    #[arg(long, default_value_t = 5.0)]
    pub d: f64,
    /// N_MID, the display level the mean luminance maps to (Eq. 9).
    #[arg(long, default_value_t = 128.0)]
    pub nmid: f64,
    /// Confidence of the noise test (0.8, 80 or 80%).
    #[arg(long, default_value = "80%")]
    pub confidence: String,
}

#[derive(Args)]
pub struct PlanArgs {
    /// Pilot render with variance (e.g. 100x100 at 16 samples per pixel).
    pub input: PathBuf,
    #[command(flatten)]
    pub stats: StatsArgs,
    /// Largest radiance, for Purgathofer's worst case (Eq. 8) [default: the pilot's brightest pixel].
    #[arg(long)]
    pub lmax: Option<f64>,
    #[command(flatten)]
    pub select: SelectArgs,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Args)]
pub struct FilterArgs {
    /// Input (super-sampled render: EXR, or Radiance .hdr/.pic; - for standard
    /// input), or a frame sequence: render.####.exr (one padded digit per #)
    /// or render.%04d.exr.
    pub input: PathBuf,
    /// Output (.exr, .hdr or .pic; - for standard output, in the input's
    /// format unless --format); for a sequence, a pattern with a frame field.
    pub output: PathBuf,

    // ---- Input ----
    /// Input samples per output pixel along each axis (1..=8) [default: 3; 1 for ep-box].
    #[arg(long, short = 's', help_heading = "Input")]
    pub supersample: Option<usize>,
    /// Part of a multi-part input, by name or index, or `all` (every part
    /// filtered into one multi-part output). With one part, at S = 1 the
    /// others are copied bit for bit; at S > 1 they are left out, with a warning.
    #[arg(long, help_heading = "Input")]
    pub part: Option<String>,
    /// A size that is not a multiple of S: crop drops the last partial output
    /// column and row; pad keeps them as pixels of fewer samples, each kernel
    /// normalised over what exists, energy exact [default: refuse, naming the options].
    #[arg(long, help_heading = "Input")]
    pub edge: Option<String>,
    /// NaN and infinite input samples: error (refuse, naming the first) or zero (count them).
    #[arg(long, default_value = "error", help_heading = "Input")]
    pub nonfinite: String,

    // ---- Method ----
    /// ep-gauss (§5.2), ep-box (§5.1, pixels with variance), gauss (linear
    /// foil), box (S x S average), or the energy-losing foils clamp, median
    /// and alpha-trim.
    #[arg(long, default_value = "ep-gauss", help_heading = "Method")]
    pub method: String,
    /// Base Gaussian radius in output pixels (weight exp(-(d/r)^2)): ep-gauss,
    /// gauss, clamp [default: 0.6; ep-gauss: its --quality's].
    #[arg(long, help_heading = "Method")]
    pub radius: Option<f64>,
    /// Largest Gaussian radius a noisy sample may get, in output pixels
    /// (ep-box: the largest spread radius, in pixels) [default: ep-gauss: its
    /// --quality's; ep-box: 8].
    #[arg(long, help_heading = "Method")]
    pub max_radius: Option<f64>,
    /// Kernel cut-off in radii [default: 3; ep-gauss: its --quality's].
    #[arg(long, help_heading = "Method")]
    pub cutoff: Option<f64>,
    /// What keeps real features from being spread. ep-box: all (default:
    /// carriers + range + stderr), carriers, range, stderr, both (range +
    /// stderr), none (§5.1 as written). ep-gauss: none (§5.2 as written)
    /// turns off its --support rule (and at S = 1 its carriers rule).
    #[arg(long, default_value = "all", help_heading = "Method")]
    pub guard: String,
    /// clamp: the largest sample value kept, per channel (then the base Gaussian).
    #[arg(long, default_value_t = 10.0, help_heading = "Method")]
    pub clamp: f64,
    /// alpha-trim: the fraction of the sorted samples trimmed from each end (0..0.5).
    #[arg(long, default_value_t = 0.25, help_heading = "Method")]
    pub alpha: f64,

    // ---- ep-gauss ----
    /// A point on ep-gauss's speed/accuracy front (docs/pareto.md): a set of
    /// the knob values below, which each given option overrides.
    #[arg(long, value_name = "fast|default|best", help_heading = "ep-gauss",
          long_help = quality_help())]
    pub quality: Option<String>,
    /// Relation 14 tolerance, at this S [default: --quality's, given at S = 3
    /// and scaled as 0.25 at 3 is to 0.15 at 4: t*(3/S)^1.776].
    #[arg(long, help_heading = "ep-gauss")]
    pub tolerance: Option<f64>,
    /// A noisy sample with at least this many noisy neighbouring
    /// super-samples (within --support-ratio of it) is a feature and keeps the
    /// base kernel; at S = 1 on a file with variance, so does a pixel whose
    /// mean enough samples carry (ep-box's carriers rule and --carriers*
    /// settings). 0 = the paper's rule, neither [default: --quality's].
    #[arg(long, help_heading = "ep-gauss")]
    pub support: Option<usize>,
    /// Neighbours support a sample when within this factor of its luminance
    /// [default: --quality's].
    #[arg(long, help_heading = "ep-gauss")]
    pub support_ratio: Option<f64>,
    /// A sample with fewer than --support supporting neighbours is kept when
    /// its group (the samples joined to it through supporting neighbours,
    /// within 2 super-samples) holds at least this many: the runs of hits
    /// along a thin line or a rim (0 = off) [default: --quality's].
    #[arg(long, help_heading = "ep-gauss")]
    pub support_group: Option<usize>,
    /// A sample with one supporting neighbour (fewer than --support) is kept
    /// when at most this many super-samples within 2 of it fail the test: a
    /// compact pair, a bulb a fraction of a pixel wide (0 = off) [default:
    /// --quality's].
    #[arg(long, help_heading = "ep-gauss")]
    pub support_compact: Option<usize>,
    /// ... and when it is at least this many times the median box luminance
    /// of the eight pixels about its own: a bulb is hundreds of times its
    /// room, two fireflies that touch rarely are (0 = any) [default:
    /// --quality's].
    #[arg(long, help_heading = "ep-gauss")]
    pub support_over: Option<f64>,
    /// A bright sample with fewer than --support noisy neighbours is kept too
    /// when at least this many super-samples within 2 of it are comparable:
    /// above its pixel's average and within --support-level of it (grain
    /// inside a glossy highlight, not a firefly on a dark ground; 0 = off)
    /// [default: --quality's].
    #[arg(long, help_heading = "ep-gauss")]
    pub support_region: Option<usize>,
    /// See --support-region: comparable is within this factor of the sample,
    /// which is itself at most this many times its pixel's average
    /// [default: --quality's].
    #[arg(long, help_heading = "ep-gauss")]
    pub support_level: Option<f64>,
    /// Relative step of the ladder of widths the search picks from (its
    /// precision) [default: --quality's].
    #[arg(long, help_heading = "ep-gauss")]
    pub width_step: Option<f64>,
    /// Spread widths of this radius (output pixels) and more on a 2x coarser
    /// grid, and from twice it on a 4x coarser grid, brought back with a tent
    /// per halving: a quarter (a sixteenth) of the taps, energy exact, no
    /// pixel given more than the full-resolution kernel would; 0 = off.
    #[arg(long, default_value_t = epfilt::filter::DEFAULT_COARSE_FROM, help_heading = "ep-gauss")]
    pub coarse_from: f64,

    // ---- ep-box ----
    #[command(flatten, next_help_heading = "ep-box")]
    pub stats: StatsArgs,
    /// The visibility threshold L_tvis [default: mean luminance / N_MID, Eq. 9].
    #[arg(long, help_heading = "ep-box")]
    pub ltvis: Option<f64>,
    /// Most passes over clusters of noisy pixels.
    #[arg(long, default_value_t = 8, help_heading = "ep-box")]
    pub passes: usize,
    /// Carriers guard: a pixel whose mean rests on at least this many samples
    /// (n Y^2 / (var + Y^2)) is not noise...
    #[arg(long, default_value_t = 16.0, help_heading = "ep-box")]
    pub carriers: f64,
    /// ... nor one whose mean rests on at least this fraction of its samples
    /// and whose relative standard error is at most --carriers-rse.
    #[arg(long, default_value_t = 0.2, help_heading = "ep-box")]
    pub carriers_fraction: f64,
    /// See --carriers-fraction.
    #[arg(long, default_value_t = 0.5, help_heading = "ep-box")]
    pub carriers_rse: f64,
    /// Confidence of the stderr guard's bound on the excess noise can explain.
    #[arg(long, default_value_t = 0.99, help_heading = "ep-box")]
    pub guard_confidence: f64,

    // ---- Channels ----
    /// Layer whose R,G,B (or Y) channels are filtered, e.g. ViewLayer.Combined
    /// [default: the unlayered channels, else a beauty-named layer, else the only one].
    #[arg(long, help_heading = "Channels")]
    pub layer: Option<String>,
    /// A multi-view (stereo) file: the view to filter, or all (each view
    /// filtered as an image of its own, into one output) [default: the first
    /// view; the others are left out, with a warning].
    #[arg(long, help_heading = "Channels")]
    pub view: Option<String>,
    /// What a channel beside the beauty gets, PATTERN=RULE (glob on the full name; repeatable, the
    /// last match wins): additive (spread with the beauty's kernels: light AOVs that sum to it),
    /// average (the base filter; copied at S = 1: depth, normals, albedo), nearest (the centre
    /// sample: ids, masks), drop [default: by name; `epfilt info` shows each channel's rule].
    #[arg(
        long = "channel-rule",
        value_name = "PATTERN=RULE",
        help_heading = "Channels"
    )]
    pub channel_rule: Vec<String>,

    // ---- Output ----
    /// The output's format where its name does not say (- or a name without
    /// an image extension): exr or hdr [default for -: the input's].
    #[arg(long, help_heading = "Output")]
    pub format: Option<String>,
    /// Output compression (none rle zips zip piz pxr24 b44 b44a dwaa dwab) [default: as input, but zip
    /// where the input's is lossy].
    #[arg(long, help_heading = "Output")]
    pub compression: Option<String>,
    /// Accept a lossy output compression (dwaa, dwab; b44, b44a for f16; pxr24 for f32): the energy on
    /// disk is then measured by decoding the file, and reported.
    #[arg(long, help_heading = "Output")]
    pub allow_lossy: bool,
    /// Output sample type: same (each channel its input type: f16 stays f16,
    /// the others f32), f32 or f16 for all (f16 refuses values it cannot hold).
    #[arg(long, default_value = "same", help_heading = "Output")]
    pub pixel_type: String,
    /// Write the summary as JSON to this file (- for standard output).
    #[arg(long, help_heading = "Output")]
    pub report: Option<PathBuf>,
    /// Record every unit of work of the run (reads, filter tasks, writes)
    /// as Chrome trace-event JSON in this file (Perfetto, chrome://tracing);
    /// `epfilt scaling-model FILE` predicts the run on more cores.
    #[arg(long, help_heading = "Output")]
    pub trace: Option<PathBuf>,
    /// No progress bar and no summary (warnings about data are still printed).
    #[arg(long, short = 'q', help_heading = "Output")]
    pub quiet: bool,

    // ---- Farm ----
    /// Sequence: the frames to filter, e.g. 1-240, 1-100x2, 3,4,10-20x5
    /// [default: the input frames on disk].
    #[arg(long, help_heading = "Farm")]
    pub frames: Option<String>,
    /// Sequence: this task's 0-based index; it filters the index-th of
    /// --task-count contiguous chunks of the frames [default: from the
    /// environment: SLURM_ARRAY_TASK_ID, JOB_COMPLETION_INDEX, AWS_BATCH_JOB_ARRAY_INDEX].
    #[arg(long, help_heading = "Farm")]
    pub task_index: Option<usize>,
    /// Sequence: how many tasks share the frames [default: SLURM_ARRAY_TASK_COUNT,
    /// AWS_BATCH_JOB_ARRAY_SIZE; needed for Kubernetes Indexed Jobs].
    #[arg(long, help_heading = "Farm")]
    pub task_count: Option<usize>,
    /// Leave outputs that are already complete outputs of their input and
    /// these settings (a retried farm task redoes only what is missing or
    /// unfinished; anything else at an output's name is redone, saying why).
    #[arg(long, help_heading = "Farm")]
    pub skip_existing: bool,
    /// Sequence: stop at the first failed frame.
    #[arg(long, conflicts_with = "keep_going", help_heading = "Farm")]
    pub fail_fast: bool,
    /// Sequence: go on past a failed frame and exit 1 at the end (the default).
    #[arg(long, help_heading = "Farm")]
    pub keep_going: bool,
    /// Filter only band K of N of the output rows (K from 1: 3/8 is the
    /// third of eight), reading the input rows they need; `epfilt merge` puts
    /// the bands together, identical to one run. `env`: K and N from the
    /// array job's environment (as --task-index). A sequence's band files are
    /// named NAME.bandKofN.exr, never a frame's name.
    #[arg(long, help_heading = "Farm")]
    pub band: Option<String>,
    /// The band's 0-based index, as --task-index counts (with --band-count).
    #[arg(long, help_heading = "Farm")]
    pub band_index: Option<usize>,
    /// How many bands; without --band-index, the index comes from the array
    /// job's environment (SLURM_ARRAY_TASK_ID, ...).
    #[arg(long, help_heading = "Farm")]
    pub band_count: Option<usize>,

    // ---- Performance ----
    /// Worker threads, 0 = one per core (does not change the result; more
    /// than the machine's cores are capped, with a warning).
    #[arg(
        long,
        default_value_t = 0,
        env = "EPFILT_THREADS",
        help_heading = "Performance"
    )]
    pub threads: usize,
    /// Refuse jobs estimated to need more memory than this, in MiB [default: half the machine's memory].
    #[arg(long, env = "EPFILT_MAX_MEMORY", help_heading = "Performance")]
    pub max_memory: Option<u64>,
    /// Accumulator tile width in output pixels (does not change the result).
    #[arg(long, default_value_t = 256, help_heading = "Performance")]
    pub tile: usize,
    /// Input rows per strip, 0 = automatic (about 4 MiB of input, at least 6 pixel rows; does not
    /// change the result).
    #[arg(long, default_value_t = 0, help_heading = "Performance")]
    pub strip_rows: usize,
}

/// `--quality`'s long help: every preset's knob values.
fn quality_help() -> String {
    let mut s = String::from(
        "A point on ep-gauss's speed/accuracy front, chosen on real renders \
         (scripts/eval-renders --sweep, docs/pareto.md): a set of knob values, which each \
         option given overrides. The report records the preset and the values used.",
    );
    for q in epfilt::filter::Quality::ALL {
        s.push_str(&format!("\n  {:<8} {}", q.name(), q.describe()));
    }
    s
}

/// The ids of the options that decide a method's settings (the ones a
/// method may ignore), as clap names them.
pub const METHOD_OPTIONS: &[&str] = &[
    "quality",
    "support_group",
    "support_compact",
    "support_over",
    "support_region",
    "support_level",
    "radius",
    "max_radius",
    "cutoff",
    "guard",
    "clamp",
    "alpha",
    "tolerance",
    "support",
    "support_ratio",
    "width_step",
    "coarse_from",
    "variance_channel",
    "variance_kind",
    "spp",
    "spp_channel",
    "d",
    "nmid",
    "confidence",
    "ltvis",
    "passes",
    "carriers",
    "carriers_fraction",
    "carriers_rse",
    "guard_confidence",
];
