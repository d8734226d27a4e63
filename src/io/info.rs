//! `epfilt info`: what an EXR file (or a Radiance picture) holds.

use super::{compression_name, luminance_weights};
use crate::filter::channels::ChannelRule;

/// A human description of an EXR file: parts, sizes, channels, compression,
/// layout.
pub fn info(path: &std::path::Path) -> crate::Result<String> {
    use std::fmt::Write;
    if is_radiance(path)? {
        return rgbe_info(path);
    }
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| crate::Error::from_exr(path, e, "header"))?;
    let mut s = String::new();
    let _ = writeln!(s, "{}: {} part(s)", path.display(), meta.headers.len());
    for (i, h) in meta.headers.iter().enumerate() {
        let dw = h.data_window();
        let disp = h.shared_attributes.display_window;
        let layout = match h.blocks {
            exr::meta::BlockDescription::ScanLines => {
                format!(
                    "scan lines ({} per block)",
                    h.compression.scan_lines_per_block()
                )
            }
            exr::meta::BlockDescription::Tiles(t) => {
                format!(
                    "tiles {}x{} {:?}",
                    t.tile_size.0, t.tile_size.1, t.level_mode
                )
            }
        };
        let _ = writeln!(
            s,
            "part {i}{}: {}x{} data window ({}, {})..({}, {}), display window ({}, {})..({}, {})",
            h.own_attributes
                .layer_name
                .as_ref()
                .map(|n| format!(" {:?}", n.to_string()))
                .unwrap_or_default(),
            dw.size.0,
            dw.size.1,
            dw.position.0,
            dw.position.1,
            dw.position.0 + dw.size.0 as i32 - 1,
            dw.position.1 + dw.size.1 as i32 - 1,
            disp.position.0,
            disp.position.1,
            disp.position.0 + disp.size.0 as i32 - 1,
            disp.position.1 + disp.size.1 as i32 - 1,
        );
        let _ = writeln!(
            s,
            "  compression {}, {layout}, line order {:?}{}",
            compression_name(h.compression),
            h.line_order,
            if h.deep { ", DEEP" } else { "" }
        );
        let chans: Vec<String> = h
            .channels
            .list
            .iter()
            .map(|c| {
                let t = match c.sample_type {
                    exr::meta::attribute::SampleType::F16 => "half",
                    exr::meta::attribute::SampleType::F32 => "float",
                    exr::meta::attribute::SampleType::U32 => "uint",
                };
                if c.sampling.0 != 1 || c.sampling.1 != 1 {
                    format!(
                        "{} {t} ({}x{} subsampled)",
                        c.name, c.sampling.0, c.sampling.1
                    )
                } else {
                    format!("{} {t}", c.name)
                }
            })
            .collect();
        let _ = writeln!(s, "  channels: {}", chans.join(", "));
        let _ = match super::reader::choose_channels(path, h, None) {
            Ok((chosen, rest)) => {
                let names: Vec<&str> = chosen.iter().map(|c| c.name.as_str()).collect();
                let _ = writeln!(s, "  filtered: {}", names.join(", "));
                // What `filter` does with the rest by default (--channel-rule
                // changes it; median and alpha-trim carry nothing).
                let views = super::reader::other_views(h);
                let (mut carried, mut dropped) = (Vec::new(), Vec::new());
                for name in &rest {
                    let uint = h.channels.list.iter().any(|c| {
                        c.name.to_string() == *name
                            && c.sample_type == exr::meta::attribute::SampleType::U32
                    });
                    match crate::filter::channels::rule_for(name, uint, &[], &views) {
                        ChannelRule::Drop => dropped.push(name.clone()),
                        r => carried.push(format!("{name} {}", r.name())),
                    }
                }
                if !carried.is_empty() {
                    let _ = writeln!(s, "  carried: {}", carried.join(", "));
                }
                if dropped.is_empty() {
                    Ok(())
                } else {
                    writeln!(s, "  dropped: {}", dropped.join(", "))
                }
            }
            Err(crate::Error::Unsupported { reason, .. }) => {
                writeln!(s, "  filtered: nothing ({reason})")
            }
            Err(e) => {
                let e = e.to_string();
                let prefix = format!("{}: ", path.display());
                writeln!(
                    s,
                    "  filtered: nothing by default ({})",
                    e.trim_start_matches(&prefix)
                )
            }
        };
        let ch = h.shared_attributes.chromaticities.as_ref();
        let lw = luminance_weights(ch);
        let _ = writeln!(
            s,
            "  luminance Y = {:.4} R + {:.4} G + {:.4} B ({}), pixel aspect {}",
            lw[0],
            lw[1],
            lw[2],
            if ch.is_some() {
                "from chromaticities"
            } else {
                "Rec. 709 primaries"
            },
            h.shared_attributes.pixel_aspect
        );
    }
    if meta.headers.len() > 1 {
        let _ = writeln!(
            s,
            "filter: choose a part with --part NAME|INDEX (at S = 1 the others are copied bit for bit, at S > 1 left out), or filter every part with --part all"
        );
    }
    Ok(s)
}

/// Whether the file begins as a Radiance picture.
fn is_radiance(path: &std::path::Path) -> crate::Result<bool> {
    use std::io::Read;
    let mut head = [0u8; 2];
    let mut f = std::fs::File::open(path).map_err(|e| crate::Error::io(path, e))?;
    let n = f.read(&mut head).map_err(|e| crate::Error::io(path, e))?;
    Ok(super::rgbe::is_rgbe(&head[..n]))
}

/// A Radiance picture: size, format, exposure, primaries, header lines.
fn rgbe_info(path: &std::path::Path) -> crate::Result<String> {
    use std::fmt::Write;
    let input = super::ExrInput::open(path, None)?;
    let r = input
        .rgbe()
        .ok_or_else(|| crate::Error::Internal("not a picture".into()))?;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{}: Radiance picture, {}x{}, {}",
        path.display(),
        r.w,
        r.h,
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
    let lw = luminance_weights(input.header().shared_attributes.chromaticities.as_ref());
    let _ = writeln!(
        s,
        "  luminance Y = {:.4} R + {:.4} G + {:.4} B ({})",
        lw[0],
        lw[1],
        lw[2],
        if r.primaries.is_some() {
            "from PRIMARIES"
        } else {
            "Rec. 709 primaries"
        }
    );
    for l in &r.lines {
        let _ = writeln!(s, "  header: {l}");
    }
    Ok(s)
}
