//! An input file opened once: mapped, its headers parsed and its offset
//! tables read. A command asks everything it needs of its input before
//! reading a pixel (the verdict, the fingerprint, the parts, the views, the
//! plan's part, layer and view) of this one opening.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use exr::io::{PeekRead, Tracking};
use exr::meta::MetaData;

use super::blocks::{parse_headers_from, part_name, read_tables};
use super::{ExrInput, PartSelect};
use crate::error::Result;
use crate::io::mapped::MappedFile;
use crate::io::parts::PartInfo;

/// What the file is, read from its first bytes.
#[derive(Clone, Debug)]
pub(super) enum Layout {
    /// An OpenEXR file: its headers, each part's offset table and where the
    /// chunks start.
    Exr {
        meta: Arc<MetaData>,
        tables: Arc<Vec<Vec<u64>>>,
        chunks_start: usize,
    },
    /// A Radiance picture (RGBE / XYZE), parsed when a part is opened.
    Rgbe,
    /// A portable float map, parsed when a part is opened.
    Pfm,
}

/// An input file, mapped and its layout parsed once; cheap to clone.
#[derive(Clone, Debug)]
pub struct InputFile {
    path: PathBuf,
    map: Arc<MappedFile>,
    layout: Layout,
}

impl InputFile {
    /// Map `path` (`-`: standard input) and parse its headers and offset
    /// tables, whose sizes are checked against the file's before anything
    /// is allocated for them.
    pub fn open(path: &Path) -> Result<Self> {
        let map = MappedFile::open(path)?;
        let bytes = map.bytes();
        let layout = if crate::io::rgbe::is_rgbe(bytes) {
            Layout::Rgbe
        } else if crate::io::pfm::is_pfm(bytes) {
            Layout::Pfm
        } else {
            let mut read = PeekRead::new(Tracking::new(bytes));
            let meta = parse_headers_from(path, &mut read)?;
            let (tables, chunks_start) = read_tables(path, bytes, &mut read, &meta)?;
            Layout::Exr {
                meta: Arc::new(meta),
                tables: Arc::new(tables),
                chunks_start,
            }
        };
        Ok(InputFile {
            path: path.into(),
            map: Arc::new(map),
            layout,
        })
    }

    /// The path it was opened from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The mapped bytes.
    pub fn bytes(&self) -> &[u8] {
        self.map.bytes()
    }

    /// Let the pages of bytes `start..end` go from this process (they stay
    /// in the page cache: a later read maps them again).
    pub fn release(&self, start: usize, end: usize) {
        self.map.release(start, end);
    }

    pub(super) fn map(&self) -> Arc<MappedFile> {
        Arc::clone(&self.map)
    }

    pub(super) fn layout(&self) -> &Layout {
        &self.layout
    }

    /// The image `part`, `layer` and `view` name, checked and its channels
    /// chosen (see [`ExrInput::open_view`]).
    pub fn input(
        &self,
        part: Option<&PartSelect>,
        layer: Option<&str>,
        view: Option<&str>,
    ) -> Result<ExrInput> {
        ExrInput::of_file(self, part, layer, view)
    }

    /// The parts of the file (one for a Radiance picture or a PFM).
    pub fn parts(&self) -> Vec<PartInfo> {
        let Layout::Exr { meta, .. } = &self.layout else {
            return vec![PartInfo {
                index: 0,
                name: String::new(),
                deep: false,
            }];
        };
        (meta.headers.iter().enumerate())
            .map(|(index, h)| PartInfo {
                index,
                name: part_name(h),
                deep: h.deep,
            })
            .collect()
    }

    /// Where the pixel data starts: after the headers and offset tables, or
    /// after a picture's header (`None`: a picture whose header does not
    /// parse; opening its part says why).
    pub fn data_start(&self) -> Option<usize> {
        match &self.layout {
            Layout::Exr { chunks_start, .. } => Some(*chunks_start),
            Layout::Rgbe => crate::io::rgbe::parse_header(&self.path, self.bytes())
                .map(|h| h.data)
                .ok(),
            Layout::Pfm => crate::io::pfm::parse_header(&self.path, self.bytes())
                .map(|h| h.data)
                .ok(),
        }
    }
}
