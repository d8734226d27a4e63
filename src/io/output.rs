//! The output of a filter run, whatever its format: an OpenEXR file or a
//! Radiance picture ([`super::Format`], chosen by the caller).

use std::path::Path;

use exr::math::Vec2;
use exr::meta::attribute::IntegerBounds;
use exr::meta::header::Header;

use super::rgbe::RgbeOutput;
use super::{ExrInput, ExrOutput, OutputSettings};
use crate::error::{Error, Result};
use crate::pipeline::{Precision, Sink};

/// What an output will be, settled before a pixel is read: the input's
/// header with the window the run writes, each channel's sample type, how many
/// channels are the filtered colour, and a Radiance input's header lines.
#[derive(Clone, Debug)]
pub struct OutputLayout {
    header: Header,
    types: Vec<Precision>,
    beauty: usize,
    rgbe_lines: Vec<String>,
}

impl OutputLayout {
    /// The layout of an output of `input`'s `channels` (the filtered colour
    /// first, those without a carry rule) written with `settings`.
    pub fn of(input: &ExrInput, channels: &[String], settings: &OutputSettings) -> Self {
        let beauty = input
            .channel_rules()
            .iter()
            .take_while(|r| r.is_none())
            .count();
        let header = input.header().clone();
        OutputLayout {
            types: super::writer::output_types(settings, &header, channels, beauty),
            header,
            beauty,
            rgbe_lines: input.rgbe().map(|r| r.lines.clone()).unwrap_or_default(),
        }
    }

    /// Each channel's sample type in the output.
    pub fn types(&self) -> &[Precision] {
        &self.types
    }

    /// The data window cropped to `w x h` samples from its origin; a
    /// display window that was the data window follows it.
    pub fn crop(&mut self, w: usize, h: usize) {
        let origin = self.header.own_attributes.layer_position;
        let old = IntegerBounds::new(origin, self.header.layer_size);
        self.header.layer_size = Vec2(w, h);
        if self.header.shared_attributes.display_window == old {
            self.header.shared_attributes.display_window =
                IntegerBounds::new(origin, self.header.layer_size);
        }
    }

    /// Only the sample rows `rows` of the data window (a band's file).
    pub fn rows(&mut self, rows: std::ops::Range<usize>) {
        self.header.layer_size.1 = rows.len();
        self.header.own_attributes.layer_position.1 += rows.start as i32;
    }

    /// Rows of one block of the compression an EXR at `dest` written with
    /// `settings` would have, and its name: the bands of `--band` end on
    /// them. A lossy compression is refused (a band's ledger must be exact).
    pub fn band_unit(&self, dest: &Path, settings: &OutputSettings) -> Result<(usize, String)> {
        let compression = self.compression(dest, settings)?;
        if self.types.iter().any(|&t| super::is_lossy(compression, t)) {
            return Err(Error::Config(format!(
                "--band needs a lossless output compression, not {}",
                super::compression_name(compression)
            )));
        }
        Ok((
            compression.scan_lines_per_block(),
            super::compression_name(compression),
        ))
    }

    /// Scan lines a block of the output at `dest` holds: the rows the
    /// writer compresses together.
    pub fn block_lines(&self, dest: &Path, settings: &OutputSettings) -> Result<usize> {
        Ok(self.compression(dest, settings)?.scan_lines_per_block())
    }

    /// The compression an EXR at `dest` written with `settings` has.
    fn compression(
        &self,
        dest: &Path,
        settings: &OutputSettings,
    ) -> Result<exr::compression::Compression> {
        let header = self.header.compression;
        super::writer::choose_compression(dest, header, settings, &self.types).map(|(c, _)| c)
    }

    /// Start the output at `dest` (see [`Output::create`]).
    pub fn create(
        &self,
        dest: &Path,
        format: super::Format,
        s: usize,
        channels: &[String],
        settings: &OutputSettings,
    ) -> Result<Output> {
        Output::create(
            dest,
            format,
            &self.header,
            s,
            channels,
            self.beauty,
            settings,
            &self.rgbe_lines,
        )
    }
}

/// An output file being written.
pub enum Output {
    /// OpenEXR.
    Exr(Box<ExrOutput>),
    /// Radiance RGBE / XYZE.
    Rgbe(Box<RgbeOutput>),
    /// Portable float map.
    Pfm(Box<super::pfm::PfmOutput>),
}

impl Output {
    /// Start the output of a run at `dest` in `format` (OpenEXR, a Radiance
    /// picture or a PFM): S x S input samples per pixel of
    /// an input described by `input_header` (and `rgbe_lines`, the header
    /// lines of a Radiance input, kept in a Radiance output); the first
    /// `beauty` of `channels` are the filtered colour.
    #[allow(clippy::too_many_arguments)]
    pub fn create(
        dest: &Path,
        format: super::Format,
        input_header: &Header,
        s: usize,
        channels: &[String],
        beauty: usize,
        settings: &OutputSettings,
        rgbe_lines: &[String],
    ) -> Result<Self> {
        if format == super::Format::Pfm {
            return Self::create_pfm(dest, input_header, s, channels, settings);
        }
        if format != super::Format::Rgbe {
            return Ok(Output::Exr(Box::new(ExrOutput::create(
                dest,
                input_header,
                s,
                channels,
                beauty,
                settings,
            )?)));
        }
        let refuse = |why: String| Error::Config(format!("{}: {why}", dest.display()));
        let xyze = match channels.iter().map(String::as_str).collect::<Vec<_>>()[..] {
            [r, g, b] if [r, g, b].map(super::reader::base_name) == ["R", "G", "B"] => false,
            ["X", "Y", "Z"] => true,
            _ => {
                return Err(refuse(format!(
                    "a Radiance picture holds R, G, B (or X, Y, Z); the filtered channels are {}",
                    channels.join(", ")
                )))
            }
        };
        if settings.compression.is_some() {
            return Err(refuse(
                "--compression applies to EXR outputs; a Radiance picture is run-length encoded"
                    .into(),
            ));
        }
        if settings.precision == Some(Precision::F16) {
            return Err(refuse(
                "--pixel-type f16 applies to EXR outputs; a Radiance picture stores RGBE".into(),
            ));
        }
        let software = settings.software();
        let history = settings.history_line();
        let (w, h) = (input_header.layer_size.0 / s, input_header.layer_size.1 / s);
        Ok(Output::Rgbe(Box::new(RgbeOutput::create(
            dest,
            w,
            h,
            xyze,
            (rgbe_lines, &history),
            &settings.extra,
            &software,
        )?)))
    }

    /// Fill a text attribute at finish (EXR; see [`ExrOutput::fill_attribute`]).
    pub fn fill_attribute(&mut self, name: &str, value: String) {
        if let Output::Exr(o) = self {
            o.fill_attribute(name, value);
        }
    }

    /// A PFM of the filtered R, G, B ([`Output::create`]).
    fn create_pfm(
        dest: &Path,
        input_header: &Header,
        s: usize,
        channels: &[String],
        settings: &OutputSettings,
    ) -> Result<Self> {
        let refuse = |why: String| Error::Config(format!("{}: {why}", dest.display()));
        let names: Vec<&str> = channels
            .iter()
            .map(|c| super::reader::base_name(c))
            .collect();
        if names != ["R", "G", "B"] {
            return Err(refuse(format!(
                "a PFM holds R, G, B; the filtered channels are {}",
                channels.join(", ")
            )));
        }
        if settings.compression.is_some() || settings.precision == Some(Precision::F16) {
            return Err(refuse(
                "--compression and --pixel-type f16 apply to EXR outputs; a PFM stores f32".into(),
            ));
        }
        let (w, h) = (input_header.layer_size.0 / s, input_header.layer_size.1 / s);
        Ok(Output::Pfm(Box::new(super::pfm::PfmOutput::create(
            dest, w, h,
        )?)))
    }

    /// The compression's name (`rgbe` for a Radiance picture).
    pub fn compression_name(&self) -> String {
        match self {
            Output::Exr(o) => super::compression_name(o.compression()).to_string(),
            Output::Rgbe(_) => "rgbe".into(),
            Output::Pfm(_) => "pfm".into(),
        }
    }

    /// What the user should know about the output's settings.
    pub fn note(&self) -> Option<&str> {
        match self {
            Output::Exr(o) => o.note(),
            Output::Rgbe(_) | Output::Pfm(_) => None,
        }
    }

    /// Whether the values on disk differ from those written (RGBE keeps 8
    /// bits of mantissa: always).
    pub fn is_lossy(&self) -> bool {
        match self {
            Output::Exr(o) => o.is_lossy(),
            Output::Rgbe(_) => true,
            Output::Pfm(_) => false,
        }
    }

    /// `--edge pad`: the energy on disk weighs each pixel by its coverage
    /// (`coverage.y` indexed by the file's rows).
    pub fn set_coverage(&mut self, coverage: crate::pipeline::edge::Coverage) {
        match self {
            Output::Exr(o) => o.set_coverage(coverage),
            Output::Rgbe(o) => o.set_coverage(coverage),
            Output::Pfm(o) => o.set_coverage(coverage),
        }
    }

    /// Per channel, the sum of what the finished file holds.
    pub fn decoded_sums(&self) -> Result<Vec<f64>> {
        match self {
            Output::Exr(o) => o.decoded_sums(),
            Output::Rgbe(o) => Ok(o.decoded_sums()),
            Output::Pfm(o) => Ok(o.decoded_sums()),
        }
    }

    /// Put the finished file in place.
    pub fn commit(self) -> Result<()> {
        match self {
            Output::Exr(o) => o.commit(),
            Output::Rgbe(o) => o.commit(),
            Output::Pfm(o) => o.commit(),
        }
    }
}

impl Sink for Output {
    fn precision(&self) -> Precision {
        match self {
            Output::Exr(o) => o.precision(),
            Output::Rgbe(o) => o.precision(),
            Output::Pfm(o) => o.precision(),
        }
    }

    fn precisions(&self, nch: usize) -> Vec<Precision> {
        match self {
            Output::Exr(o) => o.precisions(nch),
            Output::Rgbe(o) => o.precisions(nch),
            Output::Pfm(o) => o.precisions(nch),
        }
    }

    fn write_rows(&mut self, y0: usize, rows: usize, data: &[f32]) -> Result<()> {
        match self {
            Output::Exr(o) => o.write_rows(y0, rows, data),
            Output::Rgbe(o) => o.write_rows(y0, rows, data),
            Output::Pfm(o) => o.write_rows(y0, rows, data),
        }
    }

    fn finish(&mut self) -> Result<()> {
        match self {
            Output::Exr(o) => o.finish(),
            Output::Rgbe(o) => o.finish(),
            Output::Pfm(o) => o.finish(),
        }
    }
}
