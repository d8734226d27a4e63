//! Multi-view (stereo) files: their views, and one output put together from
//! the runs that filtered each view as an image of its own (`--view all`).
//!
//! OpenEXR keeps the views of a single-part stereo file in one channel list
//! (`R`, `G`, `B` of the default view, `right.R`... of the others; the
//! `multiView` attribute lists them, the default first). Each view is a
//! different picture, so `--view all` filters each with its own noise
//! decisions into a file of its own, and this module copies their channels,
//! value for value, into one file with the input's `multiView`.

use std::path::{Path, PathBuf};

use exr::meta::attribute::{ChannelDescription, ChannelList, Text};
use exr::prelude::SmallVec;

use super::{ExrInput, OutputSettings};
use crate::error::{Error, Result};
use crate::filter::channels::ChannelRule;
use crate::pipeline::{Sink, Source, Strip};

/// Rows copied at once.
const STRIP_ROWS: usize = 64;

/// Write `dest` with every channel of `sources` (each a view's file, which
/// names that view alone), in that order, values as they are, under the
/// first source's header attributes with `views` as its `multiView` and
/// `fingerprint` recorded.
pub fn assemble(
    sources: &[PathBuf],
    dest: &Path,
    views: &[String],
    fingerprint: &str,
) -> Result<()> {
    let mut inputs = Vec::with_capacity(sources.len());
    for path in sources {
        let mut input = ExrInput::open(path, None)?;
        // Every channel, as it is (ids stay whole numbers).
        input.carry_channels(|_, uint| {
            if uint {
                ChannelRule::Nearest
            } else {
                ChannelRule::Average
            }
        });
        inputs.push(input);
    }
    let first = inputs
        .first()
        .ok_or_else(|| Error::Internal("no view to put together".into()))?;
    let size = first.size();
    if let Some(odd) = inputs.iter().find(|i| i.size() != size) {
        return Err(Error::Internal(format!(
            "{}: a view's size differs from the others'",
            odd.path().display()
        )));
    }
    let names: Vec<String> = inputs.iter().flat_map(|i| i.channels()).collect();
    let mut header = first.header().clone();
    let mut list: Vec<ChannelDescription> = inputs
        .iter()
        .flat_map(|i| i.header().channels.list.iter().cloned())
        .collect();
    list.sort_by(|a, b| a.name.cmp(&b.name));
    header.channels = ChannelList::new(SmallVec::from_vec(list));
    header.own_attributes.multi_view_names =
        Some(views.iter().map(|v| Text::from(v.as_str())).collect());
    // The settings the first view's run recorded, and that it was every view.
    let software = super::provenance::settings_text(&header).unwrap_or_default();
    // The views' runs were one run: its line of the history once.
    drop_last_run(&mut header);
    let prefix = format!("epfilt {} (", env!("CARGO_PKG_VERSION"));
    let provenance = software
        .strip_prefix(&prefix)
        .and_then(|s| s.strip_suffix(')'))
        .map(|s| format!("{s} view=all"));
    let settings = OutputSettings {
        compression: None,
        precision: None,
        allow_lossy: false,
        provenance,
        extra: vec![(super::provenance::FINGERPRINT.into(), fingerprint.into())],
        write_ahead: 0,
    };
    let mut out = super::ExrOutput::create(dest, &header, 1, &names, 0, &settings)?;
    let (w, h) = size;
    let mut sources: Vec<_> = inputs
        .iter()
        .map(|i| (i.source(), i.channels().len()))
        .collect();
    let nch = names.len();
    let mut y = 0;
    let mut rows_buf = Vec::new();
    while y < h {
        let n = STRIP_ROWS.min(h - y);
        let strips: Vec<(Strip, usize)> = sources
            .iter_mut()
            .map(|(src, k)| {
                let strip = src
                    .next_strip(n)?
                    .filter(|s| s.rows == n)
                    .ok_or_else(|| Error::Internal("a view ended early".into()))?;
                Ok((strip, *k))
            })
            .collect::<Result<_>>()?;
        rows_buf.clear();
        rows_buf.reserve(n * nch * w);
        for r in 0..n {
            for (strip, k) in &strips {
                rows_buf.extend_from_slice(&strip.data[r * k * w..(r + 1) * k * w]);
            }
        }
        out.write_rows(y, n, &rows_buf)?;
        y += n;
    }
    out.finish()?;
    out.commit()
}

/// Take the last line off `header`'s history: the view's run, which the
/// writer records again as the whole file's.
fn drop_last_run(header: &mut exr::meta::header::Header) {
    use exr::meta::attribute::AttributeValue;
    let key = Text::from(super::writer::HISTORY_ATTRIBUTE);
    let Some(AttributeValue::Text(t)) = header.own_attributes.other.remove(&key) else {
        return;
    };
    if let Some((before, _)) = t.to_string().rsplit_once('\n') {
        let value = AttributeValue::Text(Text::from(before));
        header.own_attributes.other.insert(key, value);
    }
}
