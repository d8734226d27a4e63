//! The files of `epfilt filter --band K/N`: a band's labels read from its
//! header, and bands put together by copying their compressed blocks (band
//! boundaries lie on block boundaries), one block in memory at a time.

use std::io::BufWriter;
use std::path::{Path, PathBuf};

use exr::block::chunk::{Chunk, CompressedBlock};
use exr::block::writer::ChunksWriter;
use exr::meta::attribute::Text;
use exr::meta::header::Header;
use exr::meta::{BlockDescription, MetaData};

use super::provenance::{
    parse_band_ledger, Fingerprint, BAND as BAND_ATTRIBUTE, BAND_LEDGER as BAND_LEDGER_ATTRIBUTE,
    FINGERPRINT,
};
use super::reader::text_attribute;
use super::Staged;
use crate::error::{Error, Result};

/// One band file.
pub struct BandFile {
    /// Where it is.
    pub path: PathBuf,
    header: Header,
    /// Band `k` of `n`.
    pub k: usize,
    /// How many bands the image was cut into.
    pub n: usize,
    /// Its output rows.
    pub rows: (usize, usize),
    /// The whole image's output rows.
    pub of: usize,
    /// The run's super-sampling factor.
    pub s: usize,
    /// Per channel: name, energy in and out of the band's own rows.
    pub ledger: Vec<(String, f64, f64)>,
    /// The fingerprint of the run's input and settings.
    pub fingerprint: Option<Fingerprint>,
}

fn not_a_band(path: &Path, why: impl Into<String>) -> Error {
    Error::InvalidFile {
        path: path.into(),
        reason: format!("not a band of `epfilt filter --band`: {}", why.into()),
    }
}

impl BandFile {
    /// Read the header of the band at `path`.
    pub fn read(path: &Path) -> Result<BandFile> {
        let meta = MetaData::read_from_file(path, false)
            .map_err(|e| Error::from_exr(path, e, "header"))?;
        if meta.headers.len() != 1 {
            return Err(not_a_band(path, "several parts"));
        }
        let header = meta.headers[0].clone();
        if header.blocks != BlockDescription::ScanLines || header.deep {
            return Err(not_a_band(path, "not scan lines"));
        }
        let label = text_attribute(&header, BAND_ATTRIBUTE)
            .ok_or_else(|| not_a_band(path, format!("no {BAND_ATTRIBUTE} attribute")))?;
        // "K/N rows A-B of H S=s"
        let bad = || not_a_band(path, format!("{BAND_ATTRIBUTE} {label:?}"));
        let t: Vec<&str> = label.split_whitespace().collect();
        let [kn, "rows", ab, "of", of, s] = t.as_slice() else {
            return Err(bad());
        };
        let (k, n) = kn.split_once('/').ok_or_else(bad)?;
        let (a, b) = ab.split_once('-').ok_or_else(bad)?;
        let num = |v: &str| v.parse::<usize>().map_err(|_| bad());
        let s = num(s.strip_prefix("S=").ok_or_else(bad)?)?;
        let ledger = text_attribute(&header, BAND_LEDGER_ATTRIBUTE)
            .and_then(|t| parse_band_ledger(&t))
            .ok_or_else(|| not_a_band(path, format!("no readable {BAND_LEDGER_ATTRIBUTE}")))?;
        let band = BandFile {
            path: path.into(),
            k: num(k)?,
            n: num(n)?,
            rows: (num(a)?, num(b)?),
            of: num(of)?,
            s,
            ledger,
            fingerprint: text_attribute(&header, FINGERPRINT).and_then(|t| Fingerprint::parse(&t)),
            header,
        };
        if band.rows.1 - band.rows.0 != band.header.layer_size.1 {
            return Err(bad());
        }
        Ok(band)
    }

    /// The header every band of a run shares: its own without the band
    /// attributes and with the whole image's data window.
    fn whole_header(&self) -> Header {
        let mut h = self.header.clone();
        h.own_attributes.other.remove(&Text::from(BAND_ATTRIBUTE));
        h.own_attributes
            .other
            .remove(&Text::from(BAND_LEDGER_ATTRIBUTE));
        h.own_attributes.layer_position.1 -= self.rows.0 as i32;
        h.layer_size.1 = self.of;
        h.chunk_count = exr::meta::compute_chunk_count(h.compression, h.layer_size, h.blocks);
        h
    }

    /// Whether `other` was written by the same command (method, settings,
    /// channels, compression: the whole image's header is the same).
    pub fn same_layout(&self, other: &BandFile) -> bool {
        self.whole_header() == other.whole_header()
    }

    /// The image's width in samples.
    pub fn width(&self) -> usize {
        self.header.layer_size.0
    }
}

/// Write `bands` (one run's, in order, covering the image once) into
/// `staged` as one file (`output` names it in messages); returns the bytes
/// of compressed blocks copied.
pub fn write_merged(
    bands: &[BandFile],
    output: &Path,
    staged: &Staged,
    progress: crate::pipeline::Progress<'_>,
) -> Result<u64> {
    let reference = bands[0].whole_header();
    let lines = reference.compression.scan_lines_per_block();
    let y0 = reference.own_attributes.layer_position.1;
    let file = staged
        .file()
        .try_clone()
        .map_err(|e| Error::io(staged.path(), e))?;
    let mut copied = 0u64;
    let headers: exr::prelude::SmallVec<[Header; 3]> =
        exr::prelude::SmallVec::from_vec(vec![reference.clone()]);
    let written = exr::block::write(
        BufWriter::with_capacity(1 << 20, file),
        headers,
        false,
        |_meta, writer| {
            for b in bands {
                let f = std::fs::File::open(&b.path)?;
                let reader = exr::block::read(std::io::BufReader::new(f), false)?;
                // One chunk at a time, in the file's (increasing) order:
                // memory stays one block whatever the image.
                let mut last = None;
                for chunk in reader.all_chunks(false)? {
                    let chunk: Chunk = chunk?;
                    let CompressedBlock::ScanLine(block) = &chunk.compressed_block else {
                        return Err(exr::error::Error::Invalid(
                            "a band holds scan lines only".into(),
                        ));
                    };
                    let y = block.y_coordinate;
                    if last.is_some_and(|l| y <= l) || y < y0 {
                        return Err(exr::error::Error::Invalid(
                            "band blocks out of order".into(),
                        ));
                    }
                    last = Some(y);
                    let index = (y - y0) as usize / lines;
                    copied += block.compressed_pixels_le.len() as u64;
                    writer.write_chunk(index, chunk)?;
                    let done = ((y - y0) as usize + lines).min(b.of);
                    progress(done, b.of);
                }
            }
            Ok(())
        },
    );
    written.map_err(|e| Error::from_exr(output, e, "merging"))?;
    crate::io::headers::sort_header_attributes(staged.file(), None).map_err(|e| Error::Output {
        path: output.into(),
        reason: format!("putting the header in order: {e}"),
    })?;
    staged.file().sync_all().ok();
    Ok(copied)
}
