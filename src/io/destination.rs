//! Where an output goes, and how it gets there without harm.
//!
//! Every file epfilt writes (filtered EXR, PNG preview, JSON report, synth and
//! demo files) is written to a temporary file and put in place only when it
//! is complete. What the output path names decides where that is:
//!
//! * a **new name** or a **regular file**: the temporary file is made in the
//!   same folder and renamed over it (atomic: readers see the old file or the
//!   new one, never half of one);
//! * a **symbolic link**: written through. The link stays; its final target
//!   (followed through every link, created if it does not exist yet) is
//!   replaced atomically as above;
//! * **`-`**: standard output. EXR writing needs a seekable file, so the
//!   temporary file is made in the system's temporary folder and copied to
//!   standard output once complete;
//! * **`/dev/null`** (or a link to it): the run goes through the whole
//!   pipeline into a temporary file in the system's temporary folder, which
//!   is removed once complete: the run is measured, nothing is written (as
//!   other tools take it);
//! * a **directory, another character or block device, FIFO or socket**: refused
//!   with one line, before anything is written (renaming over `/dev/stdout`
//!   would replace the link with a regular file and write nothing to it).

use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use crate::error::{Error, Result};

/// Most symbolic links followed before giving up (as Linux's `MAXSYMLINKS`).
const MAX_LINKS: usize = 40;

/// A checked output path.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Destination {
    /// A regular file or a new name: `target` is what the path names after
    /// following every symbolic link.
    File {
        /// The path as given (for messages).
        named: PathBuf,
        /// The file that is replaced or created.
        target: PathBuf,
    },
    /// Standard output (`-`).
    Stdout,
    /// `/dev/null`: written, then discarded.
    Null,
}

/// Whether `path` is the null device (through any links).
fn is_null_device(path: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::{FileTypeExt, MetadataExt};
        let null = Path::new("/dev/null");
        match (std::fs::metadata(path), std::fs::metadata(null)) {
            (Ok(a), Ok(b)) => a.file_type().is_char_device() && a.rdev() == b.rdev(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        false
    }
}

fn refuse(path: &Path, reason: impl Into<String>) -> Error {
    Error::Output {
        path: path.into(),
        reason: reason.into(),
    }
}

/// The kind of a file that is not regular, in words.
fn kind_name(ft: &std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if ft.is_char_device() {
            return "a character device";
        }
        if ft.is_block_device() {
            return "a block device";
        }
        if ft.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if ft.is_socket() {
            return "a socket";
        }
    }
    if ft.is_dir() {
        "a directory"
    } else {
        "not a regular file"
    }
}

impl Destination {
    /// Check `path` as an output: `-` is standard output; links are followed;
    /// anything but a regular file or a new name is refused.
    pub fn resolve(path: &Path) -> Result<Self> {
        if path.as_os_str() == "-" {
            return Ok(Destination::Stdout);
        }
        let named = path.to_path_buf();
        match std::fs::metadata(path) {
            Ok(m) if m.is_file() => {
                let target = std::fs::canonicalize(path).map_err(|e| Error::io(path, e))?;
                Ok(Destination::File { named, target })
            }
            Ok(_) if is_null_device(path) => Ok(Destination::Null),
            Ok(m) => Err(refuse(
                path,
                format!(
                    "is {}; epfilt writes only regular files (use - for standard output)",
                    kind_name(&m.file_type())
                ),
            )),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                // A new name, or a link to one: create the link's target,
                // in a folder that must exist.
                let target = follow_links(path)?;
                if let Some(dir) = target.parent().filter(|d| !d.as_os_str().is_empty()) {
                    if !dir.is_dir() {
                        return Err(refuse(dir, "the output folder does not exist"));
                    }
                }
                Ok(Destination::File { named, target })
            }
            Err(e) => Err(Error::io(path, e)),
        }
    }

    /// The path as given, or `-`.
    pub fn named(&self) -> &Path {
        match self {
            Destination::File { named, .. } => named,
            Destination::Stdout => Path::new("-"),
            Destination::Null => Path::new("/dev/null"),
        }
    }
}

/// Follow the links of a path whose final target does not exist yet.
fn follow_links(path: &Path) -> Result<PathBuf> {
    let mut p = path.to_path_buf();
    for _ in 0..MAX_LINKS {
        match std::fs::symlink_metadata(&p) {
            Ok(m) if m.file_type().is_symlink() => {
                let t = std::fs::read_link(&p).map_err(|e| Error::io(&p, e))?;
                p = if t.is_absolute() {
                    t
                } else {
                    p.parent().unwrap_or(Path::new(".")).join(t)
                };
            }
            _ => return Ok(p),
        }
    }
    Err(refuse(path, "too many levels of symbolic links"))
}

/// The temporary files of the outputs being written now.
static UNFINISHED: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn unfinished() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    UNFINISHED.lock().unwrap_or_else(|e| e.into_inner())
}

/// Remove the temporary files of every output still being written. For a
/// program's signal handler (thread) that is about to exit: the process then
/// leaves nothing half-written behind, whatever it was doing.
pub fn remove_unfinished() {
    for p in unfinished().drain(..) {
        let _ = std::fs::remove_file(p);
    }
}

/// An output being written: a temporary file that becomes the destination on
/// [`Staged::commit`], and is removed if dropped before (or by
/// [`remove_unfinished`]).
#[derive(Debug)]
pub struct Staged {
    temp: Option<tempfile::NamedTempFile>,
    dest: Destination,
}

impl Drop for Staged {
    fn drop(&mut self) {
        if let Some(t) = &self.temp {
            unfinished().retain(|p| p != t.path());
        }
    }
}

impl Staged {
    /// Check `dest` ([`Destination::resolve`]) and make the temporary file
    /// (`.epfilt-*<suffix>`) where it can be renamed into place.
    pub fn new(dest: &Path, suffix: &str) -> Result<Self> {
        let dest = Destination::resolve(dest)?;
        let dir = match &dest {
            Destination::Stdout | Destination::Null => std::env::temp_dir(),
            Destination::File { target, .. } => match target.parent() {
                Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
                _ => PathBuf::from("."),
            },
        };
        // Created and registered under the lock, so that a signal handler's
        // `remove_unfinished` cannot run between the two.
        let mut registry = unfinished();
        let temp = tempfile::Builder::new()
            .prefix(".epfilt-")
            .suffix(suffix)
            .tempfile_in(&dir)
            // tempfile appends "at path <temp name>" to the cause: the folder
            // is what the user named, so report the bare OS error against it.
            .map_err(|e| {
                let text = e.to_string();
                let cause = text.split(" at path ").next().unwrap_or(&text).to_string();
                Error::io(&dir, std::io::Error::new(e.kind(), cause))
            })?;
        registry.push(temp.path().to_path_buf());
        drop(registry);
        Ok(Staged {
            temp: Some(temp),
            dest,
        })
    }

    fn temp(&self) -> &tempfile::NamedTempFile {
        self.temp
            .as_ref()
            .expect("a staged file holds its temporary file until commit")
    }

    /// The temporary file, for writing.
    pub fn file(&self) -> &File {
        self.temp().as_file()
    }

    /// The temporary file's path.
    pub fn path(&self) -> &Path {
        self.temp().path()
    }

    /// Where it goes.
    pub fn destination(&self) -> &Destination {
        &self.dest
    }

    /// Put the finished file in place: rename it over the target with
    /// ordinary permissions (0644), or copy it to standard output.
    pub fn commit(mut self) -> Result<()> {
        let temp = self
            .temp
            .take()
            .expect("a staged file holds its temporary file until commit");
        // Registered until it is in place: a signal before then removes it.
        let path = temp.path().to_path_buf();
        let done = match &self.dest {
            // Dropped: the temporary file goes with it.
            Destination::Null => Ok(()),
            Destination::Stdout => {
                let mut f = File::open(temp.path()).map_err(|e| Error::io(temp.path(), e))?;
                let stdout = std::io::stdout();
                let mut lock = stdout.lock();
                std::io::copy(&mut f, &mut lock)
                    .and_then(|_| std::io::Write::flush(&mut lock))
                    .map_err(|e| Error::io("-", e))
            }
            Destination::File { named, target } => {
                #[cfg(unix)]
                {
                    use std::os::unix::fs::PermissionsExt;
                    let _ = std::fs::set_permissions(
                        temp.path(),
                        std::fs::Permissions::from_mode(0o644),
                    );
                }
                temp.into_temp_path()
                    .persist(target)
                    .map(|_| ())
                    .map_err(|e| Error::io(named, e.error))
            }
        };
        unfinished().retain(|p| *p != path);
        done
    }
}

/// Write `bytes` to `dest` through a [`Staged`] file.
pub fn write_file(dest: &Path, bytes: &[u8]) -> Result<()> {
    let staged = Staged::new(dest, ".tmp")?;
    {
        let mut f = staged.file();
        std::io::Write::write_all(&mut f, bytes)
            .and_then(|_| f.sync_all())
            .map_err(|e| Error::io(staged.destination().named(), e))?;
    }
    staged.commit()
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    #[test]
    fn kinds_of_destination() {
        let dir = tempfile::tempdir().unwrap();
        let new = dir.path().join("new.exr");
        assert!(
            matches!(Destination::resolve(&new), Ok(Destination::File { target, .. }) if target == new)
        );
        assert_eq!(
            Destination::resolve(Path::new("-")).unwrap(),
            Destination::Stdout
        );
        let err = Destination::resolve(dir.path()).unwrap_err().to_string();
        assert!(err.contains("is a directory"), "{err}");
        let err = Destination::resolve(Path::new("/dev/zero"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("character device") && err.contains("/dev/zero"),
            "{err}"
        );
        assert_eq!(
            Destination::resolve(Path::new("/dev/null")).unwrap(),
            Destination::Null
        );
        // A dangling link: its target is created, through a relative link.
        let link = dir.path().join("link.exr");
        std::os::unix::fs::symlink("sub/../real.exr", &link).unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        let Destination::File { target, .. } = Destination::resolve(&link).unwrap() else {
            panic!()
        };
        assert_eq!(target, dir.path().join("sub/../real.exr"));
        // A loop.
        let a = dir.path().join("a");
        std::os::unix::fs::symlink("b", &a).unwrap();
        std::os::unix::fs::symlink("a", dir.path().join("b")).unwrap();
        assert!(Destination::resolve(&a).is_err());
    }

    #[test]
    fn a_link_is_written_through_and_stays_a_link() {
        let dir = tempfile::tempdir().unwrap();
        let real = dir.path().join("real.json");
        std::fs::write(&real, b"old").unwrap();
        let link = dir.path().join("out.json");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        write_file(&link, b"new").unwrap();
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read(&real).unwrap(), b"new");
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 2, "no temporary file left");
    }
}
