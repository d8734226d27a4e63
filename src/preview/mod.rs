//! Looking at HDR results: PNG previews under the paper's display mapping
//! or in false colour, of whole renders or a crop, at their size or shrunk.
//!
//! The tone operator is the simple linear one of §5.1 (Eq. 9): the image's
//! average luminance goes to the middle of the display range, values are
//! clamped and sRGB-encoded. `exposure` (stops) scales on top. False colour
//! shows luminance on a log scale with a legend in the image's own units,
//! as Radiance's `falsecolor` does; a difference image shows where and how
//! much two images differ the same way. A montage puts several images side
//! by side under one mapping, each with a label. Everything streams: a
//! preview holds a strip of its input and two rows of its output, so a
//! gigapixel render previews in the memory of a few of its rows.

mod colour;
mod scale;

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use colour::{legend_row, round_up, BACKGROUND, LEGEND_WIDTH};
pub use colour::{Display, LogScale};
pub use scale::AreaShrink;

use crate::error::{Error, Result};
use crate::io::reader::InputSource;
use crate::io::{ExrInput, Format, Selection};
use crate::pipeline::ledger::CompensatedSum;
use crate::pipeline::{Progress, Source, Strip};

/// Height of a line of the label band above each panel, in pixels.
const LABEL_BAND: usize = 12;
/// Gap between panels, in pixels.
const GAP: usize = 4;
/// Rows read at once.
const STRIP_ROWS: usize = 64;
/// The largest preview side, in pixels.
const MAX_SIDE: usize = 1 << 20;
/// Each of a preview's two reads' share of its progress, in steps.
const PROGRESS_STEPS: usize = 1000;
/// Values per pixel a panel makes: R, G, B, and what false colour shows.
const K: usize = 4;
/// The share of pixels a false-colour scale's top leaves above it.
const ABOVE_TOP: f64 = 1e-3;
/// Histogram bins per factor of ten, for the false-colour top.
const BINS_PER_DECADE: f64 = 32.0;
/// The histogram's range, in factors of ten (1e-30 to 1e30).
const DECADES_KEPT: f64 = 60.0;

/// What `preview` writes.
pub const WRITES: &[Format] = &[Format::Png];

/// How a preview reads, sizes and colours its inputs.
#[derive(Clone, Debug, Default)]
pub struct PreviewSettings {
    /// Exposure in stops on top of the average-to-mid-grey mapping.
    pub exposure: f64,
    /// Each panel at most this many pixels wide, shrunk by area (`None`:
    /// as read); never enlarged.
    pub width: Option<usize>,
    /// The rectangle of each input shown (`None`: all of it).
    pub crop: Option<Crop>,
    /// Luminance in false colour, with a legend, instead of the tone
    /// mapping.
    pub false_color: Option<FalseColor>,
    /// The part and layer read.
    pub select: Selection,
    /// `--format`, for an output name that does not end in `.png`.
    pub format: Option<Format>,
}

/// A rectangle of an image, in pixels of its data window from the top left.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crop {
    /// Left column.
    pub x: usize,
    /// Top row.
    pub y: usize,
    /// Width.
    pub w: usize,
    /// Height.
    pub h: usize,
}

impl Crop {
    /// Parse `WxH+X+Y` (as oiiotool and ImageMagick write a geometry).
    pub fn parse(s: &str) -> Result<Self> {
        let bad = || {
            Error::Config(format!(
                "crop {s:?} is not WxH+X+Y (for example 512x256+1024+0)"
            ))
        };
        let (size, at) = s.split_once('+').ok_or_else(bad)?;
        let (w, h) = size.split_once('x').ok_or_else(bad)?;
        let (x, y) = at.split_once('+').ok_or_else(bad)?;
        let n = |t: &str| t.trim().parse::<usize>().map_err(|_| bad());
        let crop = Crop {
            x: n(x)?,
            y: n(y)?,
            w: n(w)?,
            h: n(h)?,
        };
        if crop.w == 0 || crop.h == 0 {
            return Err(bad());
        }
        Ok(crop)
    }

    /// Check that it lies in `input` (this crop, or all of it for `None`).
    fn of(crop: Option<Crop>, input: &ExrInput) -> Result<Crop> {
        let (w, h) = input.size();
        let Some(c) = crop else {
            return Ok(Crop { x: 0, y: 0, w, h });
        };
        if c.x.checked_add(c.w).is_none_or(|r| r > w) || c.y.checked_add(c.h).is_none_or(|b| b > h)
        {
            return Err(Error::Config(format!(
                "{}: crop {}x{}+{}+{} is not inside the image ({w}x{h})",
                input.path().display(),
                c.w,
                c.h,
                c.x,
                c.y
            )));
        }
        Ok(c)
    }
}

/// A false-colour scale's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FalseColor {
    /// The value in the warmest colour (`None`: a round number just above
    /// all but the brightest 0.1% of the first image's pixels).
    pub top: Option<f64>,
    /// How many factors of ten below it the colours reach.
    pub decades: u32,
}

impl Default for FalseColor {
    fn default() -> Self {
        FalseColor {
            top: None,
            decades: 4,
        }
    }
}

/// Write `inputs` (path, label) side by side as one sRGB PNG at `output`,
/// under one mapping (from the first image), as `settings` say. With one
/// input and no label, a plain preview. `progress(done, total)`: the first
/// image's rows read for the mapping, then the preview's rows.
pub fn write_png(
    inputs: &[(PathBuf, String)],
    output: &Path,
    settings: &PreviewSettings,
    progress: Progress<'_>,
) -> Result<()> {
    check_output(output, settings)?;
    if inputs.is_empty() {
        return Err(Error::Config("preview needs at least one input".into()));
    }
    let opened: Vec<ExrInput> = (inputs.iter())
        .map(|(p, _)| settings.select.open(p))
        .collect::<Result<_>>()?;
    let crops: Vec<Crop> = (opened.iter())
        .map(|i| Crop::of(settings.crop, i))
        .collect::<Result<_>>()?;
    let panels: Vec<Panel> = (opened.iter().zip(&crops).zip(inputs))
        .map(|((i, &c), (_, label))| Panel {
            rows: Rows::image(i, c),
            label: label.clone(),
        })
        .collect();
    let first = Rows::image(&opened[0], crops[0]);
    render(panels, first, output, settings, ("lum", progress))
}

/// Write where and how much `a` differs from `b` (same size and channels)
/// as a false-colour PNG at `output`: each pixel's luminance-weighted sum of
/// the absolute differences of its channels, on a log scale with a legend;
/// `progress` as for [`write_png`].
pub fn write_diff_png(
    a: &Path,
    b: &Path,
    output: &Path,
    settings: &PreviewSettings,
    progress: Progress<'_>,
) -> Result<()> {
    check_output(output, settings)?;
    let (ia, ib) = (settings.select.open(a)?, settings.select.open(b)?);
    if ia.size() != ib.size() || ia.channels() != ib.channels() {
        return Err(Error::Mismatch {
            path: a.to_path_buf(),
            reason: format!("{} differs from it in size or channels", b.display()),
        });
    }
    let crop = Crop::of(settings.crop, &ia)?;
    let settings = &PreviewSettings {
        false_color: Some(settings.false_color.unwrap_or_default()),
        ..settings.clone()
    };
    let label = format!("|{} - {}|", name(a), name(b));
    let panels = vec![Panel {
        rows: Rows::diff(&ia, &ib, crop),
        label,
    }];
    let first = Rows::diff(&ia, &ib, crop);
    render(panels, first, output, settings, ("diff", progress))
}

fn name(p: &Path) -> String {
    (p.file_name()).map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into())
}

fn check_output(output: &Path, settings: &PreviewSettings) -> Result<()> {
    crate::io::format::output_format(
        output,
        settings.format,
        Some(Format::Png),
        WRITES,
        "preview",
    )?;
    if settings.width == Some(0) {
        return Err(Error::Config("preview --width must be at least 1".into()));
    }
    if let Some(f) = settings.false_color {
        if !(1..=30).contains(&f.decades) {
            return Err(Error::Config(format!(
                "--fc-decades {} is outside 1..30",
                f.decades
            )));
        }
        if f.top.is_some_and(|t| !(t > 0.0 && t.is_finite())) {
            return Err(Error::Config("--fc-top must be a positive number".into()));
        }
    }
    Ok(())
}

/// One panel: its rows and its label.
struct Panel<'a> {
    rows: Rows<'a>,
    label: String,
}

/// The average of the first panel's luminance, and the value above all
/// but `ABOVE_TOP` of its pixels' measures (when `top` is asked for).
fn survey(rows: &mut Rows<'_>, top: bool, progress: &dyn Fn(usize)) -> Result<(f64, f64)> {
    let w = rows.crop.w;
    let mut px = vec![0.0; w * K];
    let mut sum = CompensatedSum::default();
    let bins = (DECADES_KEPT * BINS_PER_DECADE) as usize;
    let mut hist = vec![0u64; if top { bins } else { 0 }];
    let mut positive = 0u64;
    for y in 0..rows.crop.h {
        progress(y);
        rows.next(&mut px)?;
        for p in px.chunks_exact(K) {
            // The luminance is the measure of an image; a difference has
            // no luminance of its own to map.
            sum.add(p[3]);
            if top && p[3] > 0.0 {
                let at = (p[3].log10() + DECADES_KEPT / 2.0) * BINS_PER_DECADE;
                hist[(at.max(0.0) as usize).min(bins - 1)] += 1;
                positive += 1;
            }
        }
    }
    let mean = sum.value() / (w * rows.crop.h).max(1) as f64;
    let mut above = 0u64;
    let mut at = None;
    for (i, &n) in hist.iter().enumerate().rev() {
        above += n;
        if above as f64 > ABOVE_TOP * positive as f64 {
            at = Some(i);
            break;
        }
    }
    let top = at.map_or(1.0, |i| {
        10f64.powf((i + 1) as f64 / BINS_PER_DECADE - DECADES_KEPT / 2.0)
    });
    Ok((mean, top))
}

/// The PNG of `panels` side by side, mapped by what `first` (the first
/// panel's rows, read once more) says, as `settings` ask; `legend` names the
/// false-colour legend's quantity. Progress is half the survey's rows, half
/// the preview's.
fn render(
    panels: Vec<Panel<'_>>,
    mut first: Rows<'_>,
    output: &Path,
    settings: &PreviewSettings,
    (legend, progress): (&str, Progress<'_>),
) -> Result<()> {
    let fc = settings.false_color;
    let rows = first.crop.h;
    let surveyed = |y: usize| progress(y * PROGRESS_STEPS / rows, 2 * PROGRESS_STEPS);
    let (mean, top) = survey(&mut first, fc.is_some_and(|f| f.top.is_none()), &surveyed)?;
    drop(first);
    let display = Display::for_average(mean, settings.exposure);
    let scale = fc.map(|f| LogScale {
        top: f.top.unwrap_or_else(|| round_up(top)),
        decades: f.decades,
    });
    let labelled = panels.len() > 1 || !panels[0].label.is_empty() || scale.is_some();
    // A label of several lines (split at newlines) makes the band taller.
    let lines = (panels.iter().map(|p| p.label.lines().count()).max()).unwrap_or(0);
    let band = if labelled {
        LABEL_BAND * lines.max(1)
    } else {
        0
    };
    let mut states: Vec<PanelState> = panels
        .into_iter()
        .map(|p| {
            let crop = (p.rows.crop.w, p.rows.crop.h);
            let shrink = AreaShrink::to_width(K, crop, settings.width.unwrap_or(crop.0));
            PanelState {
                input: vec![0.0; crop.0 * K],
                ready: vec![0.0; shrink.size().0 * K],
                shrink,
                rows: p.rows,
                label: p.label,
            }
        })
        .collect();
    let panels_h = states.iter().map(|s| s.shrink.size().1).max().unwrap_or(0);
    let height = panels_h + band;
    let widths: Vec<usize> = states.iter().map(|s| s.shrink.size().0).collect();
    let legend_x = widths.iter().sum::<usize>() + GAP * (widths.len() - 1);
    let width = legend_x + scale.map_or(0, |_| GAP + LEGEND_WIDTH);
    if width > MAX_SIDE || height > MAX_SIDE {
        return Err(Error::Config(format!(
            "preview of {width}x{height} pixels is too large: shrink it with --width or --crop"
        )));
    }
    let temp = crate::io::Staged::new(output, ".png.tmp")?;
    let png_err = |e: png::EncodingError| Error::io(output, std::io::Error::other(e));
    {
        let file = (temp.file().try_clone()).map_err(|e| Error::io(temp.path(), e))?;
        let mut enc = png::Encoder::new(BufWriter::new(file), width as u32, height as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        let mut writer = enc.write_header().map_err(png_err)?;
        let mut stream = writer.stream_writer().map_err(png_err)?;
        let mut row = vec![0u8; width * 3];
        let mut put = |row: &[u8]| stream.write_all(row).map_err(|e| Error::io(output, e));
        for y in 0..band {
            row.iter_mut().for_each(|b| *b = BACKGROUND);
            let mut x0 = 0;
            for (s, &w) in states.iter().zip(&widths) {
                let (line, gy) = (y / LABEL_BAND, (y % LABEL_BAND) as i64 - 2);
                let text = s.label.lines().nth(line).unwrap_or("");
                colour::draw_text(&mut row, x0, w, gy, text);
                x0 += w + GAP;
            }
            if scale.is_some() {
                colour::draw_text(&mut row, legend_x + GAP, LEGEND_WIDTH, y as i64 - 2, legend);
            }
            put(&row)?;
        }
        for y in 0..panels_h {
            progress(
                PROGRESS_STEPS + y * PROGRESS_STEPS / panels_h,
                2 * PROGRESS_STEPS,
            );
            row.iter_mut().for_each(|b| *b = BACKGROUND);
            let mut x0 = 0;
            for (s, &w) in states.iter_mut().zip(&widths) {
                if y < s.shrink.size().1 {
                    s.next()?;
                    let out = &mut row[x0 * 3..(x0 + w) * 3];
                    paint(&s.ready, out, &display, scale.as_ref());
                }
                x0 += w + GAP;
            }
            if let Some(sc) = &scale {
                let at = (legend_x + GAP) * 3;
                legend_row(sc, y, panels_h, &mut row[at..at + LEGEND_WIDTH * 3]);
            }
            put(&row)?;
        }
        stream.finish().map_err(png_err)?;
    }
    temp.commit()
}

/// A panel being drawn: its rows, its shrink, its next output row.
struct PanelState<'a> {
    rows: Rows<'a>,
    shrink: AreaShrink,
    input: Vec<f64>,
    ready: Vec<f64>,
    label: String,
}

impl PanelState<'_> {
    /// Read input rows until the shrink gives the next output row.
    fn next(&mut self) -> Result<()> {
        loop {
            self.rows.next(&mut self.input)?;
            let mut done = false;
            let ready = &mut self.ready;
            self.shrink.push(&self.input, |r| {
                ready.copy_from_slice(r);
                done = true;
                Ok::<(), Error>(())
            })?;
            if done {
                return Ok(());
            }
        }
    }
}

/// Output row `px` (`K` values a pixel) as sRGB bytes into `out`.
fn paint(px: &[f64], out: &mut [u8], display: &Display, scale: Option<&LogScale>) {
    for (p, o) in px.chunks_exact(K).zip(out.chunks_exact_mut(3)) {
        match scale {
            Some(s) => o.copy_from_slice(&s.colour(p[3])),
            None => {
                for k in 0..3 {
                    o[k] = (display.encode(p[k]) * 255.0 + 0.5) as u8;
                }
            }
        }
    }
}

/// The rows of a crop of an image, or of the difference of two, `K` values
/// a pixel: R, G, B and the measure false colour shows (the luminance; for
/// a difference, the luminance-weighted sum of each channel's absolute
/// difference, in all four).
struct Rows<'a> {
    a: Region<'a>,
    b: Option<Region<'a>>,
    crop: Crop,
    /// Each channel's luminance weight.
    weights: Vec<f64>,
    /// The channels shown as R, G, B (one three times for a grey image).
    rgb: [usize; 3],
}

impl<'a> Rows<'a> {
    fn image(input: &'a ExrInput, crop: Crop) -> Self {
        let names = input.channels();
        let pick = |want: &str| {
            names
                .iter()
                .position(|n| n.rsplit('.').next() == Some(want))
        };
        let rgb = match (pick("R"), pick("G"), pick("B")) {
            (Some(r), Some(g), Some(b)) => [r, g, b],
            _ => [0, 0, 0],
        };
        Rows {
            a: Region::new(input, crop),
            b: None,
            crop,
            weights: input.luminance(),
            rgb,
        }
    }

    fn diff(a: &'a ExrInput, b: &'a ExrInput, crop: Crop) -> Self {
        Rows {
            b: Some(Region::new(b, crop)),
            ..Rows::image(a, crop)
        }
    }

    /// The next row into `out` (`crop.w * K` values).
    fn next(&mut self, out: &mut [f64]) -> Result<()> {
        let (c, w) = (self.crop, self.a.width);
        let ra = self.a.next()?;
        let rb = match &mut self.b {
            Some(b) => Some(b.next()?),
            None => None,
        };
        for (x, o) in out.chunks_exact_mut(K).enumerate() {
            let at = c.x + x;
            let v = |row: &[f32], ch: usize| row[ch * w + at] as f64;
            match rb {
                None => {
                    for (o, &ch) in o.iter_mut().zip(&self.rgb) {
                        *o = v(ra, ch);
                    }
                    o[3] = (self.weights.iter().enumerate())
                        .map(|(ch, wt)| wt * v(ra, ch))
                        .sum();
                }
                Some(rb) => {
                    let d: f64 = (self.weights.iter().enumerate())
                        .map(|(ch, wt)| wt * (v(ra, ch) - v(rb, ch)).abs())
                        .sum();
                    o.iter_mut().for_each(|o| *o = d);
                }
            }
        }
        Ok(())
    }
}

/// The rows `crop` covers of an input, one at a time, all its channels.
struct Region<'a> {
    src: InputSource<'a>,
    strip: Option<Strip>,
    /// The next row of `strip` to give.
    at: usize,
    /// The image row wanted next.
    y: usize,
    width: usize,
    row_len: usize,
    path: &'a Path,
}

impl<'a> Region<'a> {
    fn new(input: &'a ExrInput, crop: Crop) -> Self {
        Region {
            src: input.source_from(crop.y),
            strip: None,
            at: 0,
            y: crop.y,
            width: input.size().0,
            row_len: input.size().0 * input.channels().len(),
            path: input.path(),
        }
    }

    /// The next row: each channel's `width` values after the other's.
    fn next(&mut self) -> Result<&[f32]> {
        loop {
            match &self.strip {
                Some(s) if self.at < s.rows => {
                    if s.y0 + self.at == self.y {
                        break;
                    }
                    self.at += 1; // above the crop
                }
                _ => {
                    self.strip = self.src.next_strip(STRIP_ROWS)?;
                    self.at = 0;
                    if self.strip.is_none() {
                        return Err(Error::InvalidFile {
                            path: self.path.into(),
                            reason: format!("it ends before row {}", self.y),
                        });
                    }
                }
            }
        }
        let from = self.at * self.row_len;
        self.at += 1;
        self.y += 1;
        let s = (self.strip.as_ref()).ok_or_else(|| Error::Internal("no strip".into()))?;
        Ok(&s.data[from..from + self.row_len])
    }
}
