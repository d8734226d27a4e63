//! The lab's plots: scatter and line charts drawn to PNG (8x8 text into an
//! RGB buffer, no font engine) and to SVG from one description, with the
//! axes named, figures at round values, and the legend in a band of its own
//! below the plot, where it cannot cover a point or run off the edge.

use std::fmt::Write;
use std::path::Path;

use anyhow::Result;

/// An RGB colour.
pub type Rgb = (u8, u8, u8);

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    /// Filled dots.
    Dots,
    /// Dots joined by a line, in the order given.
    Line,
    /// Crosses (marked settings).
    Crosses,
    /// Open rings around points.
    Rings,
}

/// One series: its name in the legend (empty: none), colour, style, points
/// and, optionally, a label beside each point.
#[derive(Clone, Debug)]
pub struct Series {
    /// The legend's text.
    pub name: String,
    /// Its colour.
    pub colour: Rgb,
    /// How it is drawn.
    pub style: Style,
    /// `(x, y)`.
    pub points: Vec<(f64, f64)>,
    /// A label per point (empty: none).
    pub labels: Vec<String>,
}

impl Series {
    /// A series without point labels.
    pub fn new(name: &str, colour: Rgb, style: Style, points: Vec<(f64, f64)>) -> Self {
        Series {
            name: name.into(),
            colour,
            style,
            points,
            labels: Vec::new(),
        }
    }
}

/// One chart: a title, the axes' names and scales, and its series.
#[derive(Clone, Debug, Default)]
pub struct Chart {
    /// Above the plot.
    pub title: String,
    /// The horizontal axis's name.
    pub x_label: String,
    /// The vertical axis's name.
    pub y_label: String,
    /// Logarithmic axes.
    pub log: (bool, bool),
    /// What it shows.
    pub series: Vec<Series>,
}

/// A panel's size in pixels, and its margins.
const PANEL: (usize, usize) = (620, 440);
const LEFT: usize = 76;
const RIGHT: usize = 24;
const TOP: usize = 40;
const BOTTOM: usize = 44;
/// Height of one line of the legend band.
const LEGEND_LINE: usize = 14;
const GRID: Rgb = (225, 225, 225);
const INK: Rgb = (0, 0, 0);

/// Where things go on one panel.
struct Frame {
    x0: usize,
    plot: (f64, f64, f64, f64),
    range: (f64, f64, f64, f64),
    log: (bool, bool),
}

impl Frame {
    fn new(chart: &Chart, x0: usize) -> Self {
        let pts = chart.series.iter().flat_map(|s| s.points.iter());
        let fold = |f: fn(&(f64, f64)) -> f64, log: bool| {
            let (a, b) = pts
                .clone()
                .map(f)
                .filter(|v| v.is_finite() && (!log || *v > 0.0))
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                    (a.min(v), b.max(v))
                });
            pad(a, b, log)
        };
        let (xa, xb) = fold(|p| p.0, chart.log.0);
        let (ya, yb) = fold(|p| p.1, chart.log.1);
        Frame {
            x0,
            plot: (
                (x0 + LEFT) as f64,
                TOP as f64,
                (PANEL.0 - LEFT - RIGHT) as f64,
                (PANEL.1 - TOP - BOTTOM) as f64,
            ),
            range: (xa, xb, ya, yb),
            log: chart.log,
        }
    }

    /// Pixel position of `(x, y)`.
    fn at(&self, (x, y): (f64, f64)) -> (f64, f64) {
        let (xa, xb, ya, yb) = self.range;
        let f = |v: f64, a: f64, b: f64, log: bool| {
            if log {
                (v / a).ln() / (b / a).ln()
            } else {
                (v - a) / (b - a)
            }
        };
        let (px, py, pw, ph) = self.plot;
        (
            px + f(x, xa, xb, self.log.0) * pw,
            py + (1.0 - f(y, ya, yb, self.log.1)) * ph,
        )
    }
}

/// The range `a..b` with a margin (a factor on a log axis), never empty.
fn pad(a: f64, b: f64, log: bool) -> (f64, f64) {
    if !a.is_finite() {
        return if log { (1.0, 10.0) } else { (0.0, 1.0) };
    }
    if log {
        let r = (b / a).max(1.01).powf(0.06);
        (a / r, b * r)
    } else {
        let m = ((b - a) * 0.06).max(a.abs() * 1e-3).max(1e-12);
        (a - m, b + m)
    }
}

/// Round figures for an axis over `a..b`: 1, 2, 5 x 10^k steps (linear),
/// or the powers of ten and their 2 and 5 multiples (logarithmic) where
/// fewer than three powers fall inside.
fn ticks(a: f64, b: f64, log: bool) -> Vec<f64> {
    if log {
        let (lo, hi) = (a.log10().floor() as i32, b.log10().ceil() as i32);
        let decades: Vec<f64> = (lo..=hi).map(|k| 10f64.powi(k)).collect();
        let inside = |v: &f64| *v >= a && *v <= b;
        if decades.iter().filter(|v| inside(v)).count() >= 3 {
            return decades.into_iter().filter(inside).collect();
        }
        let mut v: Vec<f64> = decades
            .iter()
            .flat_map(|d| [1.0, 2.0, 5.0].map(|m| m * d))
            .filter(inside)
            .collect();
        if v.len() < 3 {
            v = (0..=4).map(|k| a * (b / a).powf(k as f64 / 4.0)).collect();
        }
        return v;
    }
    let raw = (b - a) / 5.0;
    let p = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * p)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * p);
    let first = (a / step).ceil() as i64;
    (0..12)
        .map(|k| (first + k) as f64 * step)
        .take_while(|v| *v <= b)
        .collect()
}

/// A figure as short text: as many decimals as the ticks' step needs.
fn figure(v: f64, all: &[f64]) -> String {
    let step = all
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .fold(f64::INFINITY, f64::min);
    if v != 0.0 && (v.abs() >= 1e5 || v.abs() < 1e-3) {
        return format!("{v:.1e}");
    }
    let d = if step.is_finite() && step > 0.0 {
        (-step.log10().floor()).max(0.0) as usize
    } else {
        2
    };
    format!("{v:.d$}", d = d.min(6))
}

/// The legend's entries, laid out in lines that fit a panel: each entry's
/// position (x from the panel's left, line index).
fn legend_layout(chart: &Chart) -> Vec<(usize, usize, &Series)> {
    let mut out = Vec::new();
    let (mut x, mut line) = (LEFT, 0);
    for s in chart.series.iter().filter(|s| !s.name.is_empty()) {
        let w = 8 * (s.name.chars().count() + 3);
        if x + w > PANEL.0 - 8 && x > LEFT {
            x = LEFT;
            line += 1;
        }
        out.push((x, line, s));
        x += w + 8;
    }
    out
}

/// Write `charts` side by side as `stem.png` and `stem.svg`.
pub fn save(charts: &[Chart], stem: &Path) -> Result<()> {
    let lines = charts
        .iter()
        .map(|c| legend_layout(c).last().map_or(0, |e| e.1 + 1))
        .max()
        .unwrap_or(0);
    let (w, h) = (PANEL.0 * charts.len(), PANEL.1 + lines * LEGEND_LINE + 8);
    let mut png = Png::new(w, h);
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="monospace" font-size="12"><rect width="{w}" height="{h}" fill="white"/>"#
    );
    for (k, chart) in charts.iter().enumerate() {
        draw(chart, &Frame::new(chart, k * PANEL.0), &mut png, &mut svg);
    }
    svg.push_str("</svg>\n");
    std::fs::write(stem.with_extension("svg"), svg)?;
    crate::canvas::save_png(&stem.with_extension("png"), &png.buf, w, h)
}

fn hex(c: Rgb) -> String {
    format!("#{:02x}{:02x}{:02x}", c.0, c.1, c.2)
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// Text in both: `anchor` 0 left, 1 centre, 2 right of `x`.
fn text(png: &mut Png, svg: &mut String, (x, y): (f64, f64), s: &str, c: Rgb, anchor: u8) {
    let width = 8.0 * s.chars().count() as f64;
    let left = x - width * f64::from(anchor) / 2.0;
    crate::canvas::text(
        &mut png.buf,
        png.w,
        left.max(0.0) as usize,
        (y - 4.0).max(0.0) as usize,
        s,
        c,
    );
    let a = ["start", "middle", "end"][anchor as usize];
    let _ = writeln!(
        svg,
        r#"<text x="{x:.1}" y="{:.1}" text-anchor="{a}" fill="{}">{}</text>"#,
        y + 4.0,
        hex(c),
        escape(s)
    );
}

fn line(png: &mut Png, svg: &mut String, a: (f64, f64), b: (f64, f64), c: Rgb, width: f64) {
    png.line(a, b, c, width);
    let _ = writeln!(
        svg,
        r#"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{}" stroke-width="{width}"/>"#,
        a.0,
        a.1,
        b.0,
        b.1,
        hex(c)
    );
}

fn marker(png: &mut Png, svg: &mut String, p: (f64, f64), style: Style, c: Rgb) {
    match style {
        Style::Dots | Style::Line => {
            png.disc(p, 3.5, c);
            let _ = writeln!(
                svg,
                r#"<circle cx="{:.1}" cy="{:.1}" r="3.5" fill="{}"/>"#,
                p.0,
                p.1,
                hex(c)
            );
        }
        Style::Rings => {
            png.ring(p, 7.0, c);
            let _ = writeln!(
                svg,
                r#"<circle cx="{:.1}" cy="{:.1}" r="7" fill="none" stroke="{}"/>"#,
                p.0,
                p.1,
                hex(c)
            );
        }
        Style::Crosses => {
            for d in [(-6.0, -6.0, 6.0, 6.0), (-6.0, 6.0, 6.0, -6.0)] {
                line(
                    png,
                    svg,
                    (p.0 + d.0, p.1 + d.1),
                    (p.0 + d.2, p.1 + d.3),
                    c,
                    3.0,
                );
            }
        }
    }
}

fn draw(chart: &Chart, f: &Frame, png: &mut Png, svg: &mut String) {
    let (px, py, pw, ph) = f.plot;
    let (xa, xb, ya, yb) = f.range;
    let xt = ticks(xa, xb, f.log.0);
    let yt = ticks(ya, yb, f.log.1);
    for &t in &xt {
        let (x, _) = f.at((t, ya));
        line(png, svg, (x, py), (x, py + ph), GRID, 1.0);
        text(png, svg, (x, py + ph + 12.0), &figure(t, &xt), INK, 1);
    }
    for &t in &yt {
        let (_, y) = f.at((xa, t));
        line(png, svg, (px, y), (px + pw, y), GRID, 1.0);
        text(png, svg, (px - 6.0, y), &figure(t, &yt), INK, 2);
    }
    for (a, b) in [
        ((px, py), (px, py + ph)),
        ((px, py + ph), (px + pw, py + ph)),
    ] {
        line(png, svg, a, b, INK, 1.0);
    }
    let x0 = f.x0 as f64;
    text(png, svg, (x0 + 8.0, 10.0), &chart.title, INK, 0);
    text(
        png,
        svg,
        (px, 26.0),
        &format!("^ {}", chart.y_label),
        INK,
        0,
    );
    text(
        png,
        svg,
        (px + pw / 2.0, py + ph + 30.0),
        &format!("{} >", chart.x_label),
        INK,
        1,
    );
    let mut placed: Vec<(f64, f64, f64)> = Vec::new();
    for s in &chart.series {
        let at: Vec<(f64, f64)> = s.points.iter().map(|&p| f.at(p)).collect();
        if s.style == Style::Line {
            for w in at.windows(2) {
                line(png, svg, w[0], w[1], s.colour, 2.0);
            }
        }
        for &p in &at {
            marker(png, svg, p, s.style, s.colour);
        }
        for (p, label) in at.iter().zip(&s.labels) {
            // Above and to the right, clear of the point and of a line
            // through it; below, or further off, where another label is.
            let w = 8.0 * label.chars().count() as f64;
            let free = |x: f64, y: f64| {
                (placed.iter()).all(|&(a, b, lw)| x + w < a || a + lw < x || (y - b).abs() >= 10.0)
            };
            let (x, y) = [-12.0, 14.0, -26.0, 28.0]
                .into_iter()
                .map(|dy| (p.0 + 8.0, p.1 + dy))
                .find(|&(x, y)| free(x, y))
                .unwrap_or((p.0 + 8.0, p.1 - 12.0));
            placed.push((x, y, w));
            text(png, svg, (x, y), label, s.colour, 0);
        }
    }
    for (x, l, s) in legend_layout(chart) {
        let (x, y) = (
            x0 + x as f64,
            PANEL.1 as f64 + 4.0 + (l * LEGEND_LINE) as f64,
        );
        marker(png, svg, (x + 6.0, y), s.style, s.colour);
        text(png, svg, (x + 18.0, y), &s.name, s.colour, 0);
    }
}

/// An RGB buffer with the few shapes the charts need.
struct Png {
    buf: Vec<u8>,
    w: usize,
    h: usize,
}

impl Png {
    fn new(w: usize, h: usize) -> Self {
        Png {
            buf: vec![255; w * h * 3],
            w,
            h,
        }
    }

    fn put(&mut self, x: i64, y: i64, c: Rgb) {
        if x >= 0 && y >= 0 && (x as usize) < self.w && (y as usize) < self.h {
            let at = (y as usize * self.w + x as usize) * 3;
            self.buf[at..at + 3].copy_from_slice(&[c.0, c.1, c.2]);
        }
    }

    fn line(&mut self, a: (f64, f64), b: (f64, f64), c: Rgb, width: f64) {
        let n = (b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil().max(1.0) as usize;
        let r = (width / 2.0).floor() as i64;
        for k in 0..=n {
            let t = k as f64 / n as f64;
            let (x, y) = (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1));
            for dy in -r..=r {
                for dx in -r..=r {
                    self.put(x.round() as i64 + dx, y.round() as i64 + dy, c);
                }
            }
        }
    }

    fn disc(&mut self, p: (f64, f64), r: f64, c: Rgb) {
        let ri = r.ceil() as i64;
        for dy in -ri..=ri {
            for dx in -ri..=ri {
                if ((dx * dx + dy * dy) as f64) <= r * r {
                    self.put(p.0.round() as i64 + dx, p.1.round() as i64 + dy, c);
                }
            }
        }
    }

    fn ring(&mut self, p: (f64, f64), r: f64, c: Rgb) {
        for k in 0..64 {
            let a = k as f64 / 64.0 * std::f64::consts::TAU;
            self.put(
                (p.0 + r * a.cos()).round() as i64,
                (p.1 + r * a.sin()).round() as i64,
                c,
            );
        }
    }
}

/// The columns `names` of the CSV file `path` (a header line, then values
/// without quotes, as the lab writes them), row by row: what a replot reads.
pub fn csv_columns(path: &Path, names: &[&str]) -> Result<Vec<Vec<String>>> {
    use anyhow::Context;
    let text = std::fs::read_to_string(path).with_context(|| path.display().to_string())?;
    let mut lines = text.lines();
    let header: Vec<&str> = (lines.next())
        .with_context(|| format!("{}: empty", path.display()))?
        .split(',')
        .collect();
    let at: Vec<usize> = (names.iter())
        .map(|n| {
            (header.iter().position(|h| h == n))
                .with_context(|| format!("{}: no column {n}", path.display()))
        })
        .collect::<Result<_>>()?;
    Ok(lines
        .map(|line| {
            let f: Vec<&str> = line.split(',').collect();
            at.iter()
                .map(|&i| f.get(i).unwrap_or(&"").to_string())
                .collect()
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_and_inside() {
        let t = ticks(0.0, 1.0, false);
        let shown: Vec<String> = t.iter().map(|&v| figure(v, &t)).collect();
        assert_eq!(shown, ["0.0", "0.2", "0.4", "0.6", "0.8", "1.0"]);
        assert_eq!(ticks(0.5, 2000.0, true), vec![1.0, 10.0, 100.0, 1000.0]);
        let t = ticks(0.3, 1.5, true);
        assert!(
            t.len() >= 3 && t.iter().all(|v| (0.3..=1.5).contains(v)),
            "{t:?}"
        );
    }

    #[test]
    fn a_chart_writes_both_files() {
        let dir = tempfile::tempdir().unwrap();
        let chart = Chart {
            title: "t".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            log: (false, true),
            series: vec![Series {
                name: "a long legend entry that would once have run off the edge".into(),
                colour: (200, 0, 0),
                style: Style::Line,
                points: vec![(1.0, 1.0), (2.0, 10.0)],
                labels: vec!["first".into()],
            }],
        };
        save(&[chart], &dir.path().join("c")).unwrap();
        let svg = std::fs::read_to_string(dir.path().join("c.svg")).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("a long legend entry"));
        assert!(std::fs::metadata(dir.path().join("c.png")).unwrap().len() > 0);
    }
}
