//! Writing the filtered image: scan-line blocks filled as the rows come and
//! compressed in parallel on the shared pool (`blocks.rs`), written in
//! increasing y by the `exr` chunk writer on its own thread, into a
//! temporary file beside the destination. The file is renamed
//! into place only by [`ExrOutput::commit`], after the caller has checked the
//! energy ledger; dropped uncommitted, it is removed.

use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::thread::JoinHandle;

use exr::block::chunk::Chunk;
use exr::block::writer::ChunksWriter;
use exr::math::Vec2;
use exr::meta::attribute::{ChannelDescription, ChannelList, IntegerBounds, LineOrder, SampleType};
use exr::meta::header::Header;
use exr::meta::BlockDescription;
use exr::prelude::{Compression, SmallVec, Text};

use crate::error::{Error, Result};
use crate::pipeline::{Precision, Sink};

mod blocks;
use blocks::Blocks;

/// What the output file looks like.
#[derive(Clone, Debug, Default)]
pub struct OutputSettings {
    /// Compression (None: the input's, unless that is lossy for the output's
    /// samples: then ZIP, and [`ExrOutput::note`] says so).
    pub compression: Option<Compression>,
    /// Sample type; `None`: the input's ([`same_precision`]).
    pub precision: Option<Precision>,
    /// Accept a lossy compression ([`super::is_lossy`]): the energy on disk
    /// is then no longer exact, and the run measures it by decoding the file
    /// ([`ExrOutput::decoded_sums`]). Without it a lossy `compression` is
    /// refused.
    pub allow_lossy: bool,
    /// How the file was made: its `epfiltSettings` attribute reads
    /// `epfilt VERSION (key=value ...)`.
    pub provenance: Option<String>,
    /// More text attributes (name, value) for the header.
    pub extra: Vec<(String, String)>,
    /// Bytes of rows (as f32) the writer holds before it compresses them
    /// in parallel, one block at the least (0: [`WRITE_AHEAD_BYTES`]).
    pub write_ahead: usize,
}

/// An output file being written.
pub struct ExrOutput {
    dest: PathBuf,
    staged: Option<super::Staged>,
    headers: SmallVec<[Header; 3]>,
    nch: usize,
    /// For each header channel (sorted by name), its index in our rows.
    order: Vec<usize>,
    /// Sample type of each channel, in our rows' order.
    types: Vec<Precision>,
    /// The blocks being filled.
    blocks: Blocks,
    compression: Compression,
    note: Option<String>,
    /// A text attribute whose value is filled in (same length) at finish.
    fill: Option<(String, String)>,
    /// `--edge pad`: the decoded sums weigh pixels by this.
    coverage: Option<crate::pipeline::edge::Coverage>,
    tx: Option<crossbeam_channel::Sender<(usize, Chunk)>>,
    thread: Option<JoinHandle<Result<()>>>,
}

/// The attribute that records epfilt's settings of the run that made a file.
pub const SETTINGS_ATTRIBUTE: &str = "epfiltSettings";

/// The attribute that holds the runs that made a file, one a line, oldest
/// first (as Radiance programs append theirs to a picture's header). A line
/// is the run's version and settings, not its literal command line: paths,
/// threads, tiles, strips and bands would make the bytes of one result
/// differ from cut to cut, band to band and rerun to rerun.
pub const HISTORY_ATTRIBUTE: &str = "epfiltHistory";

impl OutputSettings {
    /// What the file says made it: `epfilt VERSION (settings)`.
    pub fn software(&self) -> String {
        match &self.provenance {
            Some(p) => format!("epfilt {} ({p})", env!("CARGO_PKG_VERSION")),
            None => format!("epfilt {}", env!("CARGO_PKG_VERSION")),
        }
    }

    /// This run's line of the history ([`HISTORY_ATTRIBUTE`]).
    pub fn history_line(&self) -> String {
        self.software()
    }
}

/// The output sample type that keeps each channel's input type
/// (`--pixel-type same`): f16, f32, or u32 for ids carried by their nearest
/// sample. The first `beauty` channels are the filtered colour: a u32 one
/// becomes f32 (its filtered values are not whole numbers).
pub fn same_precision(input_header: &Header, channels: &[String], beauty: usize) -> Vec<Precision> {
    channels
        .iter()
        .enumerate()
        .map(|(k, n)| match input_type(input_header, n) {
            Some(SampleType::F16) => Precision::F16,
            Some(SampleType::U32) if k >= beauty => Precision::U32,
            _ => Precision::F32,
        })
        .collect()
}

fn input_type(input_header: &Header, name: &str) -> Option<SampleType> {
    input_header
        .channels
        .list
        .iter()
        .find(|c| c.name.eq(name))
        .map(|c| c.sample_type)
}

/// The sample type of each of `channels` in the output: the one asked for,
/// or each channel's own ([`same_precision`]; the first `beauty` are the
/// filtered colour).
pub fn output_types(
    settings: &OutputSettings,
    input_header: &Header,
    channels: &[String],
    beauty: usize,
) -> Vec<Precision> {
    let same = same_precision(input_header, channels, beauty);
    match settings.precision {
        // Ids stay u32 whatever float type the rest is given.
        Some(p) => same
            .iter()
            .map(|&t| if t == Precision::U32 { t } else { p })
            .collect(),
        None => same,
    }
}

/// The types' names, one per channel, or one name when they agree.
pub fn types_name(types: &[Precision]) -> String {
    match types.split_first() {
        Some((first, rest)) if rest.iter().all(|t| t == first) => first.name().to_string(),
        _ => types.iter().map(|t| t.name()).collect::<Vec<_>>().join(","),
    }
}

/// The output's compression and, where it is not what the input had, why.
/// An explicit lossy choice needs `allow_lossy`; the input's lossy codec is
/// replaced by ZIP unless `allow_lossy`.
pub(crate) fn choose_compression(
    dest: &Path,
    input: Compression,
    settings: &OutputSettings,
    types: &[Precision],
) -> Result<(Compression, Option<String>)> {
    let name = super::compression_name;
    // Lossy when it is for any channel's type.
    let lossy_for = |c| types.iter().copied().find(|&t| super::is_lossy(c, t));
    let lossy = |c| lossy_for(c).is_some();
    let kind = |c| lossy_for(c).map_or("", |t| t.name());
    match settings.compression {
        Some(c) if lossy(c) && !settings.allow_lossy => Err(Error::Output {
            path: dest.to_path_buf(),
            reason: format!(
                "--compression {} is lossy for {} samples, so the energy on disk would not be exact; choose a lossless one (zip, zips, piz, rle, none) or pass --allow-lossy",
                name(c),
                kind(c)
            ),
        }),
        Some(c) => Ok((c, None)),
        None if lossy(input) && !settings.allow_lossy => Ok((
            Compression::ZIP16,
            Some(format!(
                "the input's compression ({}) is lossy for {} samples: writing zip instead (--compression to choose, --allow-lossy to keep it)",
                name(input),
                kind(input)
            )),
        )),
        None => Ok((input, None)),
    }
}

fn floor_div(a: i32, s: i32) -> i32 {
    a.div_euclid(s)
}

impl ExrOutput {
    /// Start writing `dest` (through a temporary file in its directory) with
    /// the input's header attributes that still hold.
    pub fn create(
        dest: &Path,
        input_header: &Header,
        s: usize,
        channels: &[String],
        beauty: usize,
        settings: &OutputSettings,
    ) -> Result<Self> {
        let (w, h) = (input_header.layer_size.0 / s, input_header.layer_size.1 / s);
        let types = output_types(settings, input_header, channels, beauty);
        let (compression, note) =
            choose_compression(dest, input_header.compression, settings, &types)?;
        let mut header = Self::fresh_header(w, h, channels, compression, &types);
        let si = s as i32;
        // Keep what still holds: every attribute but the geometry we change and
        // the preview (a picture of the input).
        let mut own = input_header.own_attributes.clone();
        let pos = own.layer_position;
        own.layer_position = Vec2(floor_div(pos.0, si), floor_div(pos.1, si));
        own.preview = None;
        own.original_data_window = None;
        own.multi_view_names = own.multi_view_names.as_ref().and_then(|views| {
            let names: Vec<String> = views.iter().map(|v| v.to_string()).collect();
            let kept = super::headers::views_with_channels(&names, channels);
            (!kept.is_empty()).then(|| kept.iter().map(|v| Text::from(v.as_str())).collect())
        });
        // The input's `software` stays the renderer's; epfilt's settings
        // and the command go into attributes of their own (sorted with the
        // rest once written: the bytes do not change from run to run).
        if own.software_name.is_none() {
            own.software_name = Some(Text::from(settings.software().as_str()));
        }
        let history = match own.other.get(&Text::from(HISTORY_ATTRIBUTE)) {
            Some(exr::meta::attribute::AttributeValue::Text(t)) => {
                format!("{t}\n{}", settings.history_line())
            }
            _ => settings.history_line(),
        };
        // What an input that epfilt wrote records of its own making is not
        // this output's ([`super::provenance`]); its history is kept above.
        own.other
            .retain(|k, _| !k.to_string().starts_with("epfilt"));
        for (k, v) in [
            (SETTINGS_ATTRIBUTE, settings.software()),
            (HISTORY_ATTRIBUTE, history),
        ] {
            own.other.insert(
                Text::from(k),
                exr::meta::attribute::AttributeValue::Text(Text::from(v.as_str())),
            );
        }
        for (k, v) in &settings.extra {
            own.other.insert(
                Text::from(k.as_str()),
                exr::meta::attribute::AttributeValue::Text(Text::from(v.as_str())),
            );
        }
        header.own_attributes = own;
        let mut shared = input_header.shared_attributes.clone();
        let dw = shared.display_window;
        let (x0, y0) = (floor_div(dw.position.0, si), floor_div(dw.position.1, si));
        let x1 = floor_div(dw.position.0 + dw.size.0 as i32 + si - 1, si);
        let y1 = floor_div(dw.position.1 + dw.size.1 as i32 + si - 1, si);
        shared.display_window = IntegerBounds::new(
            Vec2(x0, y0),
            Vec2((x1 - x0).max(1) as usize, (y1 - y0).max(1) as usize),
        );
        header.shared_attributes = shared;
        let mut out = Self::start(dest, header, channels, types)?;
        if settings.write_ahead > 0 {
            out.blocks.set_batch_bytes(settings.write_ahead);
        }
        out.note = note;
        Ok(out)
    }

    /// At finish, replace the value of the text attribute `name` (given in
    /// [`OutputSettings::extra`]) by `value`, which must have the same
    /// length: what is known only when the pixels are written.
    pub fn fill_attribute(&mut self, name: &str, value: String) {
        self.fill = Some((name.to_string(), value));
    }

    /// The compression being written.
    pub fn compression(&self) -> Compression {
        self.compression
    }

    /// What the caller should tell the user about the output's settings
    /// (the input's lossy codec replaced by ZIP).
    pub fn note(&self) -> Option<&str> {
        self.note.as_deref()
    }

    /// Whether the samples on disk differ from those written.
    pub fn is_lossy(&self) -> bool {
        self.types
            .iter()
            .any(|&t| super::is_lossy(self.compression, t))
    }

    /// `--edge pad`: weigh each pixel by its coverage in [`Self::decoded_sums`].
    pub fn set_coverage(&mut self, coverage: crate::pipeline::edge::Coverage) {
        self.coverage = Some(coverage);
    }

    /// Decode the finished (not yet committed) file and sum each channel,
    /// in the order of the channels given at creation: the energy on disk
    /// when the compression is lossy.
    pub fn decoded_sums(&self) -> Result<Vec<f64>> {
        let staged = self
            .staged
            .as_ref()
            .ok_or_else(|| Error::Internal("the output was already committed".into()))?;
        use exr::block::reader::ChunksReader;
        use exr::meta::attribute::SampleType;
        let path = staged.path();
        let bad = |e: exr::error::Error| Error::Output {
            path: self.dest.clone(),
            reason: format!("decoding what was written: {e}"),
        };
        let file = std::fs::File::open(path).map_err(|e| Error::Output {
            path: self.dest.clone(),
            reason: format!("reopening what was written: {e}"),
        })?;
        let chunks = exr::block::read(std::io::BufReader::new(file), false)
            .and_then(|r| r.all_chunks(false))
            .map_err(bad)?;
        let header = &self.headers[0];
        let lines = header.compression.scan_lines_per_block();
        let blocks = header.layer_size.1.div_ceil(lines);
        let (w, nch) = (header.layer_size.0, self.nch);
        // Per block, per header channel: blocks arrive in any order, their
        // sums are merged in block order so the figure is reproducible.
        let mut parts = vec![vec![crate::pipeline::ledger::CompensatedSum::default(); nch]; blocks];
        let mut malformed = false;
        chunks
            .decompress_parallel(false, |_, block| {
                let rows = block.index.pixel_size.1;
                let k = block.index.pixel_position.1 / lines;
                let row_bytes: usize = header
                    .channels
                    .list
                    .iter()
                    .map(|c| w * c.sample_type.bytes_per_sample())
                    .sum();
                if block.data.len() != rows * row_bytes || k >= blocks {
                    malformed = true;
                    return Ok(());
                }
                let mut at = 0;
                let y0 = block.index.pixel_position.1;
                let cov = self.coverage.as_ref();
                let weight = |x: usize, y: usize| cov.map_or(1.0, |c| c.at(x, y));
                for r in 0..rows {
                    for (c, ch) in header.channels.list.iter().enumerate() {
                        let sum = &mut parts[k][c];
                        match ch.sample_type {
                            SampleType::F16 => {
                                for (x, b) in block.data[at..at + 2 * w].chunks_exact(2).enumerate()
                                {
                                    let v = half::f16::from_ne_bytes([b[0], b[1]]).to_f64();
                                    sum.add(v * weight(x, y0 + r));
                                }
                                at += 2 * w;
                            }
                            SampleType::F32 => {
                                for (x, b) in block.data[at..at + 4 * w].chunks_exact(4).enumerate()
                                {
                                    let v = f32::from_ne_bytes([b[0], b[1], b[2], b[3]]) as f64;
                                    sum.add(v * weight(x, y0 + r));
                                }
                                at += 4 * w;
                            }
                            SampleType::U32 => at += 4 * w,
                        }
                    }
                }
                Ok(())
            })
            .map_err(bad)?;
        if malformed {
            return Err(Error::Output {
                path: self.dest.clone(),
                reason: "what was written decodes to blocks of the wrong size".into(),
            });
        }
        let mut sums = vec![crate::pipeline::ledger::CompensatedSum::default(); nch];
        for part in &parts {
            for (k, p) in part.iter().enumerate() {
                sums[self.order[k]].merge(p);
            }
        }
        Ok(sums.iter().map(|s| s.value()).collect())
    }

    /// Start writing a new `w` x `h` image of `channels` (planar rows in that
    /// order), with default attributes plus the integer attributes `ints`.
    pub fn create_new(
        dest: &Path,
        w: usize,
        h: usize,
        channels: &[String],
        compression: Compression,
        precision: Precision,
        ints: &[(&str, i32)],
    ) -> Result<Self> {
        let types = vec![precision; channels.len()];
        let mut header = Self::fresh_header(w, h, channels, compression, &types);
        let software = format!("epfilt {}", env!("CARGO_PKG_VERSION"));
        header.own_attributes.software_name = Some(Text::from(software.as_str()));
        for (name, v) in ints {
            header.own_attributes.other.insert(
                Text::from(*name),
                exr::meta::attribute::AttributeValue::I32(*v),
            );
        }
        Self::start(dest, header, channels, types)
    }

    fn fresh_header(
        w: usize,
        h: usize,
        channels: &[String],
        compression: Compression,
        types: &[Precision],
    ) -> Header {
        let mut sorted: Vec<(&String, Precision)> =
            channels.iter().zip(types.iter().copied()).collect();
        sorted.sort_by(|a, b| a.0.as_bytes().cmp(b.0.as_bytes()));
        let list: SmallVec<[ChannelDescription; 5]> = sorted
            .iter()
            .map(|&(n, t)| {
                let linear = n.rsplit('.').next() == Some("A");
                let sample_type = match t {
                    Precision::F32 => SampleType::F32,
                    Precision::F16 => SampleType::F16,
                    Precision::U32 => SampleType::U32,
                };
                ChannelDescription::new(Text::from(n.as_str()), sample_type, linear)
            })
            .collect();
        let mut header = Header::new(Text::from(""), Vec2(w, h), list).with_encoding(
            compression,
            BlockDescription::ScanLines,
            LineOrder::Increasing,
        );
        header.channels = ChannelList::new(header.channels.list.clone());
        header.own_attributes.layer_name = None;
        header
    }

    fn start(
        dest: &Path,
        header: Header,
        channels: &[String],
        types: Vec<Precision>,
    ) -> Result<Self> {
        let (w, h) = (header.layer_size.0, header.layer_size.1);
        let staged = super::Staged::new(dest, ".exr.tmp")?;
        let order: Vec<usize> = header
            .channels
            .list
            .iter()
            .map(|c| {
                channels
                    .iter()
                    .position(|n| n.as_str() == c.name.to_string())
                    .unwrap_or(0)
            })
            .collect();
        let lines = header.compression.scan_lines_per_block();
        let header_compression = header.compression;
        let mut blocks = Blocks::new(
            (w, h, lines),
            order.clone(),
            types.clone(),
            super::zip::codes(header_compression),
        );
        blocks.set_batch_bytes(WRITE_AHEAD_BYTES);
        let headers: SmallVec<[Header; 3]> = SmallVec::from_vec(vec![header]);

        let file = staged
            .file()
            .try_clone()
            .map_err(|e| Error::io(staged.path(), e))?;
        let (tx, rx) = crossbeam_channel::bounded::<(usize, Chunk)>(4);
        let thread_headers = headers.clone();
        let tpath = dest.to_path_buf();
        let thread = std::thread::Builder::new()
            .name("epfilt-writer".into())
            .spawn(move || -> Result<()> {
                let out = BufWriter::with_capacity(1 << 20, Writeback::new(file));
                exr::block::write(out, thread_headers, false, |_meta, writer| {
                    for (index, chunk) in rx.iter() {
                        writer.write_chunk(index, chunk)?;
                    }
                    Ok(())
                })
                .map_err(|e| Error::from_exr(&tpath, e, "writing"))
            })
            .map_err(|e| Error::io(staged.path(), e))?;
        Ok(ExrOutput {
            dest: dest.to_path_buf(),
            staged: Some(staged),
            headers,
            nch: channels.len(),
            order,
            types,
            blocks,
            compression: header_compression,
            note: None,
            fill: None,
            coverage: None,
            tx: Some(tx),
            thread: Some(thread),
        })
    }

    /// Compress and send the blocks [`Blocks::take`] gives.
    fn flush_blocks(&mut self, all: bool) -> Result<()> {
        let height = self.headers[0].layer_size.1;
        if all && self.blocks.rows_in() != height {
            // Only the image's last block may be short.
            return Err(Error::Internal(format!(
                "{}: output incomplete ({} of {height} rows)",
                self.dest.display(),
                self.blocks.rows_in()
            )));
        }
        let ready = self.blocks.take(all);
        if ready.is_empty() {
            return Ok(());
        }
        for c in self.blocks.compress(ready, &self.headers) {
            let c = c.map_err(|e| Error::from_exr(&self.dest, e, "compressing"))?;
            let tx = self.tx.as_ref().ok_or(Error::Interrupted)?;
            if tx.send(c).is_err() {
                return self.join_writer();
            }
        }
        Ok(())
    }

    fn join_writer(&mut self) -> Result<()> {
        self.tx = None;
        match self.thread.take() {
            Some(t) => t
                .join()
                .unwrap_or_else(|_| Err(Error::Internal("writer thread panicked".into()))),
            None => Ok(()),
        }
    }

    /// Put the finished file in place ([`super::Staged::commit`]).
    pub fn commit(mut self) -> Result<()> {
        let staged = self.staged.take().ok_or(Error::Interrupted)?;
        staged.commit()
    }
}

impl Sink for ExrOutput {
    fn precision(&self) -> Precision {
        // The widest type written (a mix holds f32).
        if self.types.iter().all(|&t| t == Precision::F16) {
            Precision::F16
        } else {
            Precision::F32
        }
    }

    fn precisions(&self, nch: usize) -> Vec<Precision> {
        if self.types.len() == nch {
            self.types.clone()
        } else {
            vec![self.precision(); nch]
        }
    }

    fn write_rows(&mut self, _y0: usize, _rows: usize, data: &[f32]) -> Result<()> {
        let row_len = (self.nch * self.headers[0].layer_size.0).max(1);
        let mut rows = data.chunks_exact(row_len).len();
        let mut data = data;
        while rows > 0 {
            let Some(n) = self.blocks.push(data) else {
                return Err(Error::Internal(format!(
                    "{}: rows written past the image's end",
                    self.dest.display()
                )));
            };
            self.flush_blocks(false)?;
            data = &data[n * row_len..];
            rows -= n;
        }
        Ok(())
    }

    fn finish(&mut self) -> Result<()> {
        self.flush_blocks(true)?;
        self.join_writer()?;
        if let Some(t) = &self.staged {
            let fill = self.fill.as_ref().map(|(k, v)| (k.as_str(), v.as_str()));
            super::headers::sort_header_attributes(t.file(), fill).map_err(|e| Error::Output {
                path: self.dest.clone(),
                reason: format!("putting the header in order: {e}"),
            })?;
            t.file().sync_all().ok();
        }
        Ok(())
    }
}

/// A file whose written pages the kernel starts writing to disk every
/// [`WRITEBACK_BYTES`], while the filter goes on: the `fsync` before the
/// output is renamed into place then has only the last pages to wait for,
/// not the whole file.
struct Writeback {
    file: std::fs::File,
    unsynced: u64,
}

/// Rows the writer holds before it compresses them (as f32) where the
/// settings do not say: enough blocks to keep 16 workers busy.
pub const WRITE_AHEAD_BYTES: usize = 16 << 20;

/// Bytes written between two requests to start writing back.
const WRITEBACK_BYTES: u64 = 4 << 20;

impl Writeback {
    fn new(file: std::fs::File) -> Self {
        Writeback { file, unsynced: 0 }
    }
}

impl std::io::Write for Writeback {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.file.write(buf)?;
        self.unsynced += n as u64;
        if self.unsynced >= WRITEBACK_BYTES {
            self.unsynced = 0;
            #[cfg(target_os = "linux")]
            {
                use std::os::fd::AsRawFd;
                // Start writing back every dirty page of the file, without
                // waiting (a hint: its failure changes nothing but speed).
                // SAFETY: a valid descriptor owned by `self.file`; no memory
                // is passed.
                #[allow(unsafe_code)]
                unsafe {
                    libc::sync_file_range(self.file.as_raw_fd(), 0, 0, libc::SYNC_FILE_RANGE_WRITE);
                }
            }
        }
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

impl std::io::Seek for Writeback {
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        self.file.seek(pos)
    }
}

impl Drop for ExrOutput {
    fn drop(&mut self) {
        self.tx = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        // An uncommitted staged file is removed when dropped.
    }
}
