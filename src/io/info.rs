//! `epfilt info`: what an EXR file (or a Radiance picture) holds, as text or
//! JSON ([`FileInfo`]), and every header attribute as stored
//! ([`PartInfo::attributes`], as `oiiotool --info -v` lists them).

use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::Path;

use serde::Serialize;

use super::mapped::MappedFile;
use super::{compression_name, luminance_weights};
use crate::filter::channels::ChannelRule;

/// What a file holds.
#[derive(Clone, Debug, Serialize)]
pub struct FileInfo {
    /// The path as given (`-` for standard input).
    pub path: String,
    /// `exr` or `hdr`.
    pub format: String,
    /// Every part (a Radiance picture has one).
    pub parts: Vec<PartInfo>,
    /// A Radiance picture's own header.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radiance: Option<RadianceInfo>,
}

/// One part of a file.
#[derive(Clone, Debug, Serialize)]
pub struct PartInfo {
    /// Index in the file.
    pub index: usize,
    /// The part's `name` attribute, if any.
    pub name: Option<String>,
    /// Data window size.
    pub width: usize,
    /// Data window rows.
    pub height: usize,
    /// Data window: x0, y0, x1, y1 (inclusive).
    pub data_window: [i64; 4],
    /// Display window: x0, y0, x1, y1 (inclusive).
    pub display_window: [i64; 4],
    /// Compression name.
    pub compression: String,
    /// `scan lines (N per block)` or `tiles WxH LEVELS`.
    pub layout: String,
    /// Line order.
    pub line_order: String,
    /// Deep data.
    pub deep: bool,
    /// Channels: name, sample type, sub-sampling.
    pub channels: Vec<ChannelInfo>,
    /// The channels `filter` filters by default (empty: none, see `note`).
    pub filtered: Vec<String>,
    /// Channels carried beside the beauty, with their default rule.
    pub carried: Vec<(String, String)>,
    /// Channels `filter` leaves out by default.
    pub dropped: Vec<String>,
    /// Views of a multi-view file (`multiView`), the default first.
    pub views: Vec<String>,
    /// Why nothing is filtered by default, when so.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
    /// How `filter` filters it without --method or --supersample
    /// ([`crate::io::verdict()`]), or why it cannot say.
    pub verdict: String,
    /// The guide passes found by name ([`crate::io::guides`]): `none`, or
    /// each kind with its channels.
    pub guides: String,
    /// The same by kind (`emission`, `albedo`, `normal`, `depth`): its
    /// channels, in R G B or X Y Z order.
    pub guide_channels: BTreeMap<String, Vec<String>>,
    /// Luminance weights of R, G, B.
    pub luminance: [f64; 3],
    /// Whether they come from the file's chromaticities (else Rec. 709).
    pub luminance_from_chromaticities: bool,
    /// Pixel aspect ratio.
    pub pixel_aspect: f32,
    /// Every header attribute as stored: name -> (type, value in words).
    pub attributes: BTreeMap<String, (String, String)>,
}

/// One channel.
#[derive(Clone, Debug, Serialize)]
pub struct ChannelInfo {
    /// Full name.
    pub name: String,
    /// `half`, `float` or `uint`.
    #[serde(rename = "type")]
    pub sample_type: String,
    /// x and y sub-sampling.
    pub sampling: [usize; 2],
}

/// A Radiance picture's header.
#[derive(Clone, Debug, Serialize)]
pub struct RadianceInfo {
    /// XYZE rather than RGBE.
    pub xyze: bool,
    /// What stored values were multiplied by (EXPOSURE, COLORCORR).
    pub scale: [f64; 3],
    /// Whether PRIMARIES= set the luminance weights.
    pub primaries: bool,
    /// The header's lines.
    pub lines: Vec<String>,
}

/// Describe `path` (`-`: standard input).
pub fn describe(path: &Path) -> crate::Result<FileInfo> {
    let map = MappedFile::open(path)?;
    if super::rgbe::is_rgbe(map.bytes()) {
        return describe_rgbe(path);
    }
    if super::pfm::is_pfm(map.bytes()) {
        return describe_pfm(path);
    }
    let meta = super::reader::parse_headers(path, map.bytes())?;
    let raw = raw_attributes(map.bytes());
    let parts = meta
        .headers
        .iter()
        .enumerate()
        .map(|(i, h)| describe_part(path, i, h, raw.get(i).cloned().unwrap_or_default()))
        .collect();
    Ok(FileInfo {
        path: path.display().to_string(),
        format: "exr".into(),
        parts,
        radiance: None,
    })
}

fn window(b: exr::meta::attribute::IntegerBounds) -> [i64; 4] {
    let (x, y) = (b.position.0 as i64, b.position.1 as i64);
    [x, y, x + b.size.0 as i64 - 1, y + b.size.1 as i64 - 1]
}

fn type_name(t: exr::meta::attribute::SampleType) -> &'static str {
    match t {
        exr::meta::attribute::SampleType::F16 => "half",
        exr::meta::attribute::SampleType::F32 => "float",
        exr::meta::attribute::SampleType::U32 => "uint",
    }
}

fn describe_part(
    path: &Path,
    index: usize,
    h: &exr::meta::header::Header,
    attributes: BTreeMap<String, (String, String)>,
) -> PartInfo {
    let layout = match h.blocks {
        exr::meta::BlockDescription::ScanLines => format!(
            "scan lines ({} per block)",
            h.compression.scan_lines_per_block()
        ),
        exr::meta::BlockDescription::Tiles(t) => format!(
            "tiles {}x{} {:?}",
            t.tile_size.0, t.tile_size.1, t.level_mode
        ),
    };
    let channels = h
        .channels
        .list
        .iter()
        .map(|c| ChannelInfo {
            name: c.name.to_string(),
            sample_type: type_name(c.sample_type).into(),
            sampling: [c.sampling.0, c.sampling.1],
        })
        .collect();
    let (mut filtered, mut carried, mut dropped, mut note) = (vec![], vec![], vec![], None);
    let scope = super::reader::view_scope(path, h, None, false).unwrap_or_default();
    match super::reader::choose_channels(path, h, None, &scope) {
        Ok((chosen, rest)) => {
            filtered = chosen.iter().map(|c| c.name.clone()).collect();
            // What `filter` does with the rest by default (--channel-rule
            // changes it; median and alpha-trim carry nothing).
            for name in &rest {
                let uint = h.channels.list.iter().any(|c| {
                    c.name.to_string() == *name
                        && c.sample_type == exr::meta::attribute::SampleType::U32
                });
                match crate::filter::channels::rule_for(name, uint, &[], &scope) {
                    ChannelRule::Drop => dropped.push(name.clone()),
                    r => carried.push((name.clone(), r.name().to_string())),
                }
            }
        }
        Err(crate::Error::Unsupported { reason, .. }) => note = Some(format!("({reason})")),
        Err(e) => {
            let e = e.to_string();
            let prefix = format!("{}: ", path.display());
            note = Some(format!("by default ({})", e.trim_start_matches(&prefix)));
        }
    }
    let ch = h.shared_attributes.chromaticities.as_ref();
    let (verdict, (guides, guide_channels), emission) = verdict_and_guides(path, h, &filtered);
    // The emission guide's channels are carried as they are (filter's plan).
    for (name, rule) in carried.iter_mut() {
        if emission.contains(name) {
            *rule = "average (the emission guide)".into();
        }
    }
    PartInfo {
        index,
        name: h.own_attributes.layer_name.as_ref().map(|n| n.to_string()),
        width: h.layer_size.0,
        height: h.layer_size.1,
        data_window: window(h.data_window()),
        display_window: window(h.shared_attributes.display_window),
        compression: compression_name(h.compression),
        layout,
        line_order: format!("{:?}", h.line_order),
        deep: h.deep,
        channels,
        filtered,
        carried,
        dropped,
        views: h
            .own_attributes
            .multi_view_names
            .iter()
            .flatten()
            .map(|t| t.to_string())
            .collect(),
        note,
        verdict,
        guides,
        guide_channels,
        luminance: luminance_weights(ch),
        luminance_from_chromaticities: ch.is_some(),
        pixel_aspect: h.shared_attributes.pixel_aspect,
        attributes,
    }
}

/// The guides found, in words and by kind.
type Guides = (String, BTreeMap<String, Vec<String>>);

/// What `filter` decides for a part (header `h`, beauty channels
/// `filtered`) and the guides it finds there, in words, and the emission
/// guide's channels.
fn verdict_and_guides(
    path: &Path,
    h: &exr::meta::header::Header,
    filtered: &[String],
) -> (String, Guides, Vec<String>) {
    let words = |e: crate::Error| {
        let e = e.to_string();
        let prefix = format!("{}: ", path.display());
        e.trim_start_matches(&prefix).to_string()
    };
    let verdict = match super::verdict(path, h, &super::StatsRequest::default(), None, None) {
        Ok(v) => v.line(),
        Err(e) => format!("none ({})", words(e)),
    };
    let scope = super::reader::view_scope(path, h, None, false).unwrap_or_default();
    let beauty: Vec<String> = filtered
        .iter()
        .filter(|c| !c.rsplit('.').next().unwrap_or(c).eq_ignore_ascii_case("a"))
        .cloned()
        .collect();
    let (guides, emission) =
        match super::find_guides(path, h, &beauty, &super::GuideRequest::default(), &scope) {
            Ok(g) => ((g.describe(), g.by_kind()), g.emission.unwrap_or_default()),
            Err(e) => (
                (format!("none ({})", words(e)), BTreeMap::new()),
                Vec::new(),
            ),
        };
    (verdict, guides, emission)
}

fn describe_rgbe(path: &Path) -> crate::Result<FileInfo> {
    let input = super::ExrInput::open(path, None)?;
    let r = input
        .rgbe()
        .ok_or_else(|| crate::Error::Internal("not a picture".into()))?;
    let names: Vec<&str> = if r.xyze {
        vec!["X", "Y", "Z"]
    } else {
        vec!["R", "G", "B"]
    };
    let lw = luminance_weights(input.header().shared_attributes.chromaticities.as_ref());
    let part = PartInfo {
        index: 0,
        name: None,
        width: r.w,
        height: r.h,
        data_window: [0, 0, r.w as i64 - 1, r.h as i64 - 1],
        display_window: [0, 0, r.w as i64 - 1, r.h as i64 - 1],
        compression: "rgbe".into(),
        layout: "scan lines".into(),
        line_order: "Increasing".into(),
        deep: false,
        channels: names
            .iter()
            .map(|n| ChannelInfo {
                name: n.to_string(),
                sample_type: "rgbe".into(),
                sampling: [1, 1],
            })
            .collect(),
        filtered: names.iter().map(|n| n.to_string()).collect(),
        carried: Vec::new(),
        dropped: Vec::new(),
        views: Vec::new(),
        note: None,
        verdict: verdict_and_guides(path, input.header(), &[]).0,
        guides: "none".into(),
        guide_channels: BTreeMap::new(),
        luminance: lw,
        luminance_from_chromaticities: r.primaries.is_some(),
        pixel_aspect: 1.0,
        attributes: r
            .lines
            .iter()
            .enumerate()
            .map(|(i, l)| (format!("line {:03}", i + 1), ("text".into(), l.clone())))
            .collect(),
    };
    Ok(FileInfo {
        path: path.display().to_string(),
        format: "hdr".into(),
        parts: vec![part],
        radiance: Some(RadianceInfo {
            xyze: r.xyze,
            scale: r.scale,
            primaries: r.primaries.is_some(),
            lines: r.lines.clone(),
        }),
    })
}

fn describe_pfm(path: &Path) -> crate::Result<FileInfo> {
    let input = super::ExrInput::open(path, None)?;
    let (w, h) = input.size();
    let names = input.channels();
    let part = PartInfo {
        index: 0,
        name: None,
        width: w,
        height: h,
        data_window: [0, 0, w as i64 - 1, h as i64 - 1],
        display_window: [0, 0, w as i64 - 1, h as i64 - 1],
        compression: "none".into(),
        layout: "scan lines, bottom row first".into(),
        line_order: "Decreasing".into(),
        deep: false,
        channels: (names.iter())
            .map(|n| ChannelInfo {
                name: n.clone(),
                sample_type: "float".into(),
                sampling: [1, 1],
            })
            .collect(),
        filtered: names.clone(),
        carried: Vec::new(),
        dropped: Vec::new(),
        views: Vec::new(),
        note: None,
        verdict: verdict_and_guides(path, input.header(), &[]).0,
        guides: "none".into(),
        guide_channels: BTreeMap::new(),
        luminance: luminance_weights(None),
        luminance_from_chromaticities: false,
        pixel_aspect: 1.0,
        attributes: Default::default(),
    };
    Ok(FileInfo {
        path: path.display().to_string(),
        format: "pfm".into(),
        parts: vec![part],
        radiance: None,
    })
}

impl FileInfo {
    /// The human description; with `attributes`, every header attribute too.
    pub fn text(&self, attributes: bool) -> String {
        match &self.radiance {
            Some(r) => self.rgbe_text(r),
            None => self.exr_text(attributes),
        }
    }

    fn exr_text(&self, attributes: bool) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "{}: {} part(s)", self.path, self.parts.len());
        for p in &self.parts {
            let [x0, y0, x1, y1] = p.data_window;
            let [a0, b0, a1, b1] = p.display_window;
            let _ = writeln!(
                s,
                "part {}{}: {}x{} data window ({x0}, {y0})..({x1}, {y1}), display window ({a0}, {b0})..({a1}, {b1})",
                p.index,
                p.name.as_ref().map(|n| format!(" {n:?}")).unwrap_or_default(),
                p.width,
                p.height,
            );
            let _ = writeln!(
                s,
                "  compression {}, {}, line order {}{}",
                p.compression,
                p.layout,
                p.line_order,
                if p.deep { ", DEEP" } else { "" }
            );
            let chans: Vec<String> = p
                .channels
                .iter()
                .map(|c| {
                    if c.sampling != [1, 1] {
                        format!(
                            "{} {} ({}x{} subsampled)",
                            c.name, c.sample_type, c.sampling[0], c.sampling[1]
                        )
                    } else {
                        format!("{} {}", c.name, c.sample_type)
                    }
                })
                .collect();
            let _ = writeln!(s, "  channels: {}", chans.join(", "));
            if p.views.len() > 1 {
                let _ = writeln!(
                    s,
                    "  views: {} (filter --view NAME|all; by default the first)",
                    p.views.join(", ")
                );
            }
            match &p.note {
                Some(n) => {
                    let _ = writeln!(s, "  filtered: nothing {n}");
                }
                None => {
                    let _ = writeln!(s, "  filtered: {}", p.filtered.join(", "));
                    if !p.carried.is_empty() {
                        let c: Vec<String> =
                            p.carried.iter().map(|(n, r)| format!("{n} {r}")).collect();
                        let _ = writeln!(s, "  carried: {}", c.join(", "));
                    }
                    if !p.dropped.is_empty() {
                        let _ = writeln!(s, "  dropped: {}", p.dropped.join(", "));
                    }
                }
            }
            let _ = writeln!(s, "  filter by default: {}", p.verdict);
            let _ = writeln!(s, "  guides: {}", p.guides);
            let lw = p.luminance;
            let _ = writeln!(
                s,
                "  luminance Y = {:.4} R + {:.4} G + {:.4} B ({}), pixel aspect {}",
                lw[0],
                lw[1],
                lw[2],
                if p.luminance_from_chromaticities {
                    "from chromaticities"
                } else {
                    "Rec. 709 primaries"
                },
                p.pixel_aspect
            );
            if attributes {
                let _ = writeln!(s, "  attributes:");
                for (name, (ty, value)) in &p.attributes {
                    let _ = writeln!(s, "    {name} ({ty}): {value}");
                }
            }
        }
        if self.parts.len() > 1 {
            let _ = writeln!(
                s,
                "filter: choose a part with --part NAME|INDEX (at S = 1 the others are copied bit for bit, at S > 1 left out), or filter every part with --part all"
            );
        }
        s
    }

    fn rgbe_text(&self, r: &RadianceInfo) -> String {
        let mut s = String::new();
        let Some(p) = self.parts.first() else {
            return s;
        };
        let _ = writeln!(
            s,
            "{}: Radiance picture, {}x{}, {}",
            self.path,
            p.width,
            p.height,
            if r.xyze {
                "XYZE (channels X, Y, Z)"
            } else {
                "RGBE (channels R, G, B)"
            }
        );
        let _ = writeln!(
            s,
            "  stored values x {} (EXPOSURE and COLORCORR; divided out on read)",
            if r.scale[0] == r.scale[1] && r.scale[1] == r.scale[2] {
                format!("{}", r.scale[0])
            } else {
                format!("{:?}", r.scale)
            }
        );
        let _ = writeln!(s, "  filter by default: {}", p.verdict);
        let lw = p.luminance;
        let _ = writeln!(
            s,
            "  luminance Y = {:.4} R + {:.4} G + {:.4} B ({})",
            lw[0],
            lw[1],
            lw[2],
            if r.primaries {
                "from PRIMARIES"
            } else {
                "Rec. 709 primaries"
            }
        );
        for l in &r.lines {
            let _ = writeln!(s, "  header: {l}");
        }
        s
    }
}

/// A human description of an EXR file or Radiance picture.
pub fn info(path: &Path) -> crate::Result<String> {
    Ok(describe(path)?.text(false))
}

/// Every attribute of every header of an EXR file, read from its bytes as
/// stored (name -> (type, value in words)): the `exr` crate's parsed header
/// keeps the attributes it knows in fields of its own, so the file is read
/// here as the format describes it. Damaged bytes end the list early.
fn raw_attributes(bytes: &[u8]) -> Vec<BTreeMap<String, (String, String)>> {
    let mut parts = Vec::new();
    if bytes.len() < 8 {
        return parts;
    }
    let multipart = bytes[5] & 0x10 != 0;
    let mut at = 8;
    loop {
        let mut attrs = BTreeMap::new();
        loop {
            let Some(name) = cstr(bytes, &mut at) else {
                return parts;
            };
            if name.is_empty() {
                break;
            }
            let Some(ty) = cstr(bytes, &mut at) else {
                return parts;
            };
            let Some(size) = bytes
                .get(at..at + 4)
                .map(|b| i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            else {
                return parts;
            };
            at += 4;
            let Some(value) = usize::try_from(size)
                .ok()
                .and_then(|n| bytes.get(at..at.checked_add(n)?))
            else {
                return parts;
            };
            at += value.len();
            attrs.insert(name.clone(), (ty.clone(), attribute_text(&ty, value)));
        }
        let empty = attrs.is_empty();
        if !empty {
            parts.push(attrs);
        }
        if !multipart || empty {
            return parts;
        }
    }
}

fn cstr(bytes: &[u8], at: &mut usize) -> Option<String> {
    let rest = bytes.get(*at..)?;
    let end = rest.iter().take(256).position(|&b| b == 0)?;
    let s = String::from_utf8_lossy(&rest[..end]).into_owned();
    *at += end + 1;
    Some(s)
}

/// An attribute's value in words, by its type (OpenEXR's file layout): one
/// arm per type, the longer ones in functions of their own.
fn attribute_text(ty: &str, v: &[u8]) -> String {
    let i32s = |n: usize| -> Option<Vec<i32>> {
        (v.len() >= 4 * n).then(|| {
            (0..n)
                .map(|k| i32::from_le_bytes([v[4 * k], v[4 * k + 1], v[4 * k + 2], v[4 * k + 3]]))
                .collect()
        })
    };
    let f32s = |n: usize| -> Option<Vec<f32>> {
        (v.len() >= 4 * n).then(|| {
            (0..n)
                .map(|k| f32::from_le_bytes([v[4 * k], v[4 * k + 1], v[4 * k + 2], v[4 * k + 3]]))
                .collect()
        })
    };
    let list = |x: &[f32]| {
        x.iter()
            .map(|f| f.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let text = match ty {
        "int" => i32s(1).map(|x| x[0].to_string()),
        "float" => f32s(1).map(|x| x[0].to_string()),
        "double" => (v.len() >= 8).then(|| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&v[..8]);
            f64::from_le_bytes(b).to_string()
        }),
        "string" => Some(format!("{:?}", String::from_utf8_lossy(v))),
        "box2i" => i32s(4).map(|x| format!("({}, {}) - ({}, {})", x[0], x[1], x[2], x[3])),
        "box2f" => f32s(4).map(|x| format!("({}, {}) - ({}, {})", x[0], x[1], x[2], x[3])),
        "v2i" => i32s(2).map(|x| format!("({}, {})", x[0], x[1])),
        "v3i" => i32s(3).map(|x| format!("({}, {}, {})", x[0], x[1], x[2])),
        "v2f" => f32s(2).map(|x| format!("({})", list(&x))),
        "v3f" => f32s(3).map(|x| format!("({})", list(&x))),
        "m33f" => f32s(9).map(|x| format!("[{}]", list(&x))),
        "m44f" => f32s(16).map(|x| format!("[{}]", list(&x))),
        "chromaticities" => f32s(8).map(|x| {
            format!(
                "red ({}, {}) green ({}, {}) blue ({}, {}) white ({}, {})",
                x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7]
            )
        }),
        "rational" => i32s(2).map(|x| format!("{}/{}", x[0], x[1] as u32)),
        "compression" => v.first().map(|&c| {
            [
                "none", "rle", "zips", "zip", "piz", "pxr24", "b44", "b44a", "dwaa", "dwab",
                "htj2k256", "htj2k32",
            ]
            .get(c as usize)
            .map_or_else(|| format!("unknown ({c})"), |n| n.to_string())
        }),
        "lineOrder" => v.first().map(|&c| {
            ["increasing y", "decreasing y", "random y"]
                .get(c as usize)
                .map_or_else(|| format!("unknown ({c})"), |n| n.to_string())
        }),
        "envmap" => v.first().map(|&c| match c {
            0 => "latlong".into(),
            1 => "cube".into(),
            c => format!("unknown ({c})"),
        }),
        "deepImageState" => v.first().map(|c| c.to_string()),
        "tiledesc" => tiledesc_text(v),
        "timecode" => i32s(1).map(|x| timecode_text(x[0] as u32)),
        "keycode" => i32s(7).map(|x| {
            x.iter()
                .map(|k| k.to_string())
                .collect::<Vec<_>>()
                .join(" ")
        }),
        "preview" => i32s(2).map(|x| format!("{}x{} preview image", x[0] as u32, x[1] as u32)),
        "floatvector" => f32s(v.len() / 4).map(|x| format!("[{}]", list(&x))),
        "stringvector" => Some(stringvector_text(v)),
        "chlist" => Some(chlist_text(v)),
        _ => None,
    };
    text.unwrap_or_else(|| format!("{} bytes", v.len()))
}

/// A `tiledesc`: the tile size, the levels and their rounding.
fn tiledesc_text(v: &[u8]) -> Option<String> {
    (v.len() >= 9).then(|| {
        let x = u32::from_le_bytes([v[0], v[1], v[2], v[3]]);
        let y = u32::from_le_bytes([v[4], v[5], v[6], v[7]]);
        let level = ["one level", "mipmap", "ripmap"]
            .get((v[8] & 0x0f) as usize)
            .copied()
            .unwrap_or("unknown levels");
        let round = if v[8] >> 4 == 1 {
            "round up"
        } else {
            "round down"
        };
        format!("{x}x{y}, {level}, {round}")
    })
}

/// A SMPTE time code's time (BCD hours, minutes, seconds, frames).
fn timecode_text(t: u32) -> String {
    let bcd =
        |shift: u32, mask: u32| ((t >> shift) & mask & 0xf) + 10 * (((t >> shift) & mask) >> 4);
    format!(
        "{:02}:{:02}:{:02}:{:02}",
        bcd(24, 0x3f),
        bcd(16, 0x7f),
        bcd(8, 0x7f),
        bcd(0, 0x3f)
    )
}

/// A `stringvector`: each string, quoted.
fn stringvector_text(v: &[u8]) -> String {
    let mut out = Vec::new();
    let mut at = 0;
    while at + 4 <= v.len() {
        let n = i32::from_le_bytes([v[at], v[at + 1], v[at + 2], v[at + 3]]);
        at += 4;
        let Some(s) = usize::try_from(n).ok().and_then(|n| v.get(at..at + n)) else {
            break;
        };
        out.push(format!("{:?}", String::from_utf8_lossy(s)));
        at += s.len();
    }
    out.join(", ")
}

/// A `chlist`: each channel's name and type (and sampling, where not 1 x 1).
fn chlist_text(v: &[u8]) -> String {
    let mut out = Vec::new();
    let mut at = 0;
    while let Some(name) = cstr(v, &mut at).filter(|n| !n.is_empty()) {
        let Some(b) = v.get(at..at + 16) else { break };
        let t = i32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        let xs = i32::from_le_bytes([b[8], b[9], b[10], b[11]]);
        let ys = i32::from_le_bytes([b[12], b[13], b[14], b[15]]);
        let t = ["uint", "half", "float"]
            .get(t as usize)
            .copied()
            .unwrap_or("?");
        out.push(if (xs, ys) == (1, 1) {
            format!("{name} {t}")
        } else {
            format!("{name} {t} ({xs}x{ys})")
        });
        at += 16;
    }
    out.join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn attributes_are_read_as_stored() {
        let mut v = Vec::new();
        v.extend(1.5f32.to_le_bytes());
        assert_eq!(attribute_text("float", &v), "1.5");
        assert_eq!(attribute_text("compression", &[3]), "zip");
        assert_eq!(attribute_text("lineOrder", &[1]), "decreasing y");
        let mut b = Vec::new();
        for x in [0i32, -2, 9, 7] {
            b.extend(x.to_le_bytes());
        }
        assert_eq!(attribute_text("box2i", &b), "(0, -2) - (9, 7)");
        // Short or unknown: the size, never a panic.
        assert_eq!(attribute_text("box2i", &b[..5]), "5 bytes");
        assert_eq!(attribute_text("mystery", &[1, 2]), "2 bytes");
        let mut ch = b"R\0".to_vec();
        ch.extend(1i32.to_le_bytes());
        ch.extend([0u8; 4]);
        ch.extend(1i32.to_le_bytes());
        ch.extend(1i32.to_le_bytes());
        ch.push(0);
        assert_eq!(attribute_text("chlist", &ch), "R half");
        // A header cut short ends the list.
        assert!(raw_attributes(&[0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0, b'a']).is_empty());
    }
}
