//! Multi-part files: the parts a file holds, and an output assembled from
//! parts of several files with each part's chunks copied as they are.
//!
//! A part epfilt does not filter goes through bit for bit: its header (named
//! as in the input) and its compressed chunks are copied, each chunk checked
//! first (read where the offset table says, of the block it should hold, and
//! decoded) so that a damaged input gives an error, not a damaged output.
//! Parts of deep data, which the `exr` crate cannot write, are left out.

use std::io::BufWriter;
use std::path::{Path, PathBuf};

use exr::block::chunk::Chunk;
use exr::block::writer::ChunksWriter;
use exr::meta::header::Header;
use exr::meta::MetaData;
use exr::prelude::{SmallVec, Text};
use rayon::iter::{IntoParallelRefIterator, ParallelIterator};

use super::mapped::MappedFile;
use super::reader::{block_bytes, decode_checked, parse_meta, read_chunk};
use crate::error::{Error, Result};

/// One part of a file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PartInfo {
    /// Its index in the file.
    pub index: usize,
    /// Its `name` attribute (empty in a single-part file without one).
    pub name: String,
    /// Deep data (deep scan lines or deep tiles).
    pub deep: bool,
}

/// Part `part` of the file `path`, to be part of an assembled output under
/// the name `name`.
#[derive(Clone, Debug)]
pub struct PartSource {
    /// The file.
    pub path: PathBuf,
    /// Its part.
    pub part: usize,
    /// The part's name in the output.
    pub name: String,
}

struct Opened {
    path: PathBuf,
    map: MappedFile,
    meta: MetaData,
    tables: Vec<Vec<u64>>,
}

/// Chunks checked (decoded) at a time, in parallel, at most.
const CHECK_BATCH: usize = 64;

/// Decoded bytes a batch of checks may hold: fewer chunks at a time where
/// the blocks are large.
const CHECK_BYTES: u64 = 64 << 20;

/// Write `dest` (through a temporary file beside it) as a multi-part file
/// of `sources`, in that order, each part's chunks copied. Returns the
/// compressed bytes copied.
/// (Long: headers, offset tables and chunks go through one call of the `exr`
/// crate's block writer, whose closure holds the state the steps share.)
pub fn assemble(dest: &Path, sources: &[PartSource]) -> Result<u64> {
    let (opened, which) = open_sources(sources)?;
    let headers: SmallVec<[Header; 3]> = sources
        .iter()
        .zip(&which)
        .map(|(src, &k)| {
            let mut h = opened[k].meta.headers[src.part].clone();
            h.own_attributes.layer_name = Some(Text::from(src.name.as_str()));
            h
        })
        .collect();
    let staged = super::Staged::new(dest, ".exr.tmp")?;
    let file = staged
        .file()
        .try_clone()
        .map_err(|e| Error::io(staged.path(), e))?;
    let mut failure: Option<Error> = None;
    let mut copied = 0u64;
    let written = exr::block::write(
        BufWriter::with_capacity(1 << 20, file),
        headers,
        false,
        |_meta, writer| {
            for (out_part, (src, &k)) in sources.iter().zip(&which).enumerate() {
                let o = &opened[k];
                let header = &o.meta.headers[src.part];
                let blocks: Vec<_> = header.blocks_increasing_y_order().enumerate().collect();
                let per_batch =
                    (CHECK_BYTES / block_bytes(header).max(1)).clamp(1, CHECK_BATCH as u64);
                for batch in blocks.chunks(per_batch as usize) {
                    let checked: Result<Vec<(usize, Chunk)>> = batch
                        .par_iter()
                        .map(|&(index, tile)| {
                            let offset = o.tables[src.part]
                                .get(index)
                                .and_then(|&v| usize::try_from(v).ok())
                                .ok_or_else(|| Error::InvalidFile {
                                    path: o.path.clone(),
                                    reason: format!(
                                        "part {}: offset table is shorter than the image",
                                        src.part
                                    ),
                                })?;
                            let (chunk, _) = read_chunk(
                                &o.path,
                                o.map.bytes(),
                                &o.meta,
                                src.part,
                                offset,
                                tile.location,
                            )?;
                            decode_checked(&o.path, &o.meta, offset, &chunk)?;
                            Ok((index, chunk.to_chunk()))
                        })
                        .collect();
                    let checked = match checked {
                        Ok(c) => c,
                        Err(e) => {
                            failure = Some(e);
                            return Err(exr::error::Error::Aborted);
                        }
                    };
                    for (index, mut chunk) in checked {
                        copied += chunk_bytes(&chunk);
                        chunk.layer_index = out_part;
                        writer.write_chunk(index, chunk)?;
                    }
                }
            }
            Ok(())
        },
    );
    if let Some(e) = failure {
        return Err(e);
    }
    written.map_err(|e| Error::from_exr(dest, e, "writing the parts"))?;
    super::headers::sort_header_attributes(staged.file(), None).map_err(|e| Error::Output {
        path: dest.into(),
        reason: format!("putting the headers in order: {e}"),
    })?;
    staged.file().sync_all().ok();
    staged.commit()?;
    Ok(copied)
}

/// Each distinct file of `sources` opened once, and which of them each
/// source reads: its part checked to exist, to be flat, and to claim blocks
/// a decoder may allocate.
fn open_sources(sources: &[PartSource]) -> Result<(Vec<Opened>, Vec<usize>)> {
    let mut opened: Vec<Opened> = Vec::new();
    let mut which = Vec::with_capacity(sources.len());
    for src in sources {
        let k = match opened.iter().position(|o| o.path == src.path) {
            Some(k) => k,
            None => {
                let map = MappedFile::open(&src.path)?;
                let (meta, tables, _) = parse_meta(&src.path, map.bytes())?;
                opened.push(Opened {
                    path: src.path.clone(),
                    map,
                    meta,
                    tables,
                });
                opened.len() - 1
            }
        };
        let o = &opened[k];
        let Some(h) = o.meta.headers.get(src.part) else {
            return Err(Error::Config(format!(
                "{}: no part {} (the file has {})",
                src.path.display(),
                src.part,
                o.meta.headers.len()
            )));
        };
        if h.deep {
            return Err(Error::Unsupported {
                path: src.path.clone(),
                reason: format!("part {} holds deep data, which cannot be written", src.part),
            });
        }
        // What a decoder allocates per block comes from the header: bound it
        // before any is checked (as the reader does for the part it filters).
        let limit = crate::host::default_max_memory();
        if block_bytes(h) > limit {
            return Err(Error::InvalidFile {
                path: src.path.clone(),
                reason: format!(
                    "part {}: one block claims {} MiB decoded, more than the {} MiB a block may take",
                    src.part,
                    block_bytes(h) >> 20,
                    limit >> 20
                ),
            });
        }
        which.push(k);
    }
    Ok((opened, which))
}

fn chunk_bytes(c: &Chunk) -> u64 {
    use exr::block::chunk::CompressedBlock as B;
    (match &c.compressed_block {
        B::ScanLine(b) => b.compressed_pixels_le.len(),
        B::Tile(t) => t.compressed_pixels_le.len(),
        B::DeepScanLine(b) => b.compressed_sample_data_le.len(),
        B::DeepTile(t) => t.compressed_sample_data_le.len(),
    }) as u64
}
