//! Named settings (the command line's, Python's keyword arguments) into
//! [`FilterOptions`] for the command that takes them, and `restore`'s job
//! from them: one table ([`OPTIONS`]) for every command.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use super::{cap_threads, FilterOptions, Setting, OPTIONS};
use crate::error::{Error, Result};
use crate::filter::settings;
use crate::filter::{FilterParams, Method};
use crate::io::{GuideRequest, Selection};
use crate::job::restore::RestoreJob;

/// A command whose settings [`OPTIONS`] holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Command {
    /// `epfilt filter` (and the Python `filter`, `filter_file`).
    Filter,
    /// `epfilt restore` (and the Python `restore_file`).
    Restore,
}

/// Taken by `filter` alone.
pub const FILTER: &[Command] = &[Command::Filter];
/// Taken by `filter` and `restore`.
pub const BOTH: &[Command] = &[Command::Filter, Command::Restore];
/// Taken by `restore` alone.
pub const RESTORE_ONLY: &[Command] = &[Command::Restore];

impl FilterOptions {
    /// `filter`'s options from named settings (names as the fields spell
    /// them, `support_region`; `support-region` is taken too), over the
    /// defaults and the environment variables of [`OPTIONS`]. Also returns
    /// the method settings given, for the warnings of
    /// [`FilterOptions::params`]. An unknown name is a configuration error
    /// that lists the known ones; a value its option cannot take is one that
    /// names the option.
    pub fn from_settings(
        settings: impl IntoIterator<Item = (String, Setting)>,
    ) -> Result<(FilterOptions, Vec<String>)> {
        Self::named(Command::Filter, settings)
    }

    /// `restore`'s options from named settings, as
    /// [`FilterOptions::from_settings`] takes `filter`'s.
    pub fn for_restore(
        settings: impl IntoIterator<Item = (String, Setting)>,
    ) -> Result<FilterOptions> {
        Ok(Self::named(Command::Restore, settings)?.0)
    }

    fn named(
        command: Command,
        settings: impl IntoIterator<Item = (String, Setting)>,
    ) -> Result<(FilterOptions, Vec<String>)> {
        let mut o = FilterOptions::default();
        for def in OPTIONS {
            if let Some(d) = def.default {
                o.set_option(def.name, Setting::Value(d.to_string()))?;
            }
        }
        let settings: Vec<(String, Setting)> = (settings.into_iter())
            .map(|(name, v)| (name.replace('-', "_"), v))
            .collect();
        for def in OPTIONS.iter().filter(|d| d.takes(command)) {
            let given = settings.iter().any(|(n, _)| n == def.name);
            if let (false, Some(var)) = (given, def.env) {
                if let Ok(v) = std::env::var(var) {
                    o.set_option(def.name, Setting::Value(v))?;
                    o.given.push(def.name);
                }
            }
        }
        // A scratch copy of the settings checks each knob's value as it is
        // given: the error names the option before any file is read.
        let mut scratch = FilterParams::new(Method::EpGauss, 1);
        for (name, value) in settings {
            let def = OPTIONS.iter().find(|d| d.name == name && d.takes(command));
            let knob = settings::knob(&name).filter(|_| command == Command::Filter);
            if let Some(def) = def {
                o.set_option(def.name, value)?;
                o.given.push(def.name);
            } else if let Some(k) = knob {
                let Setting::Value(raw) = value else {
                    return Err(Error::Config(format!(
                        "setting {name} takes a value, not a true/false switch or a list"
                    )));
                };
                k.set(&mut scratch, &raw)?;
                o.knobs.push((k, raw));
                o.given.push(k.name);
            } else {
                return Err(unknown(command, &name));
            }
        }
        if o.fail_fast && o.keep_going {
            return Err(Error::Config(
                "--fail-fast and --keep-going cannot be given together".into(),
            ));
        }
        let mut given: Vec<String> = Vec::new();
        for (k, _) in &o.knobs {
            if !given.iter().any(|g| g == k.name) {
                given.push(k.name.to_string());
            }
        }
        for def in OPTIONS.iter().filter(|d| d.ep_box_only) {
            if o.given.contains(&def.name) {
                given.push(def.name.to_string());
            }
        }
        Ok((o, given))
    }

    /// `restore`'s job: the denoiser's output `denoised` with the energy of
    /// `energy` put back, into `output`, as these options say (`cancel`
    /// stops it); a warning when the threads asked for are more than the
    /// machine's cores.
    pub fn restore_job(
        &self,
        (denoised, energy, output): (PathBuf, PathBuf, PathBuf),
        cancel: Option<Arc<AtomicBool>>,
    ) -> Result<(RestoreJob, Option<String>)> {
        let (threads, warning) = cap_threads(self.threads);
        let mut job = RestoreJob::new(denoised, energy, output);
        job.scale = self.scale;
        job.keep_gain = self.keep_gain;
        job.threads = threads;
        job.nonfinite = self.nonfinite;
        job.max_memory = self.max_memory.map(|m| m.saturating_mul(1 << 20));
        job.guides = GuideRequest::parse(&self.guides, &self.guide)?;
        job.select = Selection {
            part: self.part.clone(),
            layer: self.layer.clone(),
        };
        job.channel_rules = self.channel_rule.clone();
        job.output_settings.compression = self.compression;
        job.cancel = cancel;
        Ok((job, warning))
    }
}

/// The error for a setting `command` does not take, listing those it does.
fn unknown(command: Command, name: &str) -> Error {
    let mut known: Vec<&str> = (OPTIONS.iter())
        .filter(|d| d.takes(command))
        .map(|d| d.name)
        .chain(
            (settings::KNOBS
                .iter()
                .filter(|_| command == Command::Filter))
            .map(|k| k.name),
        )
        .collect();
    known.sort_unstable();
    let whose = match command {
        Command::Filter => "the settings",
        Command::Restore => "restore's settings",
    };
    Error::Config(format!(
        "unknown setting {name:?}; {whose} are: {}",
        known.join(", ")
    ))
}
