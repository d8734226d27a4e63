//! The memory-mapped input file: the crate's only `unsafe`.
#![allow(unsafe_code)]

use std::fs::File;
use std::path::Path;

use memmap2::{Advice, Mmap, UncheckedAdvice};

use crate::error::{Error, Result};

/// A read-only memory map of a whole file.
#[derive(Debug)]
pub struct MappedFile {
    map: Mmap,
}

impl MappedFile {
    /// Map `path` read-only, with sequential read-ahead advice; `-` is
    /// standard input ([`super::stdin`]), which must hold an OpenEXR file or
    /// a Radiance picture.
    pub fn open(path: &Path) -> Result<Self> {
        let stdin = super::stdin::is_stdin(path);
        let file = if stdin {
            super::stdin::file()?
        } else {
            File::open(path).map_err(|e| Error::io(path, e))?
        };
        let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
        if len == 0 {
            return Err(Error::InvalidFile {
                path: path.into(),
                reason: if stdin {
                    "standard input is empty".into()
                } else {
                    "the file is empty".into()
                },
            });
        }
        // SAFETY: the map is read-only and private to this process. epfilt
        // never writes the input (it refuses an output path that is the input,
        // also through links), so the only way the bytes change under us is
        // another process truncating or rewriting the file while we run, which
        // is outside what any reader can defend against (the same holds for
        // every mmap-based tool).
        let map = unsafe { Mmap::map(&file) }.map_err(|e| Error::io(path, e))?;
        let _ = map.advise(Advice::Sequential);
        if stdin
            && !matches!(
                super::Format::sniff(&map),
                Some(super::Format::Exr | super::Format::Rgbe)
            )
            && !super::pfm::is_pfm(&map)
        {
            return Err(Error::InvalidFile {
                path: path.into(),
                reason:
                    "standard input holds no OpenEXR file, Radiance picture or portable float map"
                        .into(),
            });
        }
        Ok(MappedFile { map })
    }

    /// The bytes.
    pub fn bytes(&self) -> &[u8] {
        &self.map
    }

    /// Tell the kernel it may drop the pages of `start..end` that we have
    /// consumed, so the resident set does not grow with the file (sequential
    /// advice alone does not release them). Pages only partly inside the range
    /// are kept.
    pub fn release(&self, start: usize, end: usize) {
        const PAGE: usize = 4096;
        let a = start.div_ceil(PAGE) * PAGE;
        let b = (end.min(self.map.len()) / PAGE) * PAGE;
        if b > a {
            // SAFETY: MADV_DONTNEED on a read-only file mapping only discards
            // cached pages; a later access faults them in again from the file,
            // with the same contents. No reference into the range is used after
            // this call without going back through the map.
            let _ = unsafe {
                self.map
                    .unchecked_advise_range(UncheckedAdvice::DontNeed, a, b - a)
            };
        }
    }
}
