//! Pictures that are not OpenEXR files, opened as one: a Radiance picture
//! and a portable float map each described by a one-part header of f32
//! channels, so that every command reads them as it reads an EXR.

use std::path::Path;
use std::sync::Arc;

use exr::meta::header::Header;
use exr::meta::{MetaData, Requirements};

use super::{channel_names, ExrInput, PartSelect, Selected};
use crate::error::{Error, Result};
use crate::io::mapped::MappedFile;
use crate::io::pfm::PfmHeader;
use crate::io::rgbe::RgbeHeader;

impl ExrInput {
    /// A Radiance picture, described as a single-part file of three f32
    /// channels (R, G, B, or X, Y, Z for XYZE) with the picture's primaries.
    pub(super) fn open_rgbe(
        path: &Path,
        map: Arc<MappedFile>,
        part: Option<&PartSelect>,
        layer: Option<&str>,
    ) -> Result<Self> {
        if matches!(part, Some(PartSelect::Index(i)) if *i != 0)
            || matches!(part, Some(PartSelect::Name(_)))
        {
            return Err(Error::Config(format!(
                "{}: a Radiance picture has one part (--part 0)",
                path.display()
            )));
        }
        if let Some(l) = layer {
            return Err(Error::Config(format!(
                "{}: a Radiance picture has no layers (--layer {l:?})",
                path.display()
            )));
        }
        let rh = crate::io::rgbe::parse_header(path, map.bytes())?;
        let (header, names, _) = rh.exr_header();
        Ok(Self::picture(path, map, header, &names, (Some(rh), None)))
    }

    /// A portable float map (OIDN's), described as a single-part file of
    /// f32 channels (R, G, B, or Y for a grey map).
    pub(super) fn open_pfm(
        path: &Path,
        map: Arc<MappedFile>,
        part: Option<&PartSelect>,
        layer: Option<&str>,
        view: Option<&str>,
    ) -> Result<Self> {
        let refuse = |what: String| {
            Err(Error::Config(format!(
                "{}: a portable float map has {what}",
                path.display()
            )))
        };
        if matches!(part, Some(PartSelect::Index(i)) if *i != 0)
            || matches!(part, Some(PartSelect::Name(_)))
        {
            return refuse("one part (--part 0)".into());
        }
        if let Some(l) = layer {
            return refuse(format!("no layers (--layer {l:?})"));
        }
        if let Some(v) = view {
            return refuse(format!("no views (--view {v:?})"));
        }
        let ph = crate::io::pfm::parse_header(path, map.bytes())?;
        let header = ph.exr_header();
        Ok(Self::picture(
            path,
            map,
            header,
            ph.names(),
            (None, Some(ph)),
        ))
    }

    /// The input over a picture described by `header`: one part, its
    /// channels `names` in the picture's order.
    fn picture(
        path: &Path,
        map: Arc<MappedFile>,
        header: Header,
        names: &[&str],
        (rgbe, pfm): (Option<RgbeHeader>, Option<PfmHeader>),
    ) -> Self {
        let sorted = channel_names(&header);
        let selected = (names.iter())
            .map(|n| Selected {
                name: n.to_string(),
                index: sorted.iter().position(|s| s == n).unwrap_or(0),
            })
            .collect();
        let meta = MetaData {
            requirements: Requirements {
                file_format_version: 2,
                is_single_layer_and_tiled: false,
                has_long_names: false,
                has_deep_data: false,
                has_multiple_layers: false,
            },
            headers: exr::prelude::SmallVec::from_vec(vec![header]),
        };
        ExrInput {
            path: path.into(),
            map,
            meta,
            part: 0,
            selected,
            rows: Vec::new(),
            dropped: Vec::new(),
            aux: 0,
            carried: Vec::new(),
            rgbe,
            pfm,
        }
    }
}
