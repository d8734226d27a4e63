//! `-` as an input: standard input, read once per process.
//!
//! The reader needs random access (an EXR's offset table points anywhere in
//! the file), so standard input is used as it is when it is a regular file
//! (`epfilt info - < x.exr`) and otherwise spooled into an unnamed temporary
//! file in the system's temporary folder (`$TMPDIR`): the kernel removes it
//! when the process ends, however it ends. Every command that opens `-`
//! again (a preview's two passes) gets the same bytes.

use std::fs::File;
use std::path::Path;
use std::sync::OnceLock;

use crate::error::{Error, Result};

/// Whether `path` names standard input.
pub fn is_stdin(path: &Path) -> bool {
    path.as_os_str() == "-"
}

/// What standard input became: a file to map, or why not.
static STDIN: OnceLock<std::result::Result<File, (std::io::ErrorKind, String)>> = OnceLock::new();

/// Bytes copied between two calls of a spool's progress.
const SPOOL_STEP: usize = 1 << 20;

fn spool(progress: &dyn Fn(u64)) -> std::result::Result<File, std::io::Error> {
    use std::io::{Read, Write};
    use std::os::fd::AsFd;
    let stdin = std::io::stdin();
    let fd = stdin.as_fd().try_clone_to_owned()?;
    let file = File::from(fd);
    if file.metadata()?.is_file() {
        return Ok(file);
    }
    let mut temp = tempfile::tempfile()?;
    let (mut input, mut buf, mut copied) = (stdin.lock(), vec![0u8; SPOOL_STEP], 0u64);
    loop {
        let n = match input.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        temp.write_all(&buf[..n])?;
        copied += n as u64;
        progress(copied);
    }
    Ok(temp)
}

/// Read standard input now (where it is a pipe, into the temporary file
/// every later open maps), telling `progress` the bytes read so far; a
/// program calls it to show that reading, which otherwise happens, quietly,
/// at the first open of `-`.
pub fn read_now(progress: &dyn Fn(u64)) {
    STDIN.get_or_init(|| spool(progress).map_err(|e| (e.kind(), e.to_string())));
}

/// Standard input as a file (a new handle on each call).
pub fn file() -> Result<File> {
    let shared = STDIN.get_or_init(|| spool(&|_| {}).map_err(|e| (e.kind(), e.to_string())));
    match shared {
        Ok(f) => f.try_clone().map_err(|e| Error::io("-", e)),
        Err((kind, text)) => Err(Error::io(
            "-",
            std::io::Error::new(*kind, format!("reading standard input: {text}")),
        )),
    }
}
