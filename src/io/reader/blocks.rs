//! Blocks of an EXR: the headers and offset tables parsed from the memory
//! map, each chunk read from its offset and checked against where it should
//! be, decompressed (ZIP by our own decoder, the rest by the `exr` crate) and
//! converted to f32.

use super::magic_number;
use super::{
    Chunk, CompressedBlock, Error, Header, MetaData, Path, PeekRead, Requirements, SampleType,
    TileCoordinates, Tracking, UncompressedBlock, IN_DECODER,
};
use crate::error::Result;

pub(super) fn invalid(path: &Path, reason: impl Into<String>) -> Error {
    Error::InvalidFile {
        path: path.into(),
        reason: reason.into(),
    }
}

pub(super) fn unsupported(path: &Path, reason: impl Into<String>) -> Error {
    Error::Unsupported {
        path: path.into(),
        reason: reason.into(),
    }
}

pub(super) fn bytes_of(t: SampleType) -> usize {
    match t {
        SampleType::F16 => 2,
        SampleType::F32 | SampleType::U32 => 4,
    }
}

pub(super) fn part_name(h: &Header) -> String {
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
pub(super) fn read_tables(
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
fn parse_layout(path: &Path, bytes: &[u8]) -> Result<(MetaData, usize, Vec<Vec<u64>>)> {
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

/// The names of a header's channels, in the header's (sorted) order.
pub(crate) fn channel_names(h: &Header) -> Vec<String> {
    h.channels.list.iter().map(|c| c.name.to_string()).collect()
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

pub(super) fn parse_headers_from(
    path: &Path,
    read: &mut PeekRead<Tracking<&[u8]>>,
) -> Result<MetaData> {
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

/// The largest gap from one of `offsets` (a part's chunks) to the next, or
/// to `end` (the file's length) from the last: at least what any of those
/// chunks takes in the file (other parts' chunks between count too). `None`
/// where there are none.
pub(super) fn largest_chunk(offsets: impl Iterator<Item = usize>, end: usize) -> Option<u64> {
    let mut offsets: Vec<usize> = offsets.collect();
    offsets.sort_unstable();
    let last = offsets.last().map(|&o| end.saturating_sub(o));
    let gaps = offsets.windows(2).map(|p| p[1] - p[0]);
    gaps.chain(last).max().map(|g| g as u64)
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
pub(super) enum RawBlock {
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
pub(super) struct Leader<'a> {
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
    guarded(path, meta, offset, chunk, |header| {
        if crate::io::zip::codes(header.compression) {
            decompress_zip_chunk(header, chunk)
        } else {
            UncompressedBlock::decompress_chunk(chunk.to_chunk(), meta, false).map(|b| BlockBytes {
                index: b.index,
                data: b.data,
                split: false,
            })
        }
    })
}

/// A ZIP or ZIPS chunk (read at `offset`) decoded straight into `dst`, with
/// the checks of [`decode_checked`]: the block's bytes in the file's order
/// (its lines, each the header's channels in turn), on a little-endian
/// machine; `Ok(None)` (nothing written) where the chunk is of another codec
/// or `dst` is not its size.
pub(crate) fn decode_zip_into(
    path: &Path,
    meta: &MetaData,
    offset: usize,
    chunk: &RawChunk<'_>,
    dst: &mut [u8],
) -> Result<Option<exr::block::BlockIndex>> {
    let header = &meta.headers[chunk.layer_index];
    if !crate::io::zip::codes(header.compression) {
        return Ok(None);
    }
    let at = |e| Error::from_exr(path, e, &format!("chunk at byte {offset}"));
    let section = header
        .get_absolute_block_pixel_coordinates(chunk.indices)
        .map_err(at)?;
    if section
        .size
        .area()
        .checked_mul(header.channels.bytes_per_pixel)
        != Some(dst.len())
    {
        return Ok(None);
    }
    guarded(path, meta, offset, chunk, |header| {
        let section = header.get_absolute_block_pixel_coordinates(chunk.indices)?;
        section.validate(Some(header.layer_size))?;
        let packed = chunk.data;
        // A block that would not shrink is stored as it is.
        if packed.len() == dst.len() {
            dst.copy_from_slice(packed);
        } else if !crate::io::zip::decode_into(packed, dst) {
            return Err(exr::error::Error::Invalid(
                "zlib-compressed data malformed".into(),
            ));
        }
        Ok(Some(exr::block::BlockIndex {
            layer: chunk.layer_index,
            pixel_position: section.position.to_usize("data indices start")?,
            level: chunk.indices.level_index,
            pixel_size: section.size,
        }))
    })
}

/// Put the planes of `line` (each `w` values), in the file's channel order,
/// in the order of `order` (the file's channel index of each plane wanted):
/// swapped in place, each plane moved once at most.
pub(super) fn reorder_planes(line: &mut [f32], w: usize, order: &[usize]) {
    // `at[p]`: the file channel now at plane `p`; `pos[c]`: where channel
    // `c` is now.
    let mut at: Vec<usize> = (0..order.len()).collect();
    let mut pos = at.clone();
    for (k, &c) in order.iter().enumerate() {
        let p = pos[c];
        if p != k {
            let (head, tail) = line.split_at_mut(p * w);
            head[k * w..(k + 1) * w].swap_with_slice(&mut tail[..w]);
            let moved = at[k];
            (at[p], pos[moved]) = (moved, p);
            (at[k], pos[c]) = (c, k);
        }
    }
}

/// Run `decode` on `chunk` (read at `offset`) after checking the sizes it
/// claims, before a decoder allocates them; a panic inside the codec becomes
/// an error naming the block.
fn guarded<T>(
    path: &Path,
    meta: &MetaData,
    offset: usize,
    chunk: &RawChunk<'_>,
    decode: impl FnOnce(&Header) -> exr::error::Result<T>,
) -> Result<T> {
    let header = &meta.headers[chunk.layer_index];
    let at = |e| Error::from_exr(path, e, &format!("chunk at byte {offset}"));
    let found = chunk.indices;
    // Sizes the chunk claims, before a decoder allocates them (an
    // allocation failure aborts; see `chunk_sizes`).
    let block_size = header
        .get_absolute_block_pixel_coordinates(found)
        .map_err(at)?
        .size;
    crate::io::chunk_sizes::check(
        header.compression,
        &header.channels,
        block_size.0,
        block_size.1,
        chunk.data,
    )
    .map_err(|reason| invalid(path, format!("block at byte {offset}: {reason}")))?;
    IN_DECODER.with(|f| f.set(true));
    let block = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| decode(header)));
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
/// [`crate::io::zip::unpredict`] leaves them.
pub(crate) struct BlockBytes {
    pub(crate) index: exr::block::BlockIndex,
    pub(crate) data: Vec<u8>,
    split: bool,
}

impl BlockBytes {
    /// `dst.len()` samples of type `t` from byte `at` of the block (which
    /// holds them: the caller checked the block's size).
    pub(super) fn read(
        &self,
        t: SampleType,
        at: usize,
        dst: &mut [f32],
    ) -> std::result::Result<(), u32> {
        let n = dst.len() * bytes_of(t);
        if !self.split {
            return convert(t, &self.data[at..at + n], dst);
        }
        let mid = self.data.len().div_ceil(2);
        if at % 2 != 0 || self.data.len() % 2 != 0 {
            // Whole samples of 2 or 4 bytes never get here; kept total.
            let bytes: Vec<u8> = (at..at + n)
                .map(|j| crate::io::zip::split_byte(&self.data, j))
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
/// little-endian machine, through [`crate::io::zip::unpredict`] (no buffer kept
/// per thread, no second copy of the block): the same block, the same
/// checks.
pub(super) fn decompress_zip_chunk(
    header: &Header,
    chunk: &RawChunk<'_>,
) -> exr::error::Result<BlockBytes> {
    let indices = chunk.indices;
    let section = header.get_absolute_block_pixel_coordinates(indices)?;
    section.validate(Some(header.layer_size))?;
    let packed = chunk.data;
    let expected = section.size.area() * header.channels.bytes_per_pixel;
    // A block that would not shrink is stored as it is.
    let (data, split) = if packed.len() == expected {
        (packed.to_vec(), false)
    } else {
        let t = crate::io::zip::unpredict(packed, expected).ok_or(exr::error::Error::Invalid(
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

/// Ids up to this are exact in f32 (2^24); a uint channel holding more is
/// refused rather than carried wrong.
pub const MAX_EXACT_ID: u32 = 1 << 24;

/// Decode samples of type `t` into f32; `Err(v)`: a uint sample `v` above
/// [`MAX_EXACT_ID`].
pub(super) fn convert(t: SampleType, src: &[u8], dst: &mut [f32]) -> std::result::Result<(), u32> {
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
