//! Typed errors of the library.
//!
//! Split as exrs does: invalid data, unsupported features, the operating system,
//! and configuration mistakes. Every variant that concerns a file names it.

use std::path::PathBuf;

/// Everything that can go wrong in epfilt.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The arguments do not make a valid filter or pipeline.
    #[error("invalid configuration: {0}")]
    Config(String),

    /// The file is not a valid OpenEXR file, or is damaged.
    #[error("{path}: invalid or damaged EXR: {reason}")]
    InvalidFile {
        /// The file.
        path: PathBuf,
        /// What is wrong, and where.
        reason: String,
    },

    /// The file is not a valid Radiance picture, or is damaged.
    #[error("{path}: invalid or damaged Radiance picture: {reason}")]
    InvalidPicture {
        /// The file.
        path: PathBuf,
        /// What is wrong, and where.
        reason: String,
    },

    /// The file is not a valid portable float map (PFM), or is damaged.
    #[error("{path}: invalid or damaged portable float map: {reason}")]
    InvalidFloatMap {
        /// The file.
        path: PathBuf,
        /// What is wrong, and where.
        reason: String,
    },

    /// The file is valid but uses something epfilt cannot filter.
    #[error("{path}: unsupported: {reason}")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// What is not supported.
        reason: String,
    },

    /// The file lacks channels (or metadata) the job needs.
    #[error("{path}: {reason}")]
    Channels {
        /// The file.
        path: PathBuf,
        /// What is missing, and what the file has.
        reason: String,
    },

    /// A sample value that the filter or the output cannot handle.
    #[error("{path}: {reason}")]
    Value {
        /// The file concerned (input or output).
        path: PathBuf,
        /// What value, where.
        reason: String,
    },

    /// A sample value the pipeline cannot handle, found before it knows
    /// the file: which side it is on (the job names the file, as
    /// [`Error::Value`]).
    #[error("{reason}")]
    StreamValue {
        /// An input sample, or an output value.
        side: Side,
        /// What value, where.
        reason: String,
    },

    /// Two images that must match do not: their sizes or channels differ.
    #[error("{reason}")]
    Mismatch {
        /// The image compared.
        path: PathBuf,
        /// What differs, naming both files.
        reason: String,
    },

    /// An operating-system error on a file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },

    /// An output path epfilt will not write to (a directory, a device, a
    /// FIFO, ...).
    #[error("{path}: {reason}")]
    Output {
        /// The path as given.
        path: PathBuf,
        /// Why.
        reason: String,
    },

    /// The energy ledger did not balance: the output was not written.
    #[error("energy ledger does not balance (channel {channel}: relative error {rel_error:e}); output not written")]
    Ledger {
        /// Channel name.
        channel: String,
        /// Relative difference found.
        rel_error: f64,
    },

    /// A broken invariant of epfilt itself (a bug: please report it).
    #[error("internal error: {0}")]
    Internal(String),

    /// The run was interrupted.
    #[error("interrupted; no output written")]
    Interrupted,
}

/// Result with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    /// Turn an `exr` crate error into ours, with the file named.
    pub fn from_exr(path: impl Into<PathBuf>, err: exr::error::Error, context: &str) -> Self {
        let path = path.into();
        let ctx = if context.is_empty() {
            String::new()
        } else {
            format!("{context}: ")
        };
        match err {
            exr::error::Error::NotSupported(msg) => Error::Unsupported {
                path,
                reason: format!("{ctx}{msg}"),
            },
            exr::error::Error::Invalid(msg) => Error::InvalidFile {
                path,
                reason: format!("{ctx}{msg}"),
            },
            exr::error::Error::Io(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
                Error::InvalidFile {
                    path,
                    reason: format!("{ctx}file is truncated"),
                }
            }
            exr::error::Error::Io(e) => Error::Io { path, source: e },
            exr::error::Error::Aborted => Error::Interrupted,
        }
    }
}

/// An error and the causes it does not already spell out, as one line (what
/// the command prints after `epfilt: `).
pub fn one_line(e: &(dyn std::error::Error + 'static)) -> String {
    let mut line = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let text = c.to_string();
        if !line.contains(&text) {
            line = format!("{line}: {text}");
        }
        cause = c.source();
    }
    line.replace('\n', " ")
}

/// Which side of a run a value is on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// A sample read from the input.
    Input,
    /// A sample of a run's second input (`restore`'s denoiser output).
    SecondInput,
    /// A value being written to the output.
    Output,
}
