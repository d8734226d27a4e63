//! The filter's settings as one value, without a command-line parser:
//! [`FilterOptions`], typed, built from named settings
//! ([`FilterOptions::from_settings`]: what the command line and the Python
//! bindings' keyword arguments both give) and turned into a [`FilterJob`]
//! or the [`FilterParams`] of an in-memory run.
//!
//! [`OPTIONS`] defines every option that is not a method's setting (those
//! are [`crate::filter::settings::KNOBS`]): its name, help, heading, default
//! and parser. The command line builds its arguments from both tables.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use crate::error::{Error, Result};
use crate::filter::channels::RuleOverride;
use crate::filter::ep_box::{Guard, VarianceKind};
use crate::filter::settings::{self, Knob};
use crate::filter::{FilterParams, Method};
use crate::io::{
    parse_compression, Compression, Format, OutputSettings, PartSelect, StatsRequest, ViewSelect,
};
use crate::pipeline::{NonFinite, PipelineConfig, Precision};
use crate::sequence::{parse_frames, FramePattern, SequenceJob, Share, Task};

use super::{Edge, FilterJob, Undecided};
use crate::filter::guides::SurfaceRule;
pub use named::{Command, BOTH, FILTER, RESTORE_ONLY};

/// One named setting, as the command line or a keyword argument gives it.
#[derive(Clone, Debug, PartialEq)]
pub enum Setting {
    /// A switch (`allow_lossy=True`); false leaves it off.
    Flag(bool),
    /// A value, as the command line would spell it (`"0.08"`, `"ep-box"`).
    Value(String),
    /// A repeatable option's values (`channel_rule=["Z=drop", ...]`).
    List(Vec<String>),
}

/// How an option takes its value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// A switch.
    Flag,
    /// One value (the last given wins).
    Value,
    /// Repeatable: every value given, in order.
    List,
}

/// One option of [`OPTIONS`].
#[derive(Debug)]
pub struct OptionDef {
    /// The field's name; the option is `--` and this with `-` for `_`.
    pub name: &'static str,
    /// A one-letter form (`-s`).
    pub short: Option<char>,
    /// The help heading.
    pub heading: &'static str,
    /// The help text (one paragraph).
    help: &'static str,
    /// What the option's value is, for `--help` (empty: its name).
    pub value_name: &'static str,
    /// How it takes its value.
    pub kind: Kind,
    /// The value it has when not given.
    pub default: Option<&'static str>,
    /// The environment variable read when it is not given.
    pub env: Option<&'static str>,
    /// It names files or their layout: an in-memory array has none.
    pub files_only: bool,
    /// Read only by ep-box (warned about when given to another method).
    pub ep_box_only: bool,
    /// The values it takes where they are a fixed set (for completions;
    /// each parses, `every_listed_value_parses`), else empty.
    pub values: &'static [&'static str],
    /// The commands that take it.
    pub commands: &'static [Command],
    /// Its help for `restore`, where restore reads less of it.
    restore_help: Option<&'static str>,
}

impl OptionDef {
    /// The option's long name (`strip-rows`).
    pub fn option(&self) -> String {
        self.name.replace('_', "-")
    }

    /// The help text as one paragraph.
    pub fn help(&self) -> String {
        one_paragraph(self.help)
    }

    /// Whether `command` takes it.
    pub fn takes(&self, command: Command) -> bool {
        self.commands.contains(&command)
    }

    /// The help text for `command`, as one paragraph.
    pub fn help_for(&self, command: Command) -> String {
        match (command, self.restore_help) {
            (Command::Restore, Some(h)) => one_paragraph(h),
            _ => self.help(),
        }
    }
}

/// Doc-comment lines as one paragraph.
fn one_paragraph(doc: &str) -> String {
    doc.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(" ")
}

/// `raw` as a number for `--option` (the method settings' parser).
fn number<T: settings::Value>(option: &str, raw: &str) -> Result<T> {
    T::parse(raw).map_err(|e| Error::Config(format!("--{} {e}", option.replace('_', "-"))))
}

/// `raw` as it is.
fn text(_: &str, raw: &str) -> Result<String> {
    Ok(raw.to_string())
}

/// What `--pixel-type` asks for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PixelType {
    /// Each channel its input's type (f16 stays f16, the others f32).
    #[default]
    Same,
    /// Every channel this type.
    All(Precision),
}

impl PixelType {
    /// `same`, `f32` (`float`) or `f16` (`half`).
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "same" => Ok(PixelType::Same),
            "f32" | "float" => Ok(PixelType::All(Precision::F32)),
            "f16" | "half" => Ok(PixelType::All(Precision::F16)),
            other => Err(Error::Config(format!(
                "--pixel-type must be same, f32 or f16, not {other:?}"
            ))),
        }
    }
}

/// A field an option's one value sets: an `Option` becomes `Some`.
trait Field {
    /// What the option's parser gives.
    type Inner;
    /// Set the field to `v`.
    fn put(&mut self, v: Self::Inner);
}

impl<T> Field for Option<T> {
    type Inner = T;
    fn put(&mut self, v: T) {
        *self = Some(v);
    }
}

macro_rules! plain_fields {
    ($($t:ty),*) => {$(
        impl Field for $t {
            type Inner = $t;
            fn put(&mut self, v: $t) {
                *self = v;
            }
        }
    )*};
}
plain_fields!(usize, f64, String, NonFinite, PixelType);

/// The help headings of [`OPTIONS`] (the method's settings have theirs in
/// [`settings`]).
const INPUT: &str = "Input";
const GUIDES: &str = "Guides";
const CHANNELS: &str = "Channels";
const OUTPUT: &str = "Output";
const FARM: &str = "Farm";
const PERFORMANCE: &str = "Performance";
const RESTORE: &str = "Restore";

/// Defines [`FilterOptions`]'s fields and [`OPTIONS`]: per option, its doc
/// (the help), name and type, and `{ kind, heading, parse, ... }`: `parse`
/// is `fn(option, raw) -> Result<T>` (a field of type `Option<T>` is set to
/// `Some`, a list field gets every value, a flag needs none); `default`,
/// `env`, `short`, `value_name`, `files_only` and `ep_box_only` as in
/// [`OptionDef`].
macro_rules! options {
    ($(
        $(#[doc = $doc:literal])*
        $name:ident: $ty:ty {
            $kind:ident, $heading:expr $(, parse: $parse:expr)?
            $(, default: $default:literal)?
            $(, env: $env:literal)?
            $(, short: $short:literal)?
            $(, value_name: $value_name:literal)?
            $(, files_only: $files_only:literal)?
            $(, ep_box_only: $ep_box_only:literal)?
            $(, values: $values:expr)?
            $(, commands: $commands:expr)?
            $(, restore_help: $restore_help:literal)?
        }
    )*) => {
        /// Every setting of `epfilt filter` but its files and what it prints
        /// ([`OPTIONS`] says what each is), and the method's settings given
        /// ([`crate::filter::settings::KNOBS`]).
        #[derive(Clone, Debug, Default)]
        pub struct FilterOptions {
            $(
                $(#[doc = $doc])*
                pub $name: $ty,
            )*
            /// The method's settings given, in the order given (the last of
            /// one name wins), as the command line spells their values.
            pub knobs: Vec<(&'static Knob, String)>,
            /// Every option and setting given, by name.
            pub given: Vec<&'static str>,
        }

        /// Every option of `epfilt filter` that is not a method's setting.
        pub static OPTIONS: &[OptionDef] = &[$(
            OptionDef {
                name: stringify!($name),
                short: options!(@opt $($short)?),
                heading: $heading,
                help: concat!($($doc, "\n"),*),
                value_name: options!(@or "" $(, $value_name)?),
                kind: Kind::$kind,
                default: options!(@opt $($default)?),
                env: options!(@opt $($env)?),
                files_only: options!(@or false $(, $files_only)?),
                ep_box_only: options!(@or false $(, $ep_box_only)?),
                values: options!(@or &[] $(, $values)?),
                commands: options!(@or FILTER $(, $commands)?),
                restore_help: options!(@opt $($restore_help)?),
            },
        )*];

        impl FilterOptions {
            /// Set the option `name` from `value`; `false` when no option
            /// has that name.
            fn set_option(&mut self, name: &str, value: Setting) -> Result<bool> {
                match name {
                    $(stringify!($name) => {
                        options!(@set self.$name, $kind, name, value $(, $parse)?);
                        Ok(true)
                    })*
                    _ => Ok(false),
                }
            }
        }
    };
    (@opt) => { None };
    (@opt $v:expr) => { Some($v) };
    (@or $d:expr) => { $d };
    (@or $d:expr, $v:expr) => { $v };
    (@set $field:expr, Flag, $name:ident, $value:ident) => {
        $field = match $value {
            Setting::Flag(on) => on,
            _ => return Err(Error::Config(format!(
                "setting {} is a switch: give True or False", $name
            ))),
        }
    };
    (@set $field:expr, Value, $name:ident, $value:ident, $parse:expr) => {
        match $value {
            Setting::Value(raw) => Field::put(&mut $field, ($parse)($name, raw.as_str())?),
            _ => return Err(Error::Config(format!(
                "setting {} takes a value, not a true/false switch or a list", $name
            ))),
        }
    };
    (@set $field:expr, List, $name:ident, $value:ident, $parse:expr) => {
        match $value {
            Setting::List(raws) => {
                for raw in raws {
                    $field.push(($parse)($name, raw.as_str())?);
                }
            }
            Setting::Value(raw) => $field.push(($parse)($name, raw.as_str())?),
            Setting::Flag(_) => return Err(Error::Config(format!(
                "setting {} takes values, not a true/false switch", $name
            ))),
        }
    };
}

options! {
    /// Input samples per output pixel along each axis (1..=8): a super-sampled
    /// render is reduced S times [default: the file's epfiltSupersample
    /// attribute, else 1: an image is never reduced unless asked].
    supersample: Option<usize> { Value, INPUT, parse: number, short: 's' }
    /// Part of a multi-part input, by name or index, or `all` (every part
    /// filtered into one multi-part output). With one part, at S = 1 the
    /// others are copied bit for bit; at S > 1 they are left out, with a warning.
    part: Option<PartSelect> {
        Value, INPUT, parse: |_, s| Ok::<_, Error>(PartSelect::parse(s)), files_only: true,
        commands: BOTH,
        restore_help: "The energy image's part of a multi-part file, by name or index (the
        denoiser's output's too, where it has parts)."
    }
    /// A size that is not a multiple of S: crop drops the last partial output
    /// column and row; pad keeps them as pixels of fewer samples, each kernel
    /// normalised over what exists, energy exact [default: refuse, naming the options].
    edge: Option<Edge> {
        Value, INPUT, parse: |_, s| Edge::parse(s), files_only: true, values: &["crop", "pad"]
    }
    /// NaN and infinite input samples: error (refuse, naming the first) or zero (count them).
    nonfinite: NonFinite {
        Value, INPUT, parse: |_, s| NonFinite::parse(s),
        default: "error", values: &["error", "zero"], commands: BOTH
    }
    /// ep-gauss (§5.2), ep-box (§5.1, pixels with variance), gauss (linear
    /// foil), box (S x S average), or the energy-losing foils clamp, median
    /// and alpha-trim [default: from the file: ep-box where it holds
    /// per-pixel variance at S = 1, else ep-gauss; `epfilt info` says which].
    method: Option<Method> {
        Value, settings::METHOD, parse: |_, s| Method::parse(s), values: &Method::NAMES
    }
    /// ep-box: the variance channel (luminance) or layer with .R/.G/.B
    /// [default: found by name].
    variance_channel: Option<String> {
        Value, settings::EP_BOX, parse: text, files_only: true, ep_box_only: true
    }
    /// ep-box: what the variance holds: sample (of single samples), mean (of
    /// the pixel mean) or moment (E[Y^2]) [default: guessed from the name].
    variance_kind: Option<VarianceKind> {
        Value, settings::EP_BOX, parse: |_, s| VarianceKind::parse(s), ep_box_only: true,
        values: &["sample", "mean", "moment"]
    }
    /// ep-box: samples per pixel [default: the header's spp/samples attribute].
    spp: Option<u32> { Value, settings::EP_BOX, parse: number, ep_box_only: true }
    /// ep-box: the channel holding each pixel's sample count.
    spp_channel: Option<String> {
        Value, settings::EP_BOX, parse: text, files_only: true, ep_box_only: true
    }
    /// Guide passes: auto (every one found by the names renderers give them:
    /// emission, albedo, normal, depth; README "With guide passes"), none, or a
    /// comma list of those that must be found. The emission (the directly
    /// visible light) is set aside before any test and added back after, so
    /// a lamp is never spread; albedo, normal and depth keep a spread on its
    /// source's surface (see --guide-normal).
    guides: String {
        Value, GUIDES, parse: text, default: "auto",
        values: &["auto", "none", "emission", "albedo", "normal", "depth"], commands: BOTH,
        restore_help: "The energy image's emission guide pass (its directly visible light):
        auto (found by the names renderers give it; a variance pass's agreeing samples keep
        pixels too), none (neither keeps; a variance pass still measures the render's
        uncertainty), or emission (it must be found)."
    }
    /// KIND=NAME: the layer (depth: the channel) of a guide, e.g.
    /// emission=ViewLayer.Emit, normal=N, depth=Z (repeatable).
    guide: Vec<String> {
        List, GUIDES, parse: text, value_name: "KIND=NAME", commands: BOTH,
        restore_help: "emission=LAYER: the layer of the emission guide, e.g.
        emission=ViewLayer.Emit."
    }
    /// Surface guides: a spread reaches a pixel only where the normals'
    /// angle is at most this many degrees, ...
    guide_normal: f64 { Value, GUIDES, parse: number, default: "30" }
    /// ... the albedos differ by at most this in every channel, ...
    guide_albedo: f64 { Value, GUIDES, parse: number, default: "0.1" }
    /// ... and the depths by at most this fraction per pixel of distance;
    /// each spread's weights are normalised over the pixels it reaches. A
    /// pixel with less than half its nearest pixels on its surface (an edge,
    /// a sliver), or too few there to take its excess, keeps clear of lights
    /// only.
    guide_depth: f64 { Value, GUIDES, parse: number, default: "0.05" }
    /// Layer whose R,G,B (or Y) channels are filtered, e.g. ViewLayer.Combined
    /// [default: the unlayered channels, else the beauty-named layer beside the most
    /// passes (a view layer's Combined, not Blender's Composite), else the only one].
    layer: Option<String> {
        Value, CHANNELS, parse: text, files_only: true, commands: BOTH,
        restore_help: "The energy image's layer whose R,G,B (or Y) channels are the beauty,
        e.g. ViewLayer.Combined [default: the unlayered channels, else the beauty-named layer
        beside the most passes, else the only one]."
    }
    /// A multi-view (stereo) file: the view to filter, or all (each view
    /// filtered as an image of its own, into one output) [default: the first
    /// view; the others are left out, with a warning]. --layer and the guides
    /// name a view's layers without it: ViewLayer.Combined is
    /// ViewLayer.Combined.right in the right view.
    view: Option<ViewSelect> {
        Value, CHANNELS, parse: |_, s| Ok::<_, Error>(ViewSelect::parse(s)), files_only: true
    }
    /// What a channel beside the beauty gets, PATTERN=RULE (glob on the full
    /// name; repeatable, the last match wins): additive (spread with the
    /// beauty's kernels: light AOVs that sum to it), average (the base
    /// filter; copied at S = 1: depth, normals, albedo), nearest (the centre
    /// sample: ids, masks), drop [default: by name; `epfilt info` shows each
    /// channel's rule].
    channel_rule: Vec<RuleOverride> {
        List, CHANNELS, parse: |_, s| RuleOverride::parse(s), value_name: "PATTERN=RULE",
        files_only: true, commands: BOTH,
        restore_help: "The energy image's channels beside the beauty (depth, normals, ids,
        light AOVs) are carried into the result as it has them, bit for bit: PATTERN=drop
        leaves those it matches out (glob on the full name; repeatable, the last match wins;
        any other rule carries)."
    }
    /// The output's format where its name does not say (- or a name without
    /// an image extension): exr, hdr or pfm [default for -: the input's].
    format: Option<Format> {
        Value, OUTPUT, parse: |_, s| Format::parse(s), files_only: true,
        values: &["exr", "hdr", "pfm"]
    }
    /// Output compression (none rle zips zip piz pxr24 b44 b44a dwaa dwab)
    /// [default: as input, but zip where the input's is lossy].
    compression: Option<Compression> {
        Value, OUTPUT, parse: |_, c| parse_compression(c)
            .ok_or_else(|| Error::Config(format!("unknown --compression {c:?}"))),
        files_only: true,
        values: &["none", "rle", "zips", "zip", "piz", "pxr24", "b44", "b44a", "dwaa", "dwab"],
        commands: BOTH, restore_help: "Output compression [default: the energy image's]."
    }
    /// Accept a lossy output compression (dwaa, dwab; b44, b44a for f16;
    /// pxr24 for f32): the energy on disk is then measured by decoding the
    /// file, and reported.
    allow_lossy: bool { Flag, OUTPUT, files_only: true }
    /// Output sample type: same (each channel its input type: f16 stays f16,
    /// the others f32), f32 or f16 for all (f16 refuses values it cannot hold).
    pixel_type: PixelType {
        Value, OUTPUT, parse: |_, s| PixelType::parse(s), default: "same",
        values: &["same", "f32", "f16"]
    }
    /// Sequence: the frames to filter, e.g. 1-240, 1-100x2, 3,4,10-20x5
    /// [default: the input frames on disk].
    frames: Option<Vec<i64>> { Value, FARM, parse: |_, s| parse_frames(s), files_only: true }
    /// Sequence: this task's 0-based index; it filters the index-th of
    /// --task-count contiguous chunks of the frames [default: from the
    /// environment: SLURM_ARRAY_TASK_ID, JOB_COMPLETION_INDEX, AWS_BATCH_JOB_ARRAY_INDEX].
    task_index: Option<usize> { Value, FARM, parse: number, files_only: true }
    /// Sequence: how many tasks share the frames [default: SLURM_ARRAY_TASK_COUNT,
    /// AWS_BATCH_JOB_ARRAY_SIZE; needed for Kubernetes Indexed Jobs].
    task_count: Option<usize> { Value, FARM, parse: number, files_only: true }
    /// Leave outputs that are already complete outputs of their input and
    /// these settings (a retried farm task redoes only what is missing or
    /// unfinished; anything else at an output's name is redone, saying why).
    skip_existing: bool { Flag, FARM, files_only: true }
    /// Sequence: stop at the first failed frame.
    fail_fast: bool { Flag, FARM, files_only: true }
    /// Sequence: go on past a failed frame and exit 1 at the end (the default).
    keep_going: bool { Flag, FARM, files_only: true }
    /// Filter only band K of N of the output rows (K from 1: 3/8 is the
    /// third of eight), reading the input rows they need; `epfilt merge` puts
    /// the bands together, identical to one run. `env`: K and N from the
    /// array job's environment (as --task-index). A sequence's band files are
    /// named NAME.bandKofN.exr, never a frame's name.
    band: Option<String> { Value, FARM, parse: text, files_only: true }
    /// The band's 0-based index, as --task-index counts (with --band-count).
    band_index: Option<usize> { Value, FARM, parse: number, files_only: true }
    /// How many bands; without --band-index, the index comes from the array
    /// job's environment (SLURM_ARRAY_TASK_ID, ...).
    band_count: Option<usize> { Value, FARM, parse: number, files_only: true }
    /// Worker threads, 0 = one per core (does not change the result; more
    /// than the machine's cores are capped, with a warning). From 2, as many
    /// again decode and compress blocks, beside the filter's: under a CPU
    /// quota (Slurm, cgroups, taskset) they share its N cores; on idle cores
    /// the run may use up to about 1.5 N.
    threads: usize {
        Value, PERFORMANCE, parse: number, default: "0", env: "EPFILT_THREADS", commands: BOTH
    }
    /// Run `--threads` even where they are more than this machine's cores
    /// (slower: to measure memory at a core count the machine lacks).
    oversubscribe: bool { Flag, PERFORMANCE }
    /// Memory the process may use, in MiB, by its estimate: where the
    /// default strips and blocks read ahead need more, it runs with shorter
    /// strips and fewer blocks (the same result, `--report` says which);
    /// refused only below the floor it names. The estimate counts the
    /// program, the mapped input and the writer's rows; the measured peak
    /// stays within it where at most one sample in ten is noisy
    /// (docs/bench/memory.md) [default: half the machine's memory, or of the
    /// container's or job's cgroup limit where less].
    max_memory: Option<u64> {
        Value, PERFORMANCE, parse: number, env: "EPFILT_MAX_MEMORY", files_only: true,
        commands: BOTH,
        restore_help: "Memory the process may use, in MiB, by its estimate (the input rows of
        the rows of blocks held, which grow with --scale and the width): where the default
        strips need more, it runs with shorter ones (the same bytes); refused only below the
        floor it names [default: half the machine's memory, or of its cgroup limit where
        less]."
    }
    /// Accumulator tile width in output pixels (does not change the result).
    tile: usize { Value, PERFORMANCE, parse: number, default: "256" }
    /// Input rows per strip, 0 = automatic (from the input's width and the
    /// threads; at least 6 pixel rows, 4 on one or two threads, 16 or two a
    /// thread where they fit; does not change the result).
    strip_rows: usize { Value, PERFORMANCE, parse: number, default: "0" }
    /// Blocks (chunks) the reader decodes ahead at most, 0 = automatic (from
    /// the threads and the memory allowed; does not change the result).
    window_blocks: usize { Value, PERFORMANCE, parse: number, default: "0" }
    /// Size the strips and the reader's window as for this many worker
    /// threads, 0 = `--threads` (a 1-thread trace for the scaling model
    /// takes the geometry of the runs it predicts; does not change the
    /// result).
    geometry_threads: usize { Value, PERFORMANCE, parse: number, default: "0" }
    /// The side (pixels) of the smallest blocks with an energy target.
    scale: usize { Value, RESTORE, parse: number, default: "32", commands: RESTORE_ONLY }
    /// Also keep a pixel's energy in place where it is over this many times
    /// what the denoiser put around it, evidence or not (1 to 1e6; keeps a
    /// render's fireflies) [default: 1 where the energy image is epfilt's
    /// ep-gauss or ep-box output, else none: evidence alone].
    keep_gain: Option<f64> { Value, RESTORE, parse: number, commands: RESTORE_ONLY }
    /// Strips the Gaussian family works on at once, 0 = automatic (two
    /// where there are two threads or more: a strip's first passes run
    /// beside the previous strip's last ones; one holds a strip less;
    /// does not change the result).
    strips_in_flight: usize { Value, PERFORMANCE, parse: number, default: "0" }
}

/// `--quality`'s long help: every preset's knob values.
pub fn quality_help() -> String {
    let mut s = settings::knob("quality")
        .map(Knob::help)
        .unwrap_or_default();
    s.push_str(" The report records the preset and the values used (here the tolerance at S = 3).");
    for q in crate::filter::Quality::ALL {
        s.push_str(&format!("\n  {:<8} {}", q.name(), q.describe()));
    }
    s
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
    /// The value given for the method's setting `name`, the last if given
    /// more than once.
    pub fn knob(&self, name: &str) -> Option<&str> {
        (self.knobs.iter().rev())
            .find(|(k, _)| k.name == name)
            .map(|(_, v)| v.as_str())
    }

    /// Where ep-box's statistics are, as the options name them.
    pub fn stats_request(&self) -> StatsRequest {
        StatsRequest {
            variance_channel: self.variance_channel.clone(),
            kind: self.variance_kind,
            spp: self.spp,
            spp_channel: self.spp_channel.clone(),
        }
    }

    /// The options given that name files or their layout, which an array
    /// has none of.
    pub fn files_only_given(&self) -> Vec<&'static str> {
        (OPTIONS.iter())
            .filter(|d| d.files_only && self.given.contains(&d.name))
            .map(|d| d.name)
            .collect()
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
        let method = self.method.unwrap_or_default();
        self.params_for(method, self.supersample.unwrap_or(1), given)
    }

    /// The settings of `method` at S = `s`, the settings given applied over
    /// their defaults (`--quality` first, then the others over its preset);
    /// `given` (the method options the user gave) yields a warning for each
    /// the method does not read.
    pub fn params_for(
        &self,
        method: Method,
        s: usize,
        given: &[String],
    ) -> Result<(FilterParams, Vec<String>)> {
        let mut params = FilterParams::new(method, s);
        if let Some(q) = self.knob("quality") {
            params.set("quality", q)?;
        }
        for (k, raw) in self.knobs.iter().filter(|(k, _)| k.name != "quality") {
            k.set(&mut params, raw)?;
        }
        // §5.2 as written: ep-gauss's feature rule off too.
        if params.ep_box.guard == Guard::None {
            params.support = 0;
        }
        params.validate()?;
        let ep_box_only = |o: &str| OPTIONS.iter().any(|d| d.name == o && d.ep_box_only);
        let warnings = (given.iter())
            .filter(|o| !params.reads(o) || (ep_box_only(o) && method != Method::EpBox))
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
        let nonfinite = self.nonfinite;
        let cfg = PipelineConfig {
            tile: self.tile,
            strip_rows: self.strip_rows,
            threads,
            window_blocks: self.window_blocks,
            geometry_threads: self.geometry_threads,
            strips_in_flight: self.strips_in_flight,
            cancel,
            nonfinite,
            ..PipelineConfig::default()
        };
        Ok((cfg, warning))
    }

    /// The output sample type `--pixel-type` asks for (`None`: each
    /// channel its input's).
    pub fn precision(&self) -> Option<Precision> {
        match self.pixel_type {
            PixelType::Same => None,
            PixelType::All(p) => Some(p),
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
            Some(frames) => frames.clone(),
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
        let job = FilterJob {
            input,
            output,
            params,
            pipeline,
            output_settings: OutputSettings {
                compression: self.compression,
                precision: self.precision(),
                allow_lossy: self.allow_lossy,
                provenance: None,
                extra: Vec::new(),
                write_ahead: 0,
            },
            part: self.part.clone(),
            layer: self.layer.clone(),
            max_memory: self.max_memory.map(|m| m.saturating_mul(1 << 20)),
            stats: self.stats_request(),
            edge: self.edge.unwrap_or_default(),
            undecided,
            guides: crate::io::GuideRequest::parse(&self.guides, &self.guide)?,
            surface_rule: SurfaceRule {
                normal_degrees: self.guide_normal,
                albedo: self.guide_albedo,
                depth: self.guide_depth,
            },
            band,
            channel_rules: self.channel_rule.clone(),
            format: self.format,
            view: self.view.clone(),
        };
        Ok((job, warnings))
    }
}

#[cfg(test)]
mod tests;

mod named;
