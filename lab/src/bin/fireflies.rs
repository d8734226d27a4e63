//! Write a super-sampled test render with fireflies, streaming (flat memory):
//!
//! `cargo run --release -p epfilt-lab --bin fireflies -- OUT.exr WIDTH HEIGHT [FRACTION] [COMPRESSION] [MIN..MAX] [--guides[=LIST]]`
//!
//! WIDTH x HEIGHT are input samples. A smooth RGB background (0.2..1.0) with
//! FRACTION (default 0.01) of the samples turned into fireflies MIN..MAX times
//! brighter (log-uniform; default 10..1000; the paper's "dynamic range of
//! 10^5": 1e2..1e5), everywhere including borders and corners, float samples,
//! ZIP by default. `--guides` adds the guide passes renderers write: an
//! emission pass naming a lamp (1000 times the ground) every 97th pixel of
//! every 97th row, albedo, normals that turn at every 512th column (walls
//! meeting) and a depth ramp: what the guides cost is measured on it.
//! `--guides=emission,albedo` writes only the passes named (of `emission`,
//! `albedo`, `normal`, `depth`).

use epfilt::io::{parse_compression, ExrOutput};
use epfilt::pipeline::{Precision, Sink};

fn hash(i: u64) -> u64 {
    let mut z = i.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let all: Vec<String> = std::env::args().collect();
    const PASSES: [&str; 4] = ["emission", "albedo", "normal", "depth"];
    let mut wanted: Vec<&str> = Vec::new();
    for x in &all {
        match x.strip_prefix("--guides") {
            Some("") => wanted = PASSES.to_vec(),
            Some(list) => {
                for p in list.trim_start_matches('=').split(',') {
                    let p = PASSES.iter().find(|q| **q == p);
                    wanted.push(p.ok_or("--guides=LIST names emission, albedo, normal, depth")?);
                }
            }
            None => {}
        }
    }
    let has = |p: &str| wanted.contains(&p);
    let guides = !wanted.is_empty();
    let a: Vec<String> = all
        .into_iter()
        .filter(|x| !x.starts_with("--guides"))
        .collect();
    if a.len() < 4 {
        return Err(
            "usage: fireflies OUT.exr WIDTH HEIGHT [FRACTION] [COMPRESSION] [MIN..MAX]".into(),
        );
    }
    let (w, h): (usize, usize) = (a[2].parse()?, a[3].parse()?);
    let frac: f64 = a.get(4).map(|s| s.parse()).transpose()?.unwrap_or(0.01);
    let comp = parse_compression(a.get(5).map(String::as_str).unwrap_or("zip"))
        .ok_or("unknown compression")?;
    let (lo, hi): (f64, f64) = match a.get(6) {
        Some(r) => {
            let (l, h) = r.split_once("..").ok_or("MIN..MAX, e.g. 1e2..1e5")?;
            (l.parse()?, h.parse()?)
        }
        None => (10.0, 1000.0),
    };
    if !(lo > 0.0 && hi >= lo) {
        return Err("MIN..MAX must be positive and increasing".into());
    }
    let (l0, span) = (lo.log10(), (hi / lo).log10());
    let mut names: Vec<&str> = vec!["R", "G", "B"];
    let groups: [(&str, &[&str]); 4] = [
        ("emission", &["emission.R", "emission.G", "emission.B"]),
        ("albedo", &["albedo.R", "albedo.G", "albedo.B"]),
        ("normal", &["N.X", "N.Y", "N.Z"]),
        ("depth", &["Z"]),
    ];
    // Where each pass's first channel sits in a row, if it is written.
    let mut at = [None; 4];
    for (k, (pass, chans)) in groups.iter().enumerate() {
        if has(pass) {
            at[k] = Some(names.len());
            names.extend(chans.iter());
        }
    }
    let nch = names.len();
    let names: Vec<String> = names.iter().map(|s| s.to_string()).collect();
    let mut out = ExrOutput::create_new(
        std::path::Path::new(&a[1]),
        w,
        h,
        &names,
        comp,
        Precision::F32,
        &[],
    )?;
    let rows = 64;
    let mut y = 0;
    while y < h {
        let n = rows.min(h - y);
        let mut data = vec![0.0f32; n * nch * w];
        for r in 0..n {
            let j = y + r;
            for i in 0..w {
                let base = 0.6 + 0.4 * ((i as f32 * 0.003).sin() * (j as f32 * 0.002).cos());
                let k = hash((j * w + i) as u64);
                let u = (k >> 11) as f64 / (1u64 << 53) as f64;
                let mag = if u < frac {
                    10f64.powf(l0 + span * (hash(k) >> 11) as f64 / (1u64 << 53) as f64)
                } else {
                    1.0
                };
                let lamp = guides && i % 97 == 48 && j % 97 == 48;
                let mag = if lamp { 1000.0 } else { mag };
                for (c, tint) in [1.0f32, 0.9, 0.75].iter().enumerate() {
                    data[(r * nch + c) * w + i] = base * tint * mag as f32;
                }
                let wall = (i / 512) % 2 == 1;
                let n = if wall {
                    [0.0, 0.0, 1.0]
                } else {
                    [0.0, 1.0, 0.0]
                };
                let idx = |k: usize| (r * nch + k) * w + i;
                for c in 0..3 {
                    if let Some(e) = at[0] {
                        data[idx(e + c)] = if lamp { data[idx(c)] } else { 0.0 };
                    }
                    if let Some(a) = at[1] {
                        data[idx(a + c)] = if wall { 0.3 } else { 0.6 };
                    }
                    if let Some(nn) = at[2] {
                        data[idx(nn + c)] = n[c];
                    }
                }
                if let Some(z) = at[3] {
                    data[idx(z)] = 2.0 + j as f32 / h as f32;
                }
            }
        }
        out.write_rows(y, n, &data)?;
        y += n;
    }
    out.finish()?;
    out.commit()?;
    Ok(())
}
