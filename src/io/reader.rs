//! Reading an EXR as a stream of planar f32 rows.
//!
//! The headers and offset tables are parsed from the memory map with the `exr`
//! crate's meta-data API; then each block row (a scan-line block, or one row of
//! tiles of the full-resolution level) is read chunk by chunk from its offset,
//! checked against where it should be, and decompressed in parallel on the
//! shared pool. Blocks are visited in increasing y whatever the file's line
//! order. Consumed byte ranges are released from the page cache.

use std::path::{Path, PathBuf};

use exr::block::chunk::{Chunk, CompressedBlock, TileCoordinates};
use exr::block::UncompressedBlock;
use exr::io::{PeekRead, Tracking};
use exr::meta::attribute::SampleType;
use exr::meta::header::Header;
use exr::meta::{magic_number, MetaData, Requirements};
use exr::prelude::Compression;
use rayon::prelude::*;

use super::mapped::MappedFile;
use crate::error::{Error, Result};
use crate::filter::channels::ChannelRule;
use crate::pipeline::{Source, Strip};

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
    map: MappedFile,
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
}

fn invalid(path: &Path, reason: impl Into<String>) -> Error {
    Error::InvalidFile {
        path: path.into(),
        reason: reason.into(),
    }
}

fn unsupported(path: &Path, reason: impl Into<String>) -> Error {
    Error::Unsupported {
        path: path.into(),
        reason: reason.into(),
    }
}

fn bytes_of(t: SampleType) -> usize {
    match t {
        SampleType::F16 => 2,
        SampleType::F32 | SampleType::U32 => 4,
    }
}

fn part_name(h: &Header) -> String {
    h.own_attributes
        .layer_name
        .as_ref()
        .map(|t| t.to_string())
        .unwrap_or_default()
}

/// The headers, checked, and the offset tables of the EXR file `bytes`
/// (whose total size must fit in it), and where the chunks start.
pub(crate) fn parse_meta(path: &Path, bytes: &[u8]) -> Result<(MetaData, Vec<Vec<u64>>, usize)> {
    let mut read = PeekRead::new(Tracking::new(bytes));
    let meta = parse_headers_from(path, &mut read)?;
    let (tables, chunks_start) = read_tables(path, bytes, &mut read, &meta)?;
    Ok((meta, tables, chunks_start))
}

/// The offset tables that follow the headers (`read` is just past them),
/// whose total size must fit in the file, and where the chunks start.
fn read_tables(
    path: &Path,
    bytes: &[u8],
    read: &mut PeekRead<Tracking<&[u8]>>,
    meta: &MetaData,
) -> Result<(Vec<Vec<u64>>, usize)> {
    let table_bytes: usize = meta
        .headers
        .iter()
        .map(|h| h.chunk_count.saturating_mul(8))
        .sum();
    if read.byte_position().saturating_add(table_bytes) > bytes.len() {
        return Err(invalid(
            path,
            "truncated: the chunk offset table does not fit in the file",
        ));
    }
    let tables = MetaData::read_offset_tables(read, &meta.headers)
        .map_err(|e| Error::from_exr(path, e, "offset table"))?;
    Ok((tables.into_vec(), read.byte_position()))
}

/// The headers of the EXR file `bytes`, where its pixel data starts (past
/// the offset tables) and the tables.
pub(crate) fn parse_layout(path: &Path, bytes: &[u8]) -> Result<(MetaData, usize, Vec<Vec<u64>>)> {
    let mut read = PeekRead::new(Tracking::new(bytes));
    let meta = parse_headers_from(path, &mut read)?;
    let (tables, start) = read_tables(path, bytes, &mut read, &meta)?;
    Ok((meta, start, tables))
}

/// Check that the EXR file `bytes` is whole: every chunk its offset tables
/// name lies in the file, its leader fits, names the right part and claims
/// no more bytes than the file has (a file cut short, or one whose writer
/// never filled in a block, fails). Deep parts are not checked.
pub(crate) fn check_chunks(path: &Path, bytes: &[u8]) -> Result<(MetaData, Vec<Vec<u64>>)> {
    let (meta, start, tables) = parse_layout(path, bytes)?;
    let multi = meta.headers.len() > 1;
    let i32_at = |at: usize| {
        bytes
            .get(at..at + 4)
            .map(|b| i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    for (part, (h, table)) in meta.headers.iter().zip(&tables).enumerate() {
        if h.deep {
            continue;
        }
        // Leader: [part] y size (scan lines) or [part] x y lx ly size (tiles).
        let words = match h.blocks {
            exr::meta::BlockDescription::ScanLines => 1,
            exr::meta::BlockDescription::Tiles(_) => 4,
        } + usize::from(multi);
        for (k, &offset) in table.iter().enumerate() {
            let missing = || {
                invalid(
                    path,
                    format!("block {k} of part {part} is missing or cut short"),
                )
            };
            let at = usize::try_from(offset).map_err(|_| missing())?;
            if at < start || at >= bytes.len() {
                return Err(missing());
            }
            if multi && i32_at(at) != Some(part as i32) {
                return Err(missing());
            }
            let size = i32_at(at + 4 * words).ok_or_else(missing)?;
            let end = usize::try_from(size)
                .ok()
                .and_then(|s| (at + 4 * words + 4).checked_add(s))
                .ok_or_else(missing)?;
            if end > bytes.len() {
                return Err(missing());
            }
        }
    }
    Ok((meta, tables))
}

/// A text attribute of a header (the part's own custom attributes).
pub(crate) fn text_attribute(h: &Header, name: &str) -> Option<String> {
    match h
        .own_attributes
        .other
        .get(&exr::meta::attribute::Text::from(name))
    {
        Some(exr::meta::attribute::AttributeValue::Text(t)) => Some(t.to_string()),
        _ => None,
    }
}

/// The headers, checked, of the EXR file `bytes`.
pub(crate) fn parse_headers(path: &Path, bytes: &[u8]) -> Result<MetaData> {
    parse_headers_from(path, &mut PeekRead::new(Tracking::new(bytes)))
}

fn parse_headers_from(path: &Path, read: &mut PeekRead<Tracking<&[u8]>>) -> Result<MetaData> {
    let exr_err = |e| Error::from_exr(path, e, "");
    if !magic_number::is_exr(read).map_err(exr_err)? {
        return Err(invalid(path, "not an OpenEXR file (no EXR magic number)"));
    }
    let requirements =
        Requirements::read(read).map_err(|e| Error::from_exr(path, e, "version field"))?;
    requirements
        .validate()
        .map_err(|e| Error::from_exr(path, e, "version field"))?;
    let headers = Header::read_all(read, &requirements, false)
        .map_err(|e| Error::from_exr(path, e, "header"))?;
    MetaData::validate(&headers, false).map_err(|e| Error::from_exr(path, e, "header"))?;
    Ok(MetaData {
        requirements,
        headers,
    })
}

/// Bytes of one decompressed block of the part `h` (all channels), as its
/// header claims: what a decoder allocates for it.
pub(crate) fn block_bytes(h: &Header) -> u64 {
    let px = match h.blocks {
        exr::meta::BlockDescription::ScanLines => {
            h.layer_size.0 as u64 * h.compression.scan_lines_per_block() as u64
        }
        exr::meta::BlockDescription::Tiles(t) => t.tile_size.0 as u64 * t.tile_size.1 as u64,
    };
    px.saturating_mul(h.channels.bytes_per_pixel as u64)
}

/// One chunk as it lies in the mapped file: its part, the block it holds and
/// its compressed bytes, borrowed (a ZIP or ZIPS block is inflated from the
/// map; other codecs take a copy, [`RawChunk::to_chunk`], as `exr`'s
/// `Chunk::read` made of every block).
pub(crate) struct RawChunk<'a> {
    pub(crate) layer_index: usize,
    block: RawBlock,
    /// Which block of the part it is.
    pub(crate) indices: TileCoordinates,
    /// The compressed bytes.
    pub(crate) data: &'a [u8],
}

/// What a chunk's leader says about its block.
#[derive(Clone, Copy)]
enum RawBlock {
    /// A scan-line block starting at this y (in the data window).
    ScanLine(i32),
    /// A tile.
    Tile,
}

impl RawChunk<'_> {
    /// The owned chunk `exr`'s decoders and writer take (a copy of the bytes).
    pub(crate) fn to_chunk(&self) -> Chunk {
        let compressed_pixels_le = self.data.to_vec();
        Chunk {
            layer_index: self.layer_index,
            compressed_block: match self.block {
                RawBlock::ScanLine(y_coordinate) => {
                    CompressedBlock::ScanLine(exr::block::chunk::CompressedScanLineBlock {
                        y_coordinate,
                        compressed_pixels_le,
                    })
                }
                RawBlock::Tile => CompressedBlock::Tile(exr::block::chunk::CompressedTileBlock {
                    coordinates: self.indices,
                    compressed_pixels_le,
                }),
            },
        }
    }
}

/// Little-endian `i32`s of a chunk's leader, read from a slice.
struct Leader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Leader<'a> {
    fn i32(&mut self) -> Option<i32> {
        let b = self.bytes.get(self.at..self.at + 4)?;
        self.at += 4;
        Some(i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn usize(&mut self) -> Option<usize> {
        self.i32().and_then(|v| usize::try_from(v).ok())
    }

    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let b = self.bytes.get(self.at..self.at.checked_add(n)?)?;
        self.at += n;
        Some(b)
    }
}

/// Read the chunk at `offset` of `bytes` and check that it is the block of
/// part `part` the offset table says (`expected`). Returns it, its bytes
/// borrowed from `bytes`, and the end of its bytes. The leader is parsed as
/// `exr`'s `Chunk::read` does, with the same bounds (a block's bytes at most
/// what the block holds uncompressed, levels below 32).
pub(crate) fn read_chunk<'a>(
    path: &Path,
    bytes: &'a [u8],
    meta: &MetaData,
    part: usize,
    offset: usize,
    expected: TileCoordinates,
) -> Result<(RawChunk<'a>, usize)> {
    let at = |what: &str| invalid(path, format!("chunk at byte {offset}: {what}"));
    if offset >= bytes.len() {
        return Err(invalid(
            path,
            format!("chunk at byte {offset} lies past the end"),
        ));
    }
    let mut r = Leader { bytes, at: offset };
    let truncated = "the file ends inside it";
    let layer_index = if meta.requirements.is_multilayer() {
        let n = r.i32().ok_or_else(|| at(truncated))?;
        usize::try_from(n)
            .ok()
            .filter(|&n| n < meta.headers.len())
            .ok_or_else(|| at(&format!("invalid part number {n}")))?
    } else {
        0
    };
    if layer_index != part {
        return Err(invalid(
            path,
            format!("chunk at byte {offset} belongs to part {layer_index}"),
        ));
    }
    let header = &meta.headers[part];
    if header.deep {
        return Err(unsupported(path, "deep data"));
    }
    let (block, indices) = match header.blocks {
        exr::meta::BlockDescription::ScanLines => {
            let y = r.i32().ok_or_else(|| at(truncated))?;
            let indices = header
                .get_scan_line_block_tile_coordinates(y)
                .map_err(|e| Error::from_exr(path, e, &format!("chunk at byte {offset}")))?;
            (RawBlock::ScanLine(y), indices)
        }
        exr::meta::BlockDescription::Tiles(_) => {
            let mut v = [0usize; 4];
            for x in &mut v {
                *x = r.usize().ok_or_else(|| at("invalid tile coordinates"))?;
            }
            if v[2] > 31 || v[3] > 31 {
                return Err(at("level index exceeding integer maximum"));
            }
            let indices = TileCoordinates {
                tile_index: exr::math::Vec2(v[0], v[1]),
                level_index: exr::math::Vec2(v[2], v[3]),
            };
            (RawBlock::Tile, indices)
        }
    };
    let size = r.usize().ok_or_else(|| at("invalid block size"))?;
    let max = header.max_block_byte_size();
    if size > max {
        return Err(at(&format!(
            "it claims {size} bytes, more than its block holds uncompressed ({max})"
        )));
    }
    let data = r.take(size).ok_or_else(|| at(truncated))?;
    if indices != expected {
        return Err(invalid(
            path,
            format!(
                "chunk at byte {offset} holds block {:?} but the offset table says {:?}",
                indices.tile_index, expected.tile_index
            ),
        ));
    }
    Ok((
        RawChunk {
            layer_index,
            block,
            indices,
            data,
        },
        r.at,
    ))
}

/// Decompress `chunk` (read at `offset`) after checking the sizes it claims;
/// a damaged block gives an error naming it, never a panic or an abort.
pub(crate) fn decode_checked(
    path: &Path,
    meta: &MetaData,
    offset: usize,
    chunk: &RawChunk<'_>,
) -> Result<BlockBytes> {
    let header = &meta.headers[chunk.layer_index];
    let at = |e| Error::from_exr(path, e, &format!("chunk at byte {offset}"));
    let found = chunk.indices;
    // Sizes the chunk claims, before a decoder allocates them (an
    // allocation failure aborts; see `chunk_sizes`).
    let block_size = header
        .get_absolute_block_pixel_coordinates(found)
        .map_err(at)?
        .size;
    super::chunk_sizes::check(
        header.compression,
        &header.channels,
        block_size.0,
        block_size.1,
        chunk.data,
    )
    .map_err(|reason| invalid(path, format!("block at byte {offset}: {reason}")))?;
    // A panic inside a codec becomes an error naming the block.
    IN_DECODER.with(|f| f.set(true));
    let block = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        if cfg!(target_endian = "little")
            && matches!(header.compression, Compression::ZIP1 | Compression::ZIP16)
        {
            decompress_zip_chunk(header, chunk)
        } else {
            UncompressedBlock::decompress_chunk(chunk.to_chunk(), meta, false).map(|b| BlockBytes {
                index: b.index,
                data: b.data,
                split: false,
            })
        }
    }));
    IN_DECODER.with(|f| f.set(false));
    block
        .map_err(|_| {
            invalid(
                path,
                format!("block at byte {offset}: the decoder failed on damaged data"),
            )
        })?
        .map_err(|e| Error::from_exr(path, e, &format!("block at byte {offset}")))
}

/// A decompressed block: where it lies, and its bytes, either in OpenEXR's
/// order (native endian) or, for ZIP, left split as
/// [`super::zip::unpredict`] leaves them.
pub(crate) struct BlockBytes {
    pub(crate) index: exr::block::BlockIndex,
    pub(crate) data: Vec<u8>,
    split: bool,
}

impl BlockBytes {
    /// `dst.len()` samples of type `t` from byte `at` of the block (which
    /// holds them: the caller checked the block's size).
    fn read(&self, t: SampleType, at: usize, dst: &mut [f32]) -> std::result::Result<(), u32> {
        let n = dst.len() * bytes_of(t);
        if !self.split {
            return convert(t, &self.data[at..at + n], dst);
        }
        let mid = self.data.len().div_ceil(2);
        if at % 2 != 0 || self.data.len() % 2 != 0 {
            // Whole samples of 2 or 4 bytes never get here; kept total.
            let bytes: Vec<u8> = (at..at + n)
                .map(|j| super::zip::split_byte(&self.data, j))
                .collect();
            return convert(t, &bytes, dst);
        }
        // Byte `at + 2i` is `lo[i]`, byte `at + 2i + 1` is `hi[i]` (little
        // endian: this path is taken on little-endian machines only).
        let lo = &self.data[at / 2..][..n / 2];
        let hi = &self.data[mid + at / 2..][..n / 2];
        match t {
            SampleType::F16 => {
                for ((d, &a), &b) in dst.iter_mut().zip(lo).zip(hi) {
                    *d = half::f16::from_bits(u16::from_le_bytes([a, b])).to_f32();
                }
            }
            SampleType::F32 => {
                for ((d, a), b) in dst
                    .iter_mut()
                    .zip(lo.chunks_exact(2))
                    .zip(hi.chunks_exact(2))
                {
                    *d = f32::from_le_bytes([a[0], b[0], a[1], b[1]]);
                }
            }
            SampleType::U32 => {
                let mut max = 0;
                for ((d, a), b) in dst
                    .iter_mut()
                    .zip(lo.chunks_exact(2))
                    .zip(hi.chunks_exact(2))
                {
                    let v = u32::from_le_bytes([a[0], b[0], a[1], b[1]]);
                    max = max.max(v);
                    *d = v as f32;
                }
                if max > MAX_EXACT_ID {
                    return Err(max);
                }
            }
        }
        Ok(())
    }
}

/// [`UncompressedBlock::decompress_chunk`] for a ZIP or ZIPS chunk on a
/// little-endian machine, through [`super::zip::unpredict`] (no buffer kept
/// per thread, no second copy of the block): the same block, the same
/// checks.
fn decompress_zip_chunk(header: &Header, chunk: &RawChunk<'_>) -> exr::error::Result<BlockBytes> {
    let indices = chunk.indices;
    let section = header.get_absolute_block_pixel_coordinates(indices)?;
    section.validate(Some(header.layer_size))?;
    let packed = chunk.data;
    let expected = section.size.area() * header.channels.bytes_per_pixel;
    // A block that would not shrink is stored as it is.
    let (data, split) = if packed.len() == expected {
        (packed.to_vec(), false)
    } else {
        let t = super::zip::unpredict(packed, expected).ok_or(exr::error::Error::Invalid(
            "zlib-compressed data malformed".into(),
        ))?;
        (t, true)
    };
    Ok(BlockBytes {
        data,
        split,
        index: exr::block::BlockIndex {
            layer: chunk.layer_index,
            pixel_position: section.position.to_usize("data indices start")?,
            level: indices.level_index,
            pixel_size: section.size,
        },
    })
}

impl ExrInput {
    /// Open and check `path`; `part` chooses a part of a multi-part file.
    /// The colour layer is chosen as [`ExrInput::open_layer`] does without one.
    pub fn open(path: &Path, part: Option<&PartSelect>) -> Result<Self> {
        Self::open_layer(path, part, None)
    }

    /// Open and check `path`; `part` chooses a part of a multi-part file and
    /// `layer` the layer whose R, G, B (or Y) channels are filtered (e.g.
    /// `ViewLayer.Combined`; by default the unlayered channels, else a layer
    /// named as the beauty, else the only layer with colour).
    pub fn open_layer(path: &Path, part: Option<&PartSelect>, layer: Option<&str>) -> Result<Self> {
        Self::open_view(path, part, layer, None)
    }

    /// [`ExrInput::open_layer`] of one view of a multi-view file: its
    /// colour channels are `layer.view.R` (`view.R` without a layer; the
    /// default view's are named as without views).
    pub fn open_view(
        path: &Path,
        part: Option<&PartSelect>,
        layer: Option<&str>,
        view: Option<&str>,
    ) -> Result<Self> {
        let map = MappedFile::open(path)?;
        if super::rgbe::is_rgbe(map.bytes()) {
            if let Some(v) = view {
                return Err(Error::Config(format!(
                    "{}: a Radiance picture has no views (--view {v:?})",
                    path.display()
                )));
            }
            return Self::open_rgbe(path, map, part, layer);
        }
        let bytes = map.bytes();
        let mut read = PeekRead::new(Tracking::new(bytes));
        let meta = parse_headers_from(path, &mut read)?;

        // Choose the part before reading offset tables (their size is checked).
        let part = match (part, meta.headers.len()) {
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
        };
        // Offset tables: their total size must fit in the file.
        let (tables, chunks_start) = read_tables(path, bytes, &mut read, &meta)?;
        let header = &meta.headers[part];
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
        let scope = view_scope(path, header, view, false)?;
        let view_layer = match (scope.name(), layer) {
            (Some(v), l) if scope.this > 0 => Some(match l {
                Some(l) => format!("{}.{v}", l.trim_end_matches('.')),
                None => v.to_string(),
            }),
            _ => layer.map(str::to_string),
        };
        let (selected, dropped) = choose_channels(path, header, view_layer.as_deref())?;

        // Level-0 block rows in increasing y, with checked offsets.
        let table = &tables[part];
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
            if offset < chunks_start || offset >= bytes.len() {
                return Err(invalid(
                    path,
                    format!("offset table entry {index} points to byte {offset}, outside the pixel data"),
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
        let input = ExrInput {
            path: path.into(),
            map,
            meta,
            part,
            selected,
            rows,
            dropped,
            aux: 0,
            carried: Vec::new(),
            rgbe: None,
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

    /// A Radiance picture, described as a single-part file of three f32
    /// channels (R, G, B, or X, Y, Z for XYZE) with the picture's primaries.
    fn open_rgbe(
        path: &Path,
        map: MappedFile,
        part: Option<&PartSelect>,
        layer: Option<&str>,
    ) -> Result<Self> {
        use exr::math::Vec2;
        use exr::meta::attribute::{ChannelDescription, ChannelList, Chromaticities, Text};
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
        let rh = super::rgbe::parse_header(path, map.bytes())?;
        let names: [&str; 3] = if rh.xyze {
            ["X", "Y", "Z"]
        } else {
            ["R", "G", "B"]
        };
        let mut sorted = names;
        sorted.sort_unstable();
        let list: exr::prelude::SmallVec<[ChannelDescription; 5]> = sorted
            .iter()
            .map(|n| ChannelDescription::new(Text::from(*n), SampleType::F32, false))
            .collect();
        let mut header = Header::new(Text::from(""), Vec2(rh.w, rh.h), list).with_encoding(
            Compression::ZIP16,
            exr::meta::BlockDescription::ScanLines,
            exr::meta::attribute::LineOrder::Increasing,
        );
        header.channels = ChannelList::new(header.channels.list.clone());
        header.own_attributes.layer_name = None;
        if let Some(p) = rh.primaries {
            let v = |i: usize| Vec2(p[i] as f32, p[i + 1] as f32);
            header.shared_attributes.chromaticities = Some(Chromaticities {
                red: v(0),
                green: v(2),
                blue: v(4),
                white: v(6),
            });
        }
        let selected = names
            .iter()
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
        Ok(ExrInput {
            path: path.into(),
            map,
            meta,
            part: 0,
            selected,
            rows: Vec::new(),
            dropped: Vec::new(),
            aux: 0,
            carried: Vec::new(),
            rgbe: Some(rh),
        })
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
        self.header()
            .channels
            .list
            .iter()
            .map(|c| c.name.to_string())
            .collect()
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

    /// Read, check and decompress one chunk of `lines` lines into `place`.
    /// Returns (first column, width, consumed byte range).
    fn decode_chunk(
        &self,
        offset: usize,
        expected: TileCoordinates,
        lines: usize,
        place: Place<'_>,
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

/// Ids up to this are exact in f32 (2^24); a uint channel holding more is
/// refused rather than carried wrong.
pub const MAX_EXACT_ID: u32 = 1 << 24;

/// Decode samples of type `t` into f32; `Err(v)`: a uint sample `v` above
/// [`MAX_EXACT_ID`].
fn convert(t: SampleType, src: &[u8], dst: &mut [f32]) -> std::result::Result<(), u32> {
    match t {
        SampleType::F16 => {
            for (d, b) in dst.iter_mut().zip(src.chunks_exact(2)) {
                *d = half::f16::from_bits(u16::from_ne_bytes([b[0], b[1]])).to_f32();
            }
        }
        SampleType::F32 => {
            for (d, b) in dst.iter_mut().zip(src.chunks_exact(4)) {
                *d = f32::from_ne_bytes([b[0], b[1], b[2], b[3]]);
            }
        }
        SampleType::U32 => {
            let mut max = 0;
            for (d, b) in dst.iter_mut().zip(src.chunks_exact(4)) {
                let v = u32::from_ne_bytes([b[0], b[1], b[2], b[3]]);
                max = max.max(v);
                *d = v as f32;
            }
            if max > MAX_EXACT_ID {
                return Err(max);
            }
        }
    }
    Ok(())
}

/// The views of a multi-view file (`multiView`), the default first; empty
/// for a file without views.
pub(crate) fn views(header: &Header) -> Vec<String> {
    header
        .own_attributes
        .multi_view_names
        .iter()
        .flatten()
        .map(|t| t.to_string())
        .collect()
}

/// Which view of a multi-view file to filter (`--view`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ViewSelect {
    /// One view, by name.
    Name(String),
    /// Every view, each filtered as its own image, into one output.
    All,
}

impl ViewSelect {
    /// Parse `--view`: `all`, or a view's name.
    pub fn parse(s: &str) -> Self {
        match s {
            "all" => ViewSelect::All,
            name => ViewSelect::Name(name.to_string()),
        }
    }
}

/// The view a run of `header`'s part writes: `view` by name, or the
/// default; an unknown name is refused with the file's views.
pub fn view_scope(
    path: &Path,
    header: &Header,
    view: Option<&str>,
    exclusive: bool,
) -> Result<crate::filter::channels::ViewScope> {
    let views = views(header);
    let this = match view {
        None => 0,
        Some(v) => views.iter().position(|n| n == v).ok_or_else(|| {
            Error::Config(format!(
                "{}: --view {v:?}: {}",
                path.display(),
                if views.is_empty() {
                    "the file has no views (no multiView attribute)".to_string()
                } else {
                    format!("its views are {}", views.join(", "))
                }
            ))
        })?,
    };
    Ok(crate::filter::channels::ViewScope {
        views,
        this,
        exclusive,
    })
}

pub(crate) fn base_name(name: &str) -> &str {
    name.rsplit('.').next().unwrap_or(name)
}

/// Layer names (last dot-component, any case) that renderers give the beauty
/// image: Blender's `ViewLayer.Combined`, `beauty`/`RGBA` (Arnold, Houdini),
/// RenderMan's `Ci`, and the generic ones.
const BEAUTY_LAYERS: &[&str] = &[
    "combined",
    "beauty",
    "rgba",
    "rgb",
    "ci",
    "color",
    "colour",
    "composite",
    "image",
];

/// The colour channels of `layer` ("" or ending in '.'): R, G, B (+ A), or
/// Y (+ A); `None` when it has neither.
fn layer_colour(names: &[String], layer: &str) -> Option<Vec<&'static str>> {
    let has = |c: &str| names.iter().any(|n| *n == format!("{layer}{c}"));
    // In a named layer, Y beside an X is a vector's component (normals
    // `N.X N.Y N.Z`, motion `vel.X vel.Y`), not a luminance.
    let vector = !layer.is_empty() && has("X");
    let mut wanted = if has("R") && has("G") && has("B") {
        vec!["R", "G", "B"]
    } else if has("Y") && !vector {
        vec!["Y"]
    } else {
        return None;
    };
    if has("A") {
        wanted.push("A");
    }
    Some(wanted)
}

/// The channels to filter: R, G, B (+ A), or Y (+ A) of one layer, and the
/// rest (dropped, and listed). The layer is `layer` when given; otherwise the
/// unlayered channels, else a layer with a beauty name ([`BEAUTY_LAYERS`]),
/// else the only layer with colour; several candidates and no beauty is an
/// error that lists them (filtering an AOV by mistake would be silent).
pub(crate) fn choose_channels(
    path: &Path,
    header: &Header,
    layer: Option<&str>,
) -> Result<(Vec<Selected>, Vec<String>)> {
    let names: Vec<String> = header
        .channels
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    let mut layers: Vec<String> = vec![String::new()];
    for n in &names {
        if let Some((l, _)) = n.rsplit_once('.') {
            let l = format!("{l}.");
            if !layers.contains(&l) {
                layers.push(l);
            }
        }
    }
    let coloured: Vec<(&String, Vec<&str>)> = layers
        .iter()
        .filter_map(|l| layer_colour(&names, l).map(|c| (l, c)))
        .collect();
    if coloured.is_empty() {
        return Err(unsupported(
            path,
            format!(
                "no colour channels to filter (need R,G,B or Y; the file has: {})",
                names.join(", ")
            ),
        ));
    }
    let shown = |l: &str| {
        if l.is_empty() {
            "(unlayered)".to_string()
        } else {
            l.trim_end_matches('.').to_string()
        }
    };
    let list = || {
        coloured
            .iter()
            .map(|(l, _)| shown(l))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let chosen = if let Some(want) = layer {
        let want = want.trim_end_matches('.');
        let key = if want.is_empty() {
            String::new()
        } else {
            format!("{want}.")
        };
        match coloured.iter().find(|(l, _)| **l == key) {
            Some(c) => c,
            None => {
                return Err(Error::Config(format!(
                    "{}: --layer {want:?} has no R,G,B or Y channels (layers with colour: {})",
                    path.display(),
                    list()
                )))
            }
        }
    } else {
        let beauty = |l: &str| {
            let last = l.trim_end_matches('.').rsplit('.').next().unwrap_or("");
            BEAUTY_LAYERS.iter().any(|b| last.eq_ignore_ascii_case(b))
        };
        match coloured
            .iter()
            .find(|(l, _)| l.is_empty())
            .or_else(|| coloured.iter().find(|(l, _)| beauty(l)))
        {
            Some(c) => c,
            None => match coloured.as_slice() {
                [only] => only,
                _ => {
                    return Err(Error::Config(format!(
                        "{}: several layers have colour and none is named as the beauty ({}): choose one with --layer NAME",
                        path.display(),
                        list()
                    )))
                }
            },
        }
    };
    let (layer, wanted) = chosen;
    if wanted[0] == "Y" {
        let has = |c: &str| names.iter().any(|n| *n == format!("{layer}{c}"));
        if has("RY") && has("BY") {
            return Err(unsupported(
                path,
                "luminance/chroma (Y, RY, BY) images are not supported",
            ));
        }
    }
    let selected: Vec<Selected> = wanted
        .iter()
        .map(|c| {
            let name = format!("{layer}{c}");
            Selected {
                index: names.iter().position(|x| *x == name).unwrap_or(0),
                name,
            }
        })
        .collect();
    let dropped = names
        .iter()
        .filter(|n| !selected.iter().any(|s| &s.name == *n))
        .cloned()
        .collect();
    Ok((selected, dropped))
}

/// Decoded bytes the reader asks for at once at most (beyond one strip's
/// rows): enough chunks to keep the workers busy at ordinary widths, few
/// enough that memory does not grow with the thread count at 32k.
pub const READ_AHEAD_BYTES: u64 = 24 << 20;

/// A [`Source`] over an [`ExrInput`].
pub struct ExrSource<'a> {
    input: &'a ExrInput,
    next_row: usize,
    /// Decoded rows; those before `head` (values) are handed over.
    buf: Vec<f32>,
    head: usize,
    buf_y0: usize,
    row_len: usize,
    /// Byte range of the file consumed (and released) so far.
    released: Option<(usize, usize)>,
}

/// Rows of an input file, whatever its format.
pub enum InputSource<'a> {
    /// OpenEXR blocks.
    Exr(ExrSource<'a>),
    /// Radiance scanlines.
    Rgbe(super::rgbe::RgbeSource<'a>),
}

impl Source for InputSource<'_> {
    fn next_strip(&mut self, max_rows: usize) -> Result<Option<Strip>> {
        match self {
            InputSource::Exr(s) => s.next_strip(max_rows),
            InputSource::Rgbe(s) => s.next_strip(max_rows),
        }
    }
}

impl Source for ExrSource<'_> {
    fn next_strip(&mut self, max_rows: usize) -> Result<Option<Strip>> {
        let (w, h) = self.input.size();
        let nch = self.input.selected.len();
        let buffered = |s: &Self| (s.buf.len() - s.head) / s.row_len;
        // Decode whole block rows until the strip is covered; two chunks per
        // worker at a time so small blocks still decode in parallel, but no
        // more than READ_AHEAD_BYTES of decoded blocks: wide blocks (6 MB at
        // 32k float RGB) times many workers would make memory grow with the
        // thread count.
        let by_bytes = (READ_AHEAD_BYTES / self.input.block_bytes().max(1)).max(2) as usize;
        // A batch is decoded only once the last is handed over (its last
        // strip may be short): the buffer is then reused as it is, never
        // moved or grown around rows still held.
        while buffered(self) == 0 && self.next_row < self.input.rows.len() {
            let want_chunks = (2 * rayon::current_num_threads()).min(by_bytes);
            let mut end = self.next_row;
            let mut chunks = 0;
            let mut rows = 0;
            while end < self.input.rows.len()
                && (chunks < want_chunks || buffered(self) + rows < max_rows)
            {
                chunks += self.input.rows[end].chunks.len();
                rows += self.input.rows[end].y1 - self.input.rows[end].y0;
                end += 1;
            }
            let batch = &self.input.rows[self.next_row..end];
            let total: usize = batch.iter().map(|r| r.y1 - r.y0).sum();
            // Every value of the batch is written by its blocks (they cover
            // its rows, as the offset table was checked to say), so the
            // buffer keeps its old values rather than being cleared (a pass
            // over the whole image, on the reader's critical path). It grows
            // exactly: doubling would hold up to twice the read-ahead.
            let len = total * self.row_len;
            self.head = 0;
            self.buf.truncate(len);
            self.buf.reserve_exact(len - self.buf.len());
            self.buf.resize(len, 0.0);
            let mut span = (usize::MAX, 0usize);
            if batch.iter().all(|r| r.chunks.len() == 1) {
                // Scan lines: each block decodes straight into its rows.
                let mut slices = Vec::with_capacity(batch.len());
                let mut rest = &mut self.buf[..];
                for r in batch {
                    let (head, tail) = rest.split_at_mut((r.y1 - r.y0) * self.row_len);
                    slices.push(head);
                    rest = tail;
                }
                let input = self.input;
                let spans: Vec<Result<Landed>> = batch
                    .par_iter()
                    .zip(slices.into_par_iter())
                    .map(|(r, dst)| {
                        let (offset, expected) = r.chunks[0];
                        input.decode_chunk(
                            offset,
                            expected,
                            r.y1 - r.y0,
                            Place::InPlace { dst, width: w },
                        )
                    })
                    .collect();
                for sp in spans {
                    let (a, b) = sp?.bytes;
                    span = (span.0.min(a), span.1.max(b));
                }
            } else {
                // Tiles: decode each into its own buffer, then place it.
                let decoded: Vec<Result<Vec<Decoded>>> =
                    batch.par_iter().map(|r| self.input.decode_row(r)).collect();
                let mut row_base = 0;
                for (row, blocks) in batch.iter().zip(decoded) {
                    let lines = row.y1 - row.y0;
                    for Decoded {
                        x0,
                        width: bw,
                        rows: data,
                        bytes: (a, b),
                    } in blocks?
                    {
                        span = (span.0.min(a), span.1.max(b));
                        if x0 + bw > w {
                            return Err(invalid(
                                &self.input.path,
                                "a block lies outside the data window",
                            ));
                        }
                        for line in 0..lines {
                            for k in 0..nch {
                                let src = &data[(line * nch + k) * bw..][..bw];
                                let at = row_base + line * self.row_len + k * w + x0;
                                self.buf[at..at + bw].copy_from_slice(src);
                            }
                        }
                    }
                    row_base += lines * self.row_len;
                }
            }
            if span.0 < span.1 {
                // Grow the released region contiguously, so the pages that
                // straddle two batches are dropped too.
                let (lo, hi) = match self.released {
                    None => span,
                    Some((lo, hi)) => (lo.min(span.0), hi.max(span.1)),
                };
                let from = match self.released {
                    Some((plo, phi)) if span.0 >= plo => (phi.min(span.0)).saturating_sub(4096),
                    _ => lo,
                };
                let to = match self.released {
                    Some((plo, _)) if span.0 < plo => (plo + 4096).min(hi),
                    _ => hi,
                };
                self.input.map.release(from, to);
                self.released = Some((lo, hi));
            }
            self.next_row = end;
        }
        let n = max_rows.min(buffered(self));
        if n == 0 {
            return if self.buf_y0 >= h {
                Ok(None)
            } else {
                Err(invalid(&self.input.path, "missing rows"))
            };
        }
        // Hand over a copy of the front rows, exactly as large as they are
        // (handing over the buffer itself would send its whole read-ahead
        // capacity down the pipeline with every strip, and draining it would
        // move the rest at every strip).
        let k = n * self.row_len;
        let data = self.buf[self.head..self.head + k].to_vec();
        self.head += k;
        let strip = Strip {
            y0: self.buf_y0,
            rows: n,
            data,
        };
        self.buf_y0 += n;
        Ok(Some(strip))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    /// `exr`'s own reading of a chunk, with the checks `read_chunk` makes:
    /// what the borrowed reader must agree with.
    fn exr_read_chunk(
        bytes: &[u8],
        meta: &MetaData,
        part: usize,
        offset: usize,
        expected: TileCoordinates,
    ) -> Option<(Chunk, usize)> {
        let mut slice = bytes.get(offset..)?;
        let chunk = Chunk::read(&mut slice, meta).ok()?;
        let end = bytes.len() - slice.len();
        let found = meta.headers[chunk.layer_index]
            .get_block_data_indices(&chunk.compressed_block)
            .ok()?;
        (chunk.layer_index == part && found == expected).then_some((chunk, end))
    }

    /// What a flat chunk holds (`Chunk` has no `PartialEq`).
    fn key(c: &Chunk) -> (usize, Option<i32>, Option<TileCoordinates>, &[u8]) {
        match &c.compressed_block {
            CompressedBlock::ScanLine(b) => (
                c.layer_index,
                Some(b.y_coordinate),
                None,
                &b.compressed_pixels_le,
            ),
            CompressedBlock::Tile(t) => (
                c.layer_index,
                None,
                Some(t.coordinates),
                &t.compressed_pixels_le,
            ),
            _ => unreachable!("deep parts are skipped"),
        }
    }

    #[test]
    fn borrowed_chunks_are_the_chunks_exr_reads() {
        // Every block of every flat part of the repository's files, damaged
        // ones included, and every block's leader cut short or with a
        // corrupted size: the same chunk and end, or an error for both.
        let mut files = Vec::new();
        let mut dirs = vec![std::path::PathBuf::from("tests/data/exr")];
        while let Some(d) = dirs.pop() {
            for e in std::fs::read_dir(&d).unwrap().flatten() {
                let p = e.path();
                if p.is_dir() {
                    dirs.push(p);
                } else if p.extension().is_some_and(|x| x == "exr") || d.ends_with("Damaged") {
                    files.push(p);
                }
            }
        }
        files.sort();
        let (mut blocks, mut agreed_errors) = (0, 0);
        for path in &files {
            let bytes = std::fs::read(path).unwrap();
            let Ok((meta, tables, _)) = parse_meta(path, &bytes) else {
                continue;
            };
            for (part, header) in meta.headers.iter().enumerate() {
                if header.deep {
                    continue;
                }
                for (index, tile) in header.blocks_increasing_y_order().enumerate() {
                    let Some(&offset) = tables[part].get(index) else {
                        continue;
                    };
                    let offset = offset as usize;
                    let mut variants = vec![bytes.clone()];
                    // Cut inside the leader and inside the data.
                    for cut in [offset + 2, offset + 6, offset + 9, offset + 40] {
                        if cut < bytes.len() {
                            variants.push(bytes[..cut].to_vec());
                        }
                    }
                    // A size field of -1 and of i32::MAX where a scan-line
                    // block (4 bytes on) or a tile (16 bytes on) keeps it.
                    let skip = if meta.requirements.is_multilayer() {
                        4
                    } else {
                        0
                    };
                    for field in [4, 16] {
                        for v in [-1i32, i32::MAX] {
                            let at = offset + skip + field;
                            if at + 4 <= bytes.len() {
                                let mut b = bytes.clone();
                                b[at..at + 4].copy_from_slice(&v.to_le_bytes());
                                variants.push(b);
                            }
                        }
                    }
                    for b in &variants {
                        let ours = read_chunk(path, b, &meta, part, offset, tile.location).ok();
                        let theirs = exr_read_chunk(b, &meta, part, offset, tile.location);
                        match (ours, theirs) {
                            (Some((c, end)), Some((d, e))) => {
                                assert!(
                                    key(&c.to_chunk()) == key(&d) && end == e,
                                    "{path:?} block {index}"
                                );
                                blocks += 1;
                            }
                            (None, None) => agreed_errors += 1,
                            (o, t) => panic!(
                                "{path:?} part {part} block {index}: ours {}, exr's {}",
                                o.is_some(),
                                t.is_some()
                            ),
                        }
                    }
                }
            }
        }
        assert!(
            blocks > 1000 && agreed_errors > 1000,
            "{blocks} {agreed_errors}"
        );
    }

    #[test]
    fn a_vector_layer_is_not_a_luminance() {
        let n = names(&[
            "Y", "N.X", "N.Y", "N.Z", "vel.X", "vel.Y", "grey.Y", "grey.A",
        ]);
        assert_eq!(layer_colour(&n, ""), Some(vec!["Y"]));
        assert_eq!(layer_colour(&n, "N."), None);
        assert_eq!(layer_colour(&n, "vel."), None);
        assert_eq!(layer_colour(&n, "grey."), Some(vec!["Y", "A"]));
        // Unlayered X, Y, Z (a Radiance XYZE picture's) keep their Y.
        assert_eq!(layer_colour(&names(&["X", "Y", "Z"]), ""), Some(vec!["Y"]));
    }
}
