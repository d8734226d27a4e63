//! `filter`'s and `plan`'s options as clap arguments, built from the
//! library's tables ([`OPTIONS`], [`KNOBS`]): clap parses the command line
//! into named settings, and the library's [`FilterOptions::from_settings`]
//! (which the Python bindings call too) gives them their types, defaults
//! and checks.

use clap::parser::ValueSource;
use clap::{Arg, ArgAction, ArgMatches, Args, Command, FromArgMatches};
use epfilt::filter::ep_box::Guard;
use epfilt::filter::settings::{self, KNOBS};
use epfilt::filter::Quality;
use epfilt::job::options::{quality_help, Command as Cmd, Kind, OptionDef, OPTIONS};
use epfilt::job::Setting;

/// One argument: its id (the setting's name), and how clap should read it.
struct Spec {
    name: &'static str,
    short: Option<char>,
    heading: &'static str,
    help: String,
    long_help: Option<String>,
    value_name: &'static str,
    kind: Kind,
    default: Option<String>,
    env: Option<&'static str>,
    /// The fixed set of values it takes, for completions (else empty).
    values: &'static [&'static str],
}

/// A value parser that takes any text (the library parses and checks it,
/// with its own messages) but names the values it knows, so that the shell
/// completions offer them.
#[derive(Clone)]
struct Suggest(&'static [&'static str]);

impl clap::builder::TypedValueParser for Suggest {
    type Value = String;

    fn parse_ref(
        &self,
        cmd: &Command,
        arg: Option<&Arg>,
        value: &std::ffi::OsStr,
    ) -> Result<String, clap::Error> {
        clap::builder::StringValueParser::new().parse_ref(cmd, arg, value)
    }

    fn possible_values(
        &self,
    ) -> Option<Box<dyn Iterator<Item = clap::builder::PossibleValue> + '_>> {
        Some(Box::new(
            self.0.iter().map(|v| clap::builder::PossibleValue::new(*v)),
        ))
    }
}

impl Spec {
    fn arg(&self, headings: bool) -> Arg {
        // As clap's derive shows a doc comment: no full stop at the end.
        let help = self
            .help
            .strip_suffix('.')
            .unwrap_or(&self.help)
            .to_string();
        let mut a = Arg::new(self.name)
            .long(self.name.replace('_', "-"))
            .help(help);
        if headings {
            a = a.help_heading(self.heading);
        }
        if let Some(c) = self.short {
            a = a.short(c);
        }
        if let Some(l) = &self.long_help {
            a = a.long_help(l.clone());
        }
        a = match self.kind {
            Kind::Flag => a.action(ArgAction::SetTrue),
            Kind::Value => a.action(ArgAction::Set),
            Kind::List => a.action(ArgAction::Append),
        };
        if self.kind != Kind::Flag {
            a = a.value_name(match self.value_name {
                "" => self.name.to_uppercase(),
                v => v.to_string(),
            });
        }
        // Shown in --help; the library applies the same default itself.
        if let Some(d) = &self.default {
            a = a.default_value(d.clone());
        }
        if let Some(e) = self.env {
            a = a.env(e);
        }
        if !self.values.is_empty() {
            a = a
                .value_parser(Suggest(self.values))
                .hide_possible_values(true);
        }
        a.allow_hyphen_values(self.kind != Kind::Flag)
    }

    /// The setting the user gave, if any (a default is not one).
    fn given(&self, m: &ArgMatches) -> Option<(String, Setting)> {
        if !matches!(
            m.value_source(self.name),
            Some(ValueSource::CommandLine | ValueSource::EnvVariable)
        ) {
            return None;
        }
        let value = match self.kind {
            Kind::Flag => Setting::Flag(m.get_flag(self.name)),
            Kind::Value => Setting::Value(m.get_one::<String>(self.name)?.clone()),
            Kind::List => Setting::List(m.get_many::<String>(self.name)?.cloned().collect()),
        };
        Some((self.name.to_string(), value))
    }
}

/// `d` as `command`'s argument.
fn option(d: &'static OptionDef, command: Cmd) -> Spec {
    Spec {
        name: d.name,
        short: d.short,
        heading: d.heading,
        help: d.help_for(command),
        long_help: None,
        value_name: d.value_name,
        kind: d.kind,
        default: d.default.map(str::to_string),
        env: d.env,
        values: d.values,
    }
}

/// Every option and setting of `filter`, in `--help`'s order: the input
/// and the method first, then each method's settings, then the rest.
fn specs() -> Vec<Spec> {
    let filter = OPTIONS.iter().filter(|d| d.takes(Cmd::Filter));
    let option = |d| option(d, Cmd::Filter);
    let knob = |k: &'static settings::Knob| Spec {
        name: k.name,
        short: None,
        heading: k.heading,
        help: k.help(),
        long_help: (k.name == "quality").then(quality_help),
        value_name: k.value_name,
        kind: Kind::Value,
        default: k.fixed_default(),
        env: None,
        values: match k.name {
            "quality" => &Quality::NAMES,
            "guard" => &Guard::NAMES,
            _ => &[],
        },
    };
    let first = |h: &str| h == "Input" || h == settings::METHOD;
    let mut v: Vec<Spec> = (filter.clone().filter(|d| first(d.heading)))
        .map(option)
        .collect();
    for heading in [settings::METHOD, settings::EP_GAUSS, settings::EP_BOX] {
        v.extend(KNOBS.iter().filter(|k| k.heading == heading).map(knob));
    }
    v.extend(filter.filter(|d| !first(d.heading)).map(option));
    v
}

/// `restore`'s options, in the table's order.
fn restore_specs() -> Vec<Spec> {
    (OPTIONS.iter().filter(|d| d.takes(Cmd::Restore)))
        .map(|d| option(d, Cmd::Restore))
        .collect()
}

/// `epfilt restore`'s settings, as named settings for the library.
#[derive(Clone, Debug, Default)]
pub struct RestoreOptionArgs {
    /// See [`FilterOptionArgs::settings`].
    pub settings: Vec<(String, Setting)>,
}

#[derive(Clone, Debug, Default)]
pub struct FilterOptionArgs {
    /// The settings given, in the tables' order.
    pub settings: Vec<(String, Setting)>,
}

/// ep-box's statistics and noise test, which `epfilt plan` reads.
#[derive(Clone, Debug, Default)]
pub struct StatsArgs {
    /// See [`FilterOptionArgs::settings`].
    pub settings: Vec<(String, Setting)>,
}

/// The names `plan` takes.
const STATS: &[&str] = &[
    "variance_channel",
    "variance_kind",
    "spp",
    "spp_channel",
    "d",
    "nmid",
    "confidence",
];

/// `filter`'s specs that `plan` takes.
fn stats_specs() -> Vec<Spec> {
    (specs().into_iter())
        .filter(|s| STATS.contains(&s.name))
        .collect()
}

/// clap's traits for `$t`, a struct of the named settings `$specs` gives
/// (under their help headings where `$headings`).
macro_rules! settings_args {
    ($t:ident, $specs:expr, $headings:expr) => {
        impl FromArgMatches for $t {
            fn from_arg_matches(m: &ArgMatches) -> Result<Self, clap::Error> {
                let settings = ($specs).iter().filter_map(|s| s.given(m)).collect();
                Ok($t { settings })
            }
            fn update_from_arg_matches(&mut self, m: &ArgMatches) -> Result<(), clap::Error> {
                *self = Self::from_arg_matches(m)?;
                Ok(())
            }
        }

        impl Args for $t {
            fn augment_args(cmd: Command) -> Command {
                cmd.args(($specs).iter().map(|s| s.arg($headings)))
            }
            fn augment_args_for_update(cmd: Command) -> Command {
                Self::augment_args(cmd)
            }
        }
    };
}

settings_args!(FilterOptionArgs, specs(), true);
settings_args!(StatsArgs, stats_specs(), false);
settings_args!(RestoreOptionArgs, restore_specs(), true);
