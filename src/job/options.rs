//! The filter's settings as one value: what `epfilt filter`'s options say
//! (the command line flattens [`FilterOptions`] into its own arguments) and
//! what the Python bindings' keyword arguments say ([`FilterOptions::from_settings`],
//! through the same parser: the same names, defaults, checks and messages),
//! turned into a [`FilterJob`] or the [`FilterParams`] of an in-memory run.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use clap::parser::ValueSource;
use clap::{ArgMatches, Args, FromArgMatches};

use crate::error::{Error, Result};
use crate::filter::channels::RuleOverride;
use crate::filter::ep_box::{EpBoxParams, Guard, VarianceKind};
use crate::filter::{FilterParams, Method, Quality};
use crate::io::{parse_compression, Format, OutputSettings, PartSelect, StatsRequest, ViewSelect};
use crate::pipeline::{NonFinite, PipelineConfig, Precision};
use crate::sequence::{parse_frames, FramePattern, SequenceJob, Share, Task};

use super::{Edge, FilterJob, Undecided};
use crate::filter::guides::SurfaceRule;

/// Every setting of `epfilt filter` but its files and what it prints: the
/// input and its channels, the method and its knobs, the output's format,
/// the farm's share and the performance knobs (none of which change the
/// result).
#[derive(Args, Clone, Debug)]
pub struct FilterOptions {
    // ---- Input ----
    /// Input samples per output pixel along each axis (1..=8): a super-sampled
    /// render is reduced S times [default: the file's epfiltSupersample
    /// attribute, else 1: an image is never reduced unless asked].
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
    /// and alpha-trim [default: from the file: ep-box where it holds
    /// per-pixel variance at S = 1, else ep-gauss; `epfilt info` says which].
    #[arg(long, help_heading = "Method")]
    pub method: Option<String>,
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
    /// turns off its --support rule (at S = 1: its feature rules).
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
    /// and scaled as 0.25 at 3 is to 0.15 at 4: t*(3/S)^1.776]. At S = 1: the
    /// most of its background a spread adds to any pixel [default: 0.25].
    #[arg(long, help_heading = "ep-gauss")]
    pub tolerance: Option<f64>,
    /// A noisy sample with at least this many noisy neighbouring
    /// super-samples (within --support-ratio of it) is a feature and keeps the
    /// base kernel (S > 1; the --support* knobs are S > 1's). 0 = the paper's
    /// rule [default: --quality's].
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
    #[arg(long, default_value_t = crate::filter::DEFAULT_COARSE_FROM, help_heading = "ep-gauss")]
    pub coarse_from: f64,
    /// Check widths of this radius (output pixels) and more against a lower
    /// bound of their average read from a summed-area table, a few entries instead of
    /// every row of the average's disc: conservative (a width that passes on
    /// the bound passes on the average), at most about a rung wider; 0 =
    /// the exact average always [default: --quality's].
    #[arg(long, help_heading = "ep-gauss")]
    pub bound_from: Option<f64>,

    // ---- ep-box ----
    // ep-box's statistics and noise test (shared with `epfilt plan`).
    #[allow(missing_docs)]
    #[command(flatten, next_help_heading = "ep-box")]
    pub stats: StatsOptions,
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

    // ---- Guides ----
    /// Guide passes: auto (every one found by the names renderers give them:
    /// emission, albedo, normal, depth; README "With guide passes"), none, or a
    /// comma list of those that must be found. The emission (the directly
    /// visible light) is set aside before any test and added back after, so
    /// a lamp is never spread; albedo, normal and depth keep a spread on its
    /// source's surface (see --guide-normal).
    #[arg(long, default_value = "auto", help_heading = "Guides")]
    pub guides: String,
    /// KIND=NAME: the layer (depth: the channel) of a guide, e.g.
    /// emission=ViewLayer.Emit, normal=N, depth=Z (repeatable).
    #[arg(long = "guide", value_name = "KIND=NAME", help_heading = "Guides")]
    pub guide: Vec<String>,
    /// Surface guides: a spread reaches a pixel only where the normals'
    /// angle is at most this many degrees, ...
    #[arg(long, default_value_t = 30.0, help_heading = "Guides")]
    pub guide_normal: f64,
    /// ... the albedos differ by at most this in every channel, ...
    #[arg(long, default_value_t = 0.1, help_heading = "Guides")]
    pub guide_albedo: f64,
    /// ... and the depths by at most this fraction per pixel of distance;
    /// each spread's weights are normalised over the pixels it reaches. A
    /// pixel with less than half its nearest pixels on its surface (an edge,
    /// a sliver), or too few there to take its excess, keeps clear of lights
    /// only.
    #[arg(long, default_value_t = 0.05, help_heading = "Guides")]
    pub guide_depth: f64,

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
    /// than the machine's cores are capped, with a warning). From 2, as many
    /// again decode and compress blocks, beside the filter's: under a CPU
    /// quota (Slurm, cgroups, taskset) they share its N cores; on idle cores
    /// the run may use up to about 1.5 N.
    #[arg(
        long,
        default_value_t = 0,
        env = "EPFILT_THREADS",
        help_heading = "Performance"
    )]
    pub threads: usize,
    /// Run `--threads` even where they are more than this machine's cores
    /// (slower: to measure memory at a core count the machine lacks).
    #[arg(long, help_heading = "Performance")]
    pub oversubscribe: bool,
    /// Refuse jobs estimated to need more memory than this, in MiB [default: half the machine's memory].
    #[arg(long, env = "EPFILT_MAX_MEMORY", help_heading = "Performance")]
    pub max_memory: Option<u64>,
    /// Accumulator tile width in output pixels (does not change the result).
    #[arg(long, default_value_t = 256, help_heading = "Performance")]
    pub tile: usize,
    /// Input rows per strip, 0 = automatic (from the input's width; at least 6 pixel rows, 16
    /// where they fit; does not change the result).
    #[arg(long, default_value_t = 0, help_heading = "Performance")]
    pub strip_rows: usize,
}

/// Statistics and noise test of ep-box, shared by `filter` and `plan`.
#[derive(Args, Clone, Debug)]
pub struct StatsOptions {
    /// Variance channel (luminance) or layer with .R/.G/.B [default: found by
    /// name] (ep-box).
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

/// `--quality`'s long help: every preset's knob values.
fn quality_help() -> String {
    let mut s = String::from(
        "A point on ep-gauss's speed/accuracy front, chosen on real renders \
         (scripts/eval-renders --sweep, docs/pareto.md): a set of knob values, which each \
         option given overrides. The report records the preset and the values used.",
    );
    for q in Quality::ALL {
        s.push_str(&format!("\n  {:<8} {}", q.name(), q.describe()));
    }
    s
}

/// The ids of the options that decide a method's settings (the ones a
/// method may ignore, and warned about when it does), as clap names them.
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
    "bound_from",
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

/// One keyword setting ([`FilterOptions::from_settings`]).
#[derive(Clone, Debug, PartialEq)]
pub enum Setting {
    /// A switch (`allow_lossy=True`); false leaves it off.
    Flag(bool),
    /// A value, as the command line would spell it (`"0.08"`, `"ep-box"`).
    Value(String),
    /// A repeatable option's values (`channel_rule=["Z=drop", ...]`).
    List(Vec<String>),
}

impl StatsOptions {
    /// Where ep-box's statistics are, as the options name them.
    pub fn request(&self) -> Result<StatsRequest> {
        Ok(StatsRequest {
            variance_channel: self.variance_channel.clone(),
            kind: self
                .variance_kind
                .as_deref()
                .map(VarianceKind::parse)
                .transpose()?,
            spp: self.spp,
            spp_channel: self.spp_channel.clone(),
        })
    }

    /// ep-box's noise test (the confidence as 0.8, 80 or 80%).
    pub fn ep_box_params(&self) -> Result<EpBoxParams> {
        let c = self.confidence.trim();
        let (num, pct) = match c.strip_suffix('%') {
            Some(n) => (n, true),
            None => (c, false),
        };
        let v: f64 = num
            .trim()
            .parse()
            .map_err(|_| Error::Config(format!("--confidence {c:?} is not a number")))?;
        let confidence = if pct || v > 1.0 { v / 100.0 } else { v };
        let p = EpBoxParams {
            d: self.d,
            nmid: self.nmid,
            confidence,
            ..Default::default()
        };
        p.validate()?;
        Ok(p)
    }
}

/// `threads` above the machine's cores only slows the run down (each
/// parallel loop's end wakes them all): capped, with a warning to pass on.
pub fn cap_threads(n: usize) -> (usize, Option<String>) {
    let cores = std::thread::available_parallelism().map_or(n, |c| c.get());
    if n > cores {
        let why = format!("--threads {n} is more than this machine's {cores} cores: using {cores}");
        (cores, Some(why))
    } else {
        (n, None)
    }
}

impl FilterOptions {
    /// The method options given (on the command line or in the
    /// environment) in `m`, which holds these options.
    pub fn given(m: &ArgMatches) -> Vec<String> {
        METHOD_OPTIONS
            .iter()
            .filter(|id| {
                matches!(
                    m.value_source(id),
                    Some(ValueSource::CommandLine | ValueSource::EnvVariable)
                )
            })
            .map(|id| id.to_string())
            .collect()
    }

    /// The options from keyword settings (names as the fields spell them,
    /// `support_region`; `support-region` is taken too), through the command
    /// line's parser: its defaults, checks and messages. Also returns the
    /// method options given ([`FilterOptions::given`]). An unknown name is a
    /// configuration error that lists the known ones.
    pub fn from_settings(
        settings: impl IntoIterator<Item = (String, Setting)>,
    ) -> Result<(FilterOptions, Vec<String>)> {
        let cmd = FilterOptions::augment_args(clap::Command::new("epfilt").no_binary_name(true));
        let mut argv: Vec<String> = Vec::new();
        for (name, value) in settings {
            let id = name.replace('-', "_");
            let Some(arg) = cmd.get_arguments().find(|a| a.get_id().as_str() == id) else {
                let mut known: Vec<&str> =
                    cmd.get_arguments().map(|a| a.get_id().as_str()).collect();
                known.sort_unstable();
                return Err(Error::Config(format!(
                    "unknown setting {name:?}; the settings are: {}",
                    known.join(", ")
                )));
            };
            let long = arg.get_long().unwrap_or(arg.get_id().as_str()).to_string();
            let takes_value = arg.get_action().takes_values();
            match (value, takes_value) {
                (Setting::Flag(true), false) => argv.push(format!("--{long}")),
                (Setting::Flag(false), false) => {}
                (Setting::Flag(_), true) => {
                    return Err(Error::Config(format!(
                        "setting {id} takes a value, not a true/false switch"
                    )))
                }
                (Setting::Value(v), true) => argv.push(format!("--{long}={v}")),
                (Setting::List(vs), true) => {
                    argv.extend(vs.iter().map(|v| format!("--{long}={v}")))
                }
                (_, false) => {
                    return Err(Error::Config(format!(
                        "setting {id} is a switch: give True or False"
                    )))
                }
            }
        }
        let m = cmd.try_get_matches_from(argv).map_err(|e| {
            let text = e.to_string();
            let line = text.lines().next().unwrap_or("invalid settings");
            Error::Config(line.trim_start_matches("error: ").to_string())
        })?;
        let opts = FilterOptions::from_arg_matches(&m).map_err(|e| Error::Config(e.to_string()))?;
        let given = FilterOptions::given(&m);
        Ok((opts, given))
    }

    /// The farm's share these options name: the band, and a sequence's
    /// task (`env` reads the array job's environment).
    pub fn share(&self, env: &dyn Fn(&str) -> Option<String>) -> Result<Share> {
        crate::sequence::band_and_task(
            self.band.as_deref(),
            self.band_index,
            self.band_count,
            self.task_index,
            self.task_count,
            env,
        )
    }

    /// The method's settings; `given` (the method options the user gave)
    /// yields a warning for each the method does not read.
    pub fn params(&self, given: &[String]) -> Result<(FilterParams, Vec<String>)> {
        let method = match &self.method {
            Some(m) => Method::parse(m)?,
            None => Method::EpGauss,
        };
        self.params_for(method, self.supersample.unwrap_or(1), given)
    }

    /// The settings of `method` at S = `s`, the options given applied
    /// over their defaults; `given` (the method options the user gave)
    /// yields a warning for each the method does not read.
    pub fn params_for(
        &self,
        method: Method,
        s: usize,
        given: &[String],
    ) -> Result<(FilterParams, Vec<String>)> {
        let mut params = FilterParams::new(method, s);
        if let Some(q) = &self.quality {
            let q = Quality::parse(q)?;
            if method == Method::EpGauss {
                params = params.with_quality(q);
            }
        }
        params.ep_box = EpBoxParams {
            ltvis: self.ltvis,
            passes: self.passes,
            guard: Guard::parse(&self.guard)?,
            guard_confidence: self.guard_confidence,
            carriers: self.carriers,
            carriers_fraction: self.carriers_fraction,
            carriers_rse: self.carriers_rse,
            ..self.stats.ep_box_params()?
        };
        self.set_knobs(&mut params);
        params.validate()?;
        let warnings = (given.iter())
            .filter(|o| !params.reads(o))
            .map(|option| {
                format!(
                    "--{} has no effect with --method {}{}",
                    option.replace('_', "-"),
                    method.name(),
                    if method == Method::EpGauss {
                        format!(" at S = {s}")
                    } else {
                        String::new()
                    }
                )
            })
            .collect();
        Ok((params, warnings))
    }

    /// The knobs given, over the method's (and its `--quality`'s) defaults.
    fn set_knobs(&self, params: &mut FilterParams) {
        let set = |field: &mut f64, v: Option<f64>| {
            if let Some(v) = v {
                *field = v;
            }
        };
        set(&mut params.radius, self.radius);
        set(&mut params.cutoff, self.cutoff);
        set(&mut params.support_ratio, self.support_ratio);
        set(&mut params.support_over, self.support_over);
        set(&mut params.support_level, self.support_level);
        set(&mut params.max_radius, self.max_radius);
        set(&mut params.width_step, self.width_step);
        set(&mut params.tolerance, self.tolerance);
        set(&mut params.bound_from, self.bound_from);
        if let Some(n) = self.support {
            params.support = n;
        }
        if self.guard == "none" {
            params.support = 0;
        }
        if let Some(n) = self.support_group {
            params.support_group = n;
        }
        if let Some(n) = self.support_compact {
            params.support_compact = n;
        }
        if let Some(n) = self.support_region {
            params.support_region = n;
        }
        params.clamp = self.clamp;
        params.alpha = self.alpha;
        params.coarse_from = self.coarse_from;
    }

    /// How the work is cut (`cancel` stops it); a warning when the threads
    /// asked for are more than the machine's cores.
    pub fn pipeline(
        &self,
        cancel: Option<Arc<AtomicBool>>,
    ) -> Result<(PipelineConfig, Option<String>)> {
        let (threads, warning) = if self.oversubscribe {
            (self.threads, None)
        } else {
            cap_threads(self.threads)
        };
        let nonfinite = match self.nonfinite.as_str() {
            "error" => NonFinite::Error,
            "zero" => NonFinite::Zero,
            other => {
                return Err(Error::Config(format!(
                    "--nonfinite must be error or zero, not {other:?}"
                )))
            }
        };
        let cfg = PipelineConfig {
            tile: self.tile,
            strip_rows: self.strip_rows,
            threads,
            cancel,
            nonfinite,
            classify_samples: 0,
            spread_chunk: 0,
        };
        Ok((cfg, warning))
    }

    /// The output sample type `--pixel-type` asks for (`None`: each
    /// channel its input's).
    pub fn precision(&self) -> Result<Option<Precision>> {
        match self.pixel_type.as_str() {
            "same" => Ok(None),
            "f32" | "float" => Ok(Some(Precision::F32)),
            "f16" | "half" => Ok(Some(Precision::F16)),
            other => Err(Error::Config(format!(
                "--pixel-type must be same, f32 or f16, not {other:?}"
            ))),
        }
    }

    /// The frame sequence `template`'s input and output name (both patterns
    /// with a frame field; `task`: this process's share), or `None` for one
    /// file. Refuses a pattern on one side only, an output pattern that is
    /// the input's, and the sequence options without a sequence.
    pub fn sequence(&self, template: FilterJob, task: Option<Task>) -> Result<Option<SequenceJob>> {
        let input = FramePattern::parse(&template.input)?;
        let output = FramePattern::parse(&template.output)?;
        let (input, output) = match (input, output) {
            (Some(i), Some(o)) => (i, o),
            (Some(i), None) => {
                return Err(Error::Config(format!(
                    "the input {i} is a frame sequence: give the output a frame field too (e.g. out/render.####.exr)"
                )))
            }
            (None, Some(o)) => {
                return Err(Error::Config(format!(
                    "the output {o} has a frame field but the input {} does not",
                    template.input.display()
                )))
            }
            (None, None) => {
                if self.frames.is_some() || self.task_index.is_some() || self.task_count.is_some() {
                    return Err(Error::Config(
                        "--frames, --task-index and --task-count need a frame sequence (render.####.exr)"
                            .into(),
                    ));
                }
                return Ok(None);
            }
        };
        if input.to_string() == output.to_string() {
            return Err(Error::Config(format!(
                "the output pattern {output} is the input's: each frame would overwrite its input"
            )));
        }
        let frames = match &self.frames {
            Some(spec) => parse_frames(spec)?,
            None => input.on_disk()?,
        };
        Ok(Some(SequenceJob {
            template,
            input,
            output,
            frames,
            task,
            skip_existing: self.skip_existing,
            fail_fast: self.fail_fast,
        }))
    }

    /// The job of filtering `input` into `output` (every check that needs
    /// no file), with the warnings to pass on: options the method does not
    /// read, threads capped.
    pub fn job(
        &self,
        input: PathBuf,
        output: PathBuf,
        band: Option<(usize, usize)>,
        given: &[String],
        cancel: Option<Arc<AtomicBool>>,
    ) -> Result<(FilterJob, Vec<String>)> {
        let (params, warnings) = self.params(given)?;
        let undecided = Undecided {
            method: self.method.is_none(),
            supersample: self.supersample.is_none(),
            rebuild: {
                let opts = self.clone();
                let given = given.to_vec();
                Some(Arc::new(move |m, s| opts.params_for(m, s, &given)))
            },
        };
        // Where the file decides, the warnings come once it has.
        let mut warnings = if undecided.method || undecided.supersample {
            Vec::new()
        } else {
            warnings
        };
        let (pipeline, capped) = self.pipeline(cancel)?;
        warnings.extend(capped);
        let compression = match &self.compression {
            Some(c) => Some(
                parse_compression(c)
                    .ok_or_else(|| Error::Config(format!("unknown --compression {c:?}")))?,
            ),
            None => None,
        };
        let job = FilterJob {
            input,
            output,
            params,
            pipeline,
            output_settings: OutputSettings {
                compression,
                precision: self.precision()?,
                allow_lossy: self.allow_lossy,
                provenance: None,
                extra: Vec::new(),
            },
            part: self.part.as_deref().map(PartSelect::parse),
            layer: self.layer.clone(),
            max_memory: self.max_memory.map(|m| m.saturating_mul(1 << 20)),
            stats: self.stats.request()?,
            edge: match &self.edge {
                Some(e) => Edge::parse(e)?,
                None => Edge::Exact,
            },
            undecided,
            verdict: None,
            notes: Vec::new(),
            guides: crate::io::GuideRequest::parse(&self.guides, &self.guide)?,
            surface_rule: SurfaceRule {
                normal_degrees: self.guide_normal,
                albedo: self.guide_albedo,
                depth: self.guide_depth,
            },
            band,
            channel_rules: (self.channel_rule.iter())
                .map(|r| RuleOverride::parse(r))
                .collect::<Result<_>>()?,
            format: self.format.as_deref().map(Format::parse).transpose()?,
            view: self.view.as_deref().map(ViewSelect::parse),
        };
        Ok((job, warnings))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings(pairs: &[(&str, Setting)]) -> Result<(FilterOptions, Vec<String>)> {
        FilterOptions::from_settings(pairs.iter().map(|(k, v)| (k.to_string(), v.clone())))
    }

    #[test]
    fn no_settings_are_the_command_lines_defaults() {
        let (o, given) = settings(&[]).unwrap();
        assert!(given.is_empty());
        assert_eq!(o.method, None);
        assert_eq!((o.tile, o.strip_rows, o.passes), (256, 0, 8));
        let (p, warnings) = o.params(&given).unwrap();
        assert_eq!(p, FilterParams::new(Method::EpGauss, 1));
        assert!(warnings.is_empty());
    }

    #[test]
    fn settings_take_values_switches_and_lists() {
        let (o, given) = settings(&[
            ("tolerance", Setting::Value("0.1".into())),
            ("support-region", Setting::Value("0".into())),
            ("allow_lossy", Setting::Flag(true)),
            (
                "channel_rule",
                Setting::List(vec!["Z=drop".into(), "id=nearest".into()]),
            ),
            ("radius", Setting::Value("-1".into())),
        ])
        .unwrap();
        assert_eq!(o.tolerance, Some(0.1));
        assert_eq!(o.support_region, Some(0));
        assert!(o.allow_lossy);
        assert_eq!(o.channel_rule, ["Z=drop", "id=nearest"]);
        assert_eq!(given, ["support_region", "radius", "tolerance"]);
        // A negative radius reaches the library's check, not the parser's.
        assert!(matches!(o.params(&given), Err(Error::Config(_))));
    }

    #[test]
    fn unknown_and_malformed_settings_are_configuration_errors() {
        let e = settings(&[("tolerence", Setting::Value("0.1".into()))]).unwrap_err();
        assert!(
            e.to_string().contains("unknown setting \"tolerence\""),
            "{e}"
        );
        assert!(e.to_string().contains("tolerance"), "{e}");
        let e = settings(&[("tolerance", Setting::Value("x".into()))]).unwrap_err();
        assert!(
            matches!(e, Error::Config(_)) && e.to_string().contains("tolerance"),
            "{e}"
        );
        let e = settings(&[("tolerance", Setting::Flag(true))]).unwrap_err();
        assert!(e.to_string().contains("takes a value"), "{e}");
        let e = settings(&[("allow_lossy", Setting::Value("yes".into()))]).unwrap_err();
        assert!(e.to_string().contains("switch"), "{e}");
    }

    #[test]
    fn options_the_method_ignores_are_warned_about() {
        let (o, given) = settings(&[
            ("method", Setting::Value("gauss".into())),
            ("tolerance", Setting::Value("0.1".into())),
        ])
        .unwrap();
        let (_, warnings) = o.params(&given).unwrap();
        assert_eq!(warnings, ["--tolerance has no effect with --method gauss"]);
    }
}
