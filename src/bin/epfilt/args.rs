//! The command line as clap sees it: raw flags, no side effects. `main.rs`
//! turns them into the library's validated jobs.

use std::path::PathBuf;

use crate::options::{FilterOptionArgs, RestoreOptionArgs, StatsArgs};
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
unbalanced ledger); 2 a usage error (bad arguments); 130 / 143 interrupted by SIGINT / SIGTERM \
(unfinished outputs removed). compare's are idiff's: 0 within every limit, 1 beyond a --warn-* \
limit, 2 beyond a --max-* limit, 3 images of different sizes or channels, 4 a file unreadable.";

/// Examples of `filter`, under its `--help`.
const FILTER_EXAMPLES: &str = "Examples:
  epfilt filter render.exr out.exr                        at the render's resolution; the file decides the method and guides
  epfilt filter render_3x.exr out.exr -s 3                3x3 super-samples reduced to pixels (ep-gauss)
  epfilt filter in.exr out.exr -s 4 --tolerance 0.1       a stricter Relation 14
  epfilt filter pt.exr out.exr --method ep-box --d 5      per-pixel variance (§5.1)
  cat in.hdr | epfilt filter - - -s 3 > out.hdr           a pipe, as pfilt is used
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
    /// Filter a render (EXR or Radiance picture) at its own resolution, or reduce super-samples with --supersample.
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
    /// Put a render's energy back into a denoiser's output (OIDN, OptiX, ...):
    /// the energy of every --scale block and the total become the render's, exactly.
    #[command(after_long_help = RESTORE_EXAMPLES)]
    Restore(Box<RestoreArgs>),
    /// Compare an image with a reference: RMSE, relative MSE, PSNR, energy
    /// ratio; statuses as idiff's (1 beyond --warn-*, 2 beyond --max-*, 3
    /// sizes or channels differ, 4 a file unreadable).
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
        /// Write the summary as JSON to this file (- for standard output).
        #[arg(long)]
        report: Option<PathBuf>,
        /// The summary as JSON on standard output (as --report -).
        #[arg(long, conflicts_with = "report")]
        json: bool,
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
    /// Print a shell completion script: `epfilt completions bash > /etc/bash_completion.d/epfilt`.
    Completions {
        /// bash, zsh, fish, elvish or powershell.
        shell: clap_complete::Shell,
    },
    /// Print the manual page (roff): `epfilt man > epfilt.1`; with --dir,
    /// write it and one page per command (epfilt-filter.1 ...) there.
    Man {
        /// Write every page into this directory (made if missing).
        #[arg(long, value_hint = clap::ValueHint::DirPath)]
        dir: Option<std::path::PathBuf>,
    },
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

const RESTORE_EXAMPLES: &str = "Examples:
  oidnDenoise --hdr render.pfm --alb albedo.pfm --nrm normal.pfm -o denoised.pfm
  epfilt restore denoised.pfm render.exr restored.exr
  epfilt restore denoised.exr render.exr out.exr --scale 64 --report r.json

The denoiser's output (any denoiser: OIDN, OptiX, Arnold's noice, ...) shapes
the light; the energy image (the render, or epfilt's output of it: same size,
its beauty's colour channels in the denoiser's output by name, a layer's
`ViewLayer.Combined.R` as a plain `R`; an alpha the denoiser did not write stays
as the render has it) says how much there is. The render is an unbiased but
noisy estimate of every region's energy, the denoiser's a steady but biased
one. Each block of --scale x --scale pixels (from the top left), and each of
twice, four times... that side up to the whole image, gets a target: the
render's energy where the render is sure (relative standard error under 1%)
or the denoiser is far from it beyond its noise, the denoiser's where the two
agree within the render's noise, in between by how sure each is; children
sum to their parent, the whole to the render's total. The render's
uncertainty is its variance pass (and sample count, found as ep-box finds
them) or, without one, its residual against the denoiser. The report's levels
say, per block side, how many targets follow the render.
A bright pixel stays in place only on evidence: the emission guide (--guides;
its light beyond the denoiser's share around), a variance pass whose samples
agree there (a bulb, never a firefly: one bright sample), or a peak the
denoiser kept. A firefly joins its region's energy. On epfilt's ep-gauss or
ep-box output (read from its header), or with --keep-gain, a gain keeps too.
The rest is carried by the denoiser's picture and a smooth field: what a block
lacks goes back mostly to its brightest features (a denoiser dims them), a
surplus comes off in proportion.
The total is exact: the ledger balances to 1e-12 or nothing is written.
--part and --layer choose the energy image's part and beauty layer (the
denoiser's output takes the same part where it has it); its other channels
(depth, normals, ids, light AOVs) are carried as it has them, bit for bit,
unless --channel-rule 'PATTERN=drop' leaves them out.
Two passes over both inputs (every block's sums, then the result); memory
grows with the width and --scale, and a few words per block.";

#[derive(Args)]
pub struct RestoreArgs {
    /// The denoiser's output (EXR, Radiance picture or OIDN's PFM).
    pub denoised: PathBuf,
    /// The image whose energy is right: the render, or epfilt's output of it.
    pub energy: PathBuf,
    /// The result (.exr; never one of the inputs).
    pub output: PathBuf,
    /// Every setting (the library's table, shared with filter and the
    /// Python bindings).
    #[command(flatten)]
    pub opts: RestoreOptionArgs,
    /// Write the summary as JSON to this file (- for standard output).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// The summary as JSON on standard output (as --report -).
    #[arg(long, conflicts_with = "report")]
    pub json: bool,
    /// No progress bar and no summary.
    #[arg(long, short = 'q')]
    pub quiet: bool,
}

/// Which image of a file: shared by compare, preview and restore.
#[derive(Args)]
pub struct SelectArgs {
    /// Part of a multi-part file, by name or index.
    #[arg(long)]
    pub part: Option<String>,
    /// Layer whose R,G,B (or Y) channels are the image, e.g. ViewLayer.Combined
    /// [default: the unlayered channels, else the beauty-named layer beside the most
    /// passes (a view layer's Combined, not Blender's Composite), else the only one].
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
    /// Fail (status 2) when the RMSE is above this.
    #[arg(long)]
    pub max_rmse: Option<f64>,
    /// Fail (status 2) when the relative MSE is above this.
    #[arg(long)]
    pub max_rel_mse: Option<f64>,
    /// Fail (status 2) when any channel's energy ratio is further than this
    /// from 1.
    #[arg(long)]
    pub max_energy_error: Option<f64>,
    /// Warn (status 1) when the RMSE is above this.
    #[arg(long)]
    pub warn_rmse: Option<f64>,
    /// Warn (status 1) when the relative MSE is above this.
    #[arg(long)]
    pub warn_rel_mse: Option<f64>,
    /// Warn (status 1) when any channel's energy ratio is further than this
    /// from 1.
    #[arg(long)]
    pub warn_energy_error: Option<f64>,
    /// No progress bar.
    #[arg(long, short = 'q')]
    pub quiet: bool,
    /// Write where and how much the images differ as a PNG: each pixel's
    /// luminance-weighted absolute difference, in false colour with a legend.
    #[arg(long, value_name = "PNG")]
    pub diff: Option<PathBuf>,
    /// How the --diff image shows the difference.
    #[command(flatten, next_help_heading = "The --diff image")]
    pub look: LookArgs,
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
    /// Comma-separated labels for the montage (a newline starts another line).
    #[arg(long)]
    pub labels: Option<String>,
    /// Luminance on a log scale in false colour, with a legend in the
    /// image's units (as Radiance's falsecolor).
    #[arg(long)]
    pub false_color: bool,
    #[command(flatten)]
    pub look: LookArgs,
    /// No progress bar.
    #[arg(long, short = 'q')]
    pub quiet: bool,
}

/// How a PNG shows an image: its size, its crop, its false-colour scale.
#[derive(Args)]
pub struct LookArgs {
    /// Shrink each image to at most this many pixels wide (the mean of the
    /// area each pixel covers; never enlarged).
    #[arg(long, value_name = "PIXELS")]
    pub width: Option<usize>,
    /// Show this rectangle of each image: WxH+X+Y, in pixels from the top
    /// left (as oiiotool writes it).
    #[arg(long, value_name = "WxH+X+Y")]
    pub crop: Option<String>,
    /// The value at the top of the false-colour scale [default: a round
    /// number above all but the brightest 0.1% of the first image].
    #[arg(long, value_name = "VALUE")]
    pub fc_top: Option<f64>,
    /// How many factors of ten the false-colour scale spans below its top.
    #[arg(long, value_name = "N", default_value_t = 4)]
    pub fc_decades: u32,
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
    /// Output (.exr, .hdr or .pic, .pfm; - for standard output, in the input's
    /// format unless --format); for a sequence, a pattern with a frame field.
    pub output: PathBuf,
    /// Every setting (the library's, shared with the Python bindings).
    #[command(flatten)]
    pub opts: FilterOptionArgs,
    /// Write the summary as JSON to this file (- for standard output).
    #[arg(long, help_heading = "Output")]
    pub report: Option<PathBuf>,
    /// The summary as JSON on standard output (as --report -).
    #[arg(long, help_heading = "Output", conflicts_with = "report")]
    pub json: bool,
    /// Record every unit of work of the run (reads, filter tasks, writes)
    /// as Chrome trace-event JSON in this file (Perfetto, chrome://tracing);
    /// the lab's `scripts/scaling-model FILE` predicts the run on more cores.
    #[arg(long, help_heading = "Output")]
    pub trace: Option<PathBuf>,
    /// No progress bar and no summary (warnings about data are still printed).
    #[arg(long, short = 'q', help_heading = "Output")]
    pub quiet: bool,
}
