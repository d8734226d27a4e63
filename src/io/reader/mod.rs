//! Reading an EXR as a stream of planar f32 rows.
//!
//! The headers and offset tables are parsed from the memory map with the `exr`
//! crate's meta-data API; then each block row (a scan-line block, or one row of
//! tiles of the full-resolution level) is read chunk by chunk from its offset,
//! checked against where it should be, and decompressed in parallel on the
//! shared pool. Blocks are visited in increasing y whatever the file's line
//! order. Consumed byte ranges are released from the page cache.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use exr::block::chunk::{Chunk, CompressedBlock, TileCoordinates};
use exr::block::UncompressedBlock;
use exr::io::{PeekRead, Tracking};
use exr::meta::attribute::SampleType;
use exr::meta::header::Header;
use exr::meta::{magic_number, MetaData, Requirements};
use exr::prelude::Compression;
use rayon::iter::{IntoParallelRefIterator, ParallelIterator};

mod ahead;
mod blocks;
mod decode;
mod file;
mod layers;
mod pictures;
mod source;

pub use blocks::MAX_EXACT_ID;
pub(crate) use blocks::{
    block_bytes, channel_names, check_chunks, decode_checked, decode_zip_into, parse_headers,
    parse_meta, read_chunk, text_attribute,
};
use blocks::{bytes_of, invalid, part_name, reorder_planes, unsupported};
pub use file::InputFile;
use file::Layout;
pub(crate) use layers::{base_name, beauty_layers, choose_channels, scope, views};
pub use layers::{view_scope, ViewSelect};
pub use source::{ExrSource, InputSource, READ_AHEAD_BYTES};

use super::mapped::MappedFile;
use crate::error::{Error, Result};
use crate::filter::channels::ChannelRule;
use crate::pipeline::{Decoder, Source, Strip};

thread_local! {
    /// Set while a codec decodes a block on this thread.
    static IN_DECODER: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Keep the default panic message quiet for panics inside a codec: the
/// reader turns them into one clear error line (damaged B44 data, for one,
/// makes the `exr` crate's decoder panic). Other panics print as before. For
/// programs (the `epfilt` binary calls it once at start-up).
pub fn quiet_decoder_panics() {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if !IN_DECODER.with(|f| f.get()) {
            previous(info);
        }
    }));
}

/// Which part of a multi-part file to read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PartSelect {
    /// By index (0-based).
    Index(usize),
    /// By the part's `name` attribute.
    Name(String),
    /// Every part (`filter --part all`: each filtered into one multi-part
    /// output); a single-part file's only part.
    All,
}

impl PartSelect {
    /// Parse `--part`: a number is an index, `all` every part, anything else
    /// a name.
    pub fn parse(s: &str) -> Self {
        if s == "all" {
            return PartSelect::All;
        }
        s.parse()
            .map(PartSelect::Index)
            .unwrap_or_else(|_| PartSelect::Name(s.to_string()))
    }
}

/// Which image of a file a command reads (`--part`, `--layer`).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Selection {
    /// The part of a multi-part file.
    pub part: Option<PartSelect>,
    /// The layer whose R, G, B (or Y) channels are the image.
    pub layer: Option<String>,
}

impl Selection {
    /// Open `path` as selected ([`ExrInput::open_layer`]).
    pub fn open(&self, path: &Path) -> Result<ExrInput> {
        ExrInput::open_layer(path, self.part.as_ref(), self.layer.as_deref())
    }
}

#[derive(Clone, Debug)]
struct BlockRow {
    y0: usize,
    y1: usize,
    /// (offset, expected tile coordinates) of each chunk, left to right.
    chunks: Vec<(usize, TileCoordinates)>,
}

#[derive(Clone, Debug)]
pub(crate) struct Selected {
    pub(crate) name: String,
    /// Index in the header's channel list.
    index: usize,
}

/// An opened input file: headers parsed and checked, channels chosen.
#[derive(Debug)]
pub struct ExrInput {
    path: PathBuf,
    map: Arc<MappedFile>,
    meta: MetaData,
    part: usize,
    selected: Vec<Selected>,
    rows: Vec<BlockRow>,
    dropped: Vec<String>,
    /// The last `aux` selected channels are statistics (read, not filtered).
    aux: usize,
    /// Selected channels after the beauty's, before the statistics: carried
    /// by their [`ChannelRule`]s ([`ExrInput::carry_channels`]).
    carried: Vec<ChannelRule>,
    /// A Radiance picture's header: the file is RGBE / XYZE, and `meta` a
    /// header made to describe it (three f32 channels, no blocks).
    rgbe: Option<super::rgbe::RgbeHeader>,
    /// A portable float map's header: the file is PFM, and `meta` a header
    /// made to describe it.
    pfm: Option<super::pfm::PfmHeader>,
}

/// The index of the part `part` names in `meta` (the only one when none is
/// named), or an error that lists the parts.
fn choose_part(path: &Path, meta: &MetaData, part: Option<&PartSelect>) -> Result<usize> {
    Ok(match (part, meta.headers.len()) {
        (Some(PartSelect::Index(i)), n) if *i < n => *i,
        (Some(PartSelect::All), 1) => 0,
        (Some(PartSelect::All), n) => {
            return Err(Error::Config(format!(
                "{}: --part all: this command reads one of the file's {n} parts; choose one with --part NAME|INDEX",
                path.display()
            )))
        }
        (Some(PartSelect::Index(i)), n) => {
            return Err(Error::Config(format!(
                "{}: --part {i} but the file has {n} part(s)",
                path.display()
            )))
        }
        (Some(PartSelect::Name(name)), _) => meta
            .headers
            .iter()
            .position(|h| &part_name(h) == name)
            .ok_or_else(|| {
                let names: Vec<String> = meta.headers.iter().map(part_name).collect();
                Error::Config(format!(
                    "{}: no part named {name:?} (parts: {})",
                    path.display(),
                    names.join(", ")
                ))
            })?,
        (None, 1) => 0,
        (None, n) => {
            let names: Vec<String> = meta
                .headers
                .iter()
                .enumerate()
                .map(|(i, h)| format!("{i}:{:?}", part_name(h)))
                .collect();
            return Err(unsupported(
                path,
                format!(
                    "multi-part file with {n} parts ({}): choose one with --part NAME|INDEX, or filter every part with --part all",
                    names.join(", ")
                ),
            ));
        }
    })
}

/// Refuse what epfilt does not filter: deep data, subsampled channels and
/// the HTJ2K codecs.
fn check_filterable(path: &Path, header: &Header) -> Result<()> {
    if header.deep {
        return Err(unsupported(
            path,
            "deep data (deepscanline/deeptile) cannot be filtered",
        ));
    }
    if let Some(c) = header
        .channels
        .list
        .iter()
        .find(|c| c.sampling.0 != 1 || c.sampling.1 != 1)
    {
        return Err(unsupported(
            path,
            format!(
                "channel {} is subsampled {}x{} (luminance/chroma images are not supported)",
                c.name, c.sampling.0, c.sampling.1
            ),
        ));
    }
    if matches!(
        header.compression,
        Compression::HTJ2K32 | Compression::HTJ2K256
    ) {
        return Err(unsupported(
            path,
            format!("{:?} compression", header.compression),
        ));
    }
    Ok(())
}

/// The level-0 block rows of `header` in increasing y, each chunk's offset
/// (from `table`) checked to lie in the pixel data (`chunks_start..len`), and
/// the rows checked to cover the data window.
fn block_rows(
    path: &Path,
    header: &Header,
    table: &[u64],
    chunks_start: usize,
    len: usize,
) -> Result<Vec<BlockRow>> {
    // Level-0 block rows in increasing y, with checked offsets.
    let mut rows: Vec<BlockRow> = Vec::new();
    for (index, tile) in header.blocks_increasing_y_order().enumerate() {
        if tile.location.level_index != exr::math::Vec2(0, 0) {
            continue;
        }
        let bounds = header
            .get_absolute_block_pixel_coordinates(tile.location)
            .map_err(|e| Error::from_exr(path, e, "block layout"))?;
        let offset = *table
            .get(index)
            .ok_or_else(|| invalid(path, "offset table is shorter than the image"))?;
        let offset = usize::try_from(offset).unwrap_or(usize::MAX);
        if offset < chunks_start || offset >= len {
            return Err(invalid(
                path,
                format!(
                    "offset table entry {index} points to byte {offset}, outside the pixel data"
                ),
            ));
        }
        let y0 = bounds.position.1.max(0) as usize;
        let y1 = y0 + bounds.size.1;
        match rows.last_mut() {
            Some(r) if r.y0 == y0 => r.chunks.push((offset, tile.location)),
            _ => rows.push(BlockRow {
                y0,
                y1,
                chunks: vec![(offset, tile.location)],
            }),
        }
    }
    if rows.last().map(|r| r.y1) != Some(header.layer_size.1) {
        return Err(invalid(
            path,
            "the block layout does not cover the data window",
        ));
    }
    Ok(rows)
}

impl ExrInput {
    /// Open and check `path`; `part` chooses a part of a multi-part file.
    /// The colour layer is chosen as [`ExrInput::open_layer`] does without one.
    pub fn open(path: &Path, part: Option<&PartSelect>) -> Result<Self> {
        Self::open_layer(path, part, None)
    }

    /// Open and check `path`; `part` chooses a part of a multi-part file and
    /// `layer` the layer whose R, G, B (or Y) channels are filtered (e.g.
    /// `ViewLayer.Combined`; by default the unlayered channels, else the
    /// layer named as the beauty beside the most passes, else the only layer
    /// with colour).
    pub fn open_layer(path: &Path, part: Option<&PartSelect>, layer: Option<&str>) -> Result<Self> {
        Self::open_view(path, part, layer, None)
    }

    /// [`ExrInput::open_layer`] of one view of a multi-view file: its
    /// colour channels are `layer.view.R` (`view.R` without a layer, and
    /// `R` in the default view), and `layer` names the layer as the view
    /// sees it (`ViewLayer.Combined`;
    /// [`crate::filter::channels::ViewScope::seen`]).
    pub fn open_view(
        path: &Path,
        part: Option<&PartSelect>,
        layer: Option<&str>,
        view: Option<&str>,
    ) -> Result<Self> {
        InputFile::open(path)?.input(part, layer, view)
    }

    /// [`ExrInput::open_view`] of an opened file.
    fn of_file(
        file: &InputFile,
        part: Option<&PartSelect>,
        layer: Option<&str>,
        view: Option<&str>,
    ) -> Result<Self> {
        let path = file.path();
        let (meta, tables, chunks_start) = match file.layout() {
            Layout::Rgbe => {
                if let Some(v) = view {
                    return Err(Error::Config(format!(
                        "{}: a Radiance picture has no views (--view {v:?})",
                        path.display()
                    )));
                }
                return Self::open_rgbe(path, file.map(), part, layer);
            }
            Layout::Pfm => return Self::open_pfm(path, file.map(), part, layer, view),
            Layout::Exr {
                meta,
                tables,
                chunks_start,
            } => (meta, tables, *chunks_start),
        };
        let part = choose_part(path, meta, part)?;
        let header = &meta.headers[part];
        check_filterable(path, header)?;
        let scope = view_scope(path, header, view, false)?;
        let (selected, dropped) = choose_channels(path, header, layer, &scope)?;

        let rows = block_rows(
            path,
            header,
            &tables[part],
            chunks_start,
            file.bytes().len(),
        )?;
        let input = ExrInput {
            path: path.into(),
            map: file.map(),
            meta: MetaData::clone(meta),
            part,
            selected,
            rows,
            dropped,
            aux: 0,
            carried: Vec::new(),
            rgbe: None,
            pfm: None,
        };
        // What a decoder allocates per block comes from the header: bound it
        // before any command reads pixels (filter checks its whole job
        // against --max-memory as well).
        let limit = crate::host::default_max_memory();
        if input.block_bytes() > limit {
            return Err(invalid(
                path,
                format!(
                    "one block of this file claims {} MiB decoded, more than the {} MiB a block may take",
                    input.block_bytes() >> 20,
                    limit >> 20
                ),
            ));
        }
        Ok(input)
    }

    /// The Radiance header of an RGBE / XYZE input.
    pub fn rgbe(&self) -> Option<&super::rgbe::RgbeHeader> {
        self.rgbe.as_ref()
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The chosen part's header.
    pub fn header(&self) -> &Header {
        &self.meta.headers[self.part]
    }

    /// Width and height of the data window.
    pub fn size(&self) -> (usize, usize) {
        let s = self.header().layer_size;
        (s.0, s.1)
    }

    /// Where the data window starts (its top-left sample).
    pub fn origin(&self) -> (i32, i32) {
        let o = self.header().own_attributes.layer_position;
        (o.0, o.1)
    }

    /// Whether the channel `name` holds unsigned integers (ids).
    pub fn is_uint(&self, name: &str) -> bool {
        self.header().channels.list.iter().any(|c| {
            c.name.to_string() == name && c.sample_type == exr::meta::attribute::SampleType::U32
        })
    }

    /// Bytes of one decompressed block of this file (all channels), as the
    /// header claims: what a decoder allocates for it.
    pub fn block_bytes(&self) -> u64 {
        block_bytes(self.header())
    }

    /// Bytes one block of this file takes in it at most (its offset table's
    /// gaps), at most [`ExrInput::block_bytes`]: what the reader's window
    /// holds of the mapped file a block.
    pub fn stored_block_bytes(&self) -> u64 {
        let offsets = self.rows.iter().flat_map(|r| r.chunks.iter().map(|c| c.0));
        let largest = blocks::largest_chunk(offsets, self.map.bytes().len());
        largest.map_or(self.block_bytes(), |n| n.min(self.block_bytes()))
    }

    /// Whether its blocks are inflated straight into the reader's window
    /// (ZIP and ZIPS scan lines, [`crate::io::zip::codes`], every channel a
    /// 32-bit float and read): no decoder holds a block of its own.
    pub fn decodes_in_place(&self) -> bool {
        let h = self.header();
        let lines = matches!(h.blocks, exr::meta::BlockDescription::ScanLines);
        crate::io::zip::codes(h.compression) && lines && self.reads_every_f32_channel()
    }

    /// Every channel is a 32-bit float and read: a block's bytes are the
    /// rows' values, in the file's channel order.
    fn reads_every_f32_channel(&self) -> bool {
        let channels = &self.header().channels.list;
        channels.iter().all(|c| c.sample_type == SampleType::F32)
            && self.selected.len() == channels.len()
    }

    /// Names of the channels that will be filtered, in strip order.
    pub fn channels(&self) -> Vec<String> {
        let n = self.selected.len() - self.aux;
        self.selected[..n].iter().map(|s| s.name.clone()).collect()
    }

    /// Names of the statistics channels read after the filtered ones.
    pub fn aux_channels(&self) -> Vec<String> {
        let n = self.selected.len() - self.aux;
        self.selected[n..].iter().map(|s| s.name.clone()).collect()
    }

    /// Every channel name of the chosen part, in header order.
    pub fn all_channels(&self) -> Vec<String> {
        channel_names(self.header())
    }

    /// Also read `names` (after the filtered channels, in this order), as
    /// statistics: they are not filtered and not written.
    pub fn add_aux_channels(&mut self, names: &[String]) -> Result<()> {
        let all = self.all_channels();
        for name in names {
            let index = all.iter().position(|n| n == name).ok_or_else(|| {
                unsupported(
                    &self.path,
                    format!("no channel {name:?} (the file has: {})", all.join(", ")),
                )
            })?;
            // A colour channel may serve as a statistic too (read twice).
            let colour = self.selected.len() - self.aux;
            if self.selected[colour..].iter().any(|s| s.index == index) {
                continue;
            }
            self.selected.push(Selected {
                name: name.clone(),
                index,
            });
            self.aux += 1;
            self.dropped.retain(|d| d != name);
        }
        Ok(())
    }

    /// Where each of `names` is in a strip row: a channel `carried` keeps
    /// as it is read (a float with an average or nearest rule: the books
    /// never alter it) where it is carried, so it is held once; the others
    /// read after the filtered channels ([`ExrInput::add_aux_channels`]).
    pub fn read_beside(
        &mut self,
        names: &[String],
        carried: &[(String, ChannelRule)],
    ) -> Result<Vec<usize>> {
        let filtered = self.channels();
        let copy = |name: &String| {
            let rule = carried.iter().find(|(n, _)| n == name).map(|c| c.1);
            let exact = matches!(rule, Some(ChannelRule::Average | ChannelRule::Nearest));
            (exact && !self.is_uint(name))
                .then(|| filtered.iter().position(|f| f == name))
                .flatten()
        };
        let copies: Vec<Option<usize>> = names.iter().map(copy).collect();
        let read: Vec<String> = (names.iter().zip(&copies))
            .filter(|(_, c)| c.is_none())
            .map(|(n, _)| n.clone())
            .collect();
        self.add_aux_channels(&read)?;
        let aux = self.aux_channels();
        let at = |(name, copied): (&String, &Option<usize>)| {
            copied
                .unwrap_or_else(|| filtered.len() + aux.iter().position(|a| a == name).unwrap_or(0))
        };
        Ok(names.iter().zip(&copies).map(at).collect())
    }

    /// Carry the channels beside the beauty's: each gets `rule(name, uint)`;
    /// those it drops stay dropped. Returns the carried channels and their
    /// rules. Call before [`ExrInput::add_aux_channels`].
    pub fn carry_channels(
        &mut self,
        rule: impl Fn(&str, bool) -> ChannelRule,
    ) -> Vec<(String, ChannelRule)> {
        assert_eq!(self.aux, 0, "carry channels before the statistics");
        let header = self.header();
        let mut carried = Vec::new();
        let mut added = Vec::new();
        for (index, ch) in header.channels.list.iter().enumerate() {
            let name = ch.name.to_string();
            if self.selected.iter().any(|s| s.index == index) {
                continue;
            }
            let uint = ch.sample_type == SampleType::U32;
            let r = rule(&name, uint);
            if r == ChannelRule::Drop {
                continue;
            }
            added.push(Selected {
                name: name.clone(),
                index,
            });
            carried.push((name, r));
        }
        self.dropped
            .retain(|d| !carried.iter().any(|(n, _)| n == d));
        self.selected.extend(added);
        self.carried = carried.iter().map(|(_, r)| *r).collect();
        carried
    }

    /// The rule of each filtered channel, in strip order: `None` for the
    /// beauty's own.
    pub fn channel_rules(&self) -> Vec<Option<ChannelRule>> {
        let n = self.selected.len() - self.aux - self.carried.len();
        (0..n)
            .map(|_| None)
            .chain(self.carried.iter().map(|&r| Some(r)))
            .collect()
    }

    /// Channels of the file that are not filtered (and not written).
    pub fn dropped_channels(&self) -> &[String] {
        &self.dropped
    }

    /// Luminance weight of each filtered channel.
    pub fn luminance(&self) -> Vec<f64> {
        let rgb = super::luminance_weights(self.header().shared_attributes.chromaticities.as_ref());
        let beauty = self.selected.len() - self.aux - self.carried.len();
        self.selected[..self.selected.len() - self.aux]
            .iter()
            .enumerate()
            .map(|(i, s)| if i >= beauty { "" } else { base_name(&s.name) })
            .map(|b| match b {
                "R" => rgb[0],
                "G" => rgb[1],
                "B" => rgb[2],
                "Y" => 1.0,
                _ => 0.0,
            })
            .collect()
    }

    /// A source of rows from the block that holds row `y` on (rows above it
    /// are not decoded; a Radiance picture is read from the top, its
    /// scanlines having no index).
    pub fn source_from(&self, y: usize) -> InputSource<'_> {
        let mut src = self.source();
        if let InputSource::Exr(e) = &mut src {
            let first = self.rows.iter().position(|r| r.y1 > y);
            e.next_row = first.unwrap_or(self.rows.len());
            e.buf_y0 = first.map_or(self.size().1, |i| self.rows[i].y0);
        }
        src
    }

    /// A source of rows over this file.
    pub fn source(&self) -> InputSource<'_> {
        if let Some(ph) = &self.pfm {
            return InputSource::Pfm(super::pfm::PfmSource::new(
                &self.path,
                self.map.bytes(),
                ph.clone(),
            ));
        }
        if let Some(rh) = &self.rgbe {
            return InputSource::Rgbe(super::rgbe::RgbeSource::new(
                &self.path,
                self.map.bytes(),
                rh.clone(),
            ));
        }
        let (w, _) = self.size();
        InputSource::Exr(ExrSource {
            input: self,
            next_row: 0,
            buf: Vec::new(),
            head: 0,
            buf_y0: 0,
            row_len: self.selected.len() * w,
            released: None,
            ahead: None,
            batch_blocks: 0,
            spare: Vec::new(),
        })
    }

    /// Decode the tiles of one block row, each into its own buffer.
    fn decode_row(&self, row: &BlockRow) -> Result<Vec<Decoded>> {
        row.chunks
            .par_iter()
            .map(|&(offset, expected)| {
                let mut rows = Vec::new();
                let Landed { x0, width, bytes } =
                    self.decode_chunk(offset, expected, row.y1 - row.y0, Place::Own(&mut rows))?;
                Ok(Decoded {
                    x0,
                    width,
                    rows,
                    bytes,
                })
            })
            .collect()
    }

    /// The file's channel index of each selected channel where a block of
    /// `lines` lines, `width` samples wide, can be decoded straight into a
    /// buffer of `len` values as its rows (every channel 32-bit float, each
    /// selected, the block as wide as the rows): the block's bytes are then
    /// the rows' values, with the channels in the file's order.
    fn in_place_order(&self, lines: usize, width: usize, len: usize) -> Option<Vec<usize>> {
        let n = self.selected.len();
        (self.reads_every_f32_channel() && lines.checked_mul(n * width) == Some(len))
            .then(|| self.selected.iter().map(|s| s.index).collect())
    }

    /// Read, check and decompress one chunk of `lines` lines into `place`.
    /// Returns (first column, width, consumed byte range).
    fn decode_chunk(
        &self,
        offset: usize,
        expected: TileCoordinates,
        lines: usize,
        mut place: Place<'_>,
    ) -> Result<Landed> {
        let path = &self.path;
        let header = self.header();
        let (chunk, end) = read_chunk(
            path,
            self.map.bytes(),
            &self.meta,
            self.part,
            offset,
            expected,
        )?;
        if let Place::InPlace { dst, width } = &mut place {
            if let Some(order) = self.in_place_order(lines, *width, dst.len()) {
                let bytes: &mut [u8] = bytemuck::cast_slice_mut(dst);
                if let Some(index) = decode_zip_into(path, &self.meta, offset, &chunk, bytes)? {
                    if index.pixel_position.0 != 0
                        || (index.pixel_size.0, index.pixel_size.1) != (*width, lines)
                    {
                        return Err(invalid(
                            path,
                            format!("block at byte {offset} decodes to the wrong size"),
                        ));
                    }
                    // The planes in the rows' order (in the decoding task:
                    // in the strips' copy, on the reader's thread, it was
                    // serial work of every strip).
                    for line in dst.chunks_exact_mut(order.len() * *width) {
                        reorder_planes(line, *width, &order);
                    }
                    return Ok(Landed {
                        x0: 0,
                        width: *width,
                        bytes: (offset, end),
                    });
                }
            }
        }
        let block = decode_checked(path, &self.meta, offset, &chunk)?;
        let (bw, bh) = (block.index.pixel_size.0, block.index.pixel_size.1);
        let channels = &header.channels.list;
        let line_bytes: usize = channels.iter().map(|c| bw * bytes_of(c.sample_type)).sum();
        if block.data.len() != line_bytes * bh || bh != lines {
            return Err(invalid(
                path,
                format!("block at byte {offset} decodes to the wrong size"),
            ));
        }
        let mut ch_off = Vec::with_capacity(channels.len());
        let mut acc = 0;
        for c in channels.iter() {
            ch_off.push(acc);
            acc += bw * bytes_of(c.sample_type);
        }
        let n = self.selected.len();
        let x0 = block.index.pixel_position.0;
        let (dst, stride, at): (&mut [f32], usize, usize) = match place {
            Place::InPlace { dst, width } if x0 + bw <= width => (dst, width, x0),
            Place::InPlace { .. } => {
                return Err(invalid(
                    path,
                    format!("block at byte {offset} lies outside the data window"),
                ))
            }
            Place::Own(v) => {
                v.clear();
                v.resize(bh * n * bw, 0.0);
                (v.as_mut_slice(), bw, 0)
            }
        };
        for line in 0..bh {
            for (k, sel) in self.selected.iter().enumerate() {
                let t = channels[sel.index].sample_type;
                let from = line * line_bytes + ch_off[sel.index];
                block.read(t, from, &mut dst[(line * n + k) * stride + at..][..bw]).map_err(|v| {
                    unsupported(
                        path,
                        format!(
                            "uint channel {} holds {v}, above 2^24: f32 cannot carry such ids exactly; drop it with --channel-rule '{}=drop'",
                            sel.name, sel.name
                        ),
                    )
                })?;
            }
        }
        Ok(Landed {
            x0,
            width: bw,
            bytes: (offset, end),
        })
    }
}

/// Where a decoded chunk landed: first column, width, bytes of the file.
struct Landed {
    x0: usize,
    width: usize,
    bytes: (usize, usize),
}

/// Where a decoded block goes.
enum Place<'a> {
    /// Into rows of `width` columns, at the block's own columns.
    InPlace { dst: &'a mut [f32], width: usize },
    /// Into its own buffer, exactly the block's size.
    Own(&'a mut Vec<f32>),
}

/// One decompressed block: its first column, width, planar rows
/// `[line][channel][x]` and the byte range it came from.
struct Decoded {
    x0: usize,
    width: usize,
    rows: Vec<f32>,
    bytes: (usize, usize),
}

#[cfg(test)]
mod tests;
