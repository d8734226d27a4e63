//! `epfilt merge`: put the bands of `filter --band K/N` together into one
//! file, copying their compressed blocks (band boundaries lie on block
//! boundaries), so it runs at the speed of the disk and gives the file a run
//! over the whole image gives. The bands' ledgers add up to the image's.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use crate::error::{Error, Result};
use crate::io::bands::BandFile;
use crate::io::provenance::Fingerprint;
use crate::pipeline::ledger::CompensatedSum;

/// What `merge` did.
#[derive(Clone, Debug, Serialize)]
pub struct MergeReport {
    /// The merged file.
    pub output: String,
    /// Bands merged.
    pub bands: usize,
    /// Output size.
    pub width: usize,
    /// Output rows.
    pub height: usize,
    /// Channel names.
    pub channels: Vec<String>,
    /// Per channel, the input energy the bands own (their sum).
    pub energy_in: Vec<f64>,
    /// Per channel, the output energy times S² (their sum).
    pub energy_out: Vec<f64>,
    /// Per channel, |out - in| / |in|.
    pub energy_rel_error: Vec<f64>,
    /// Bytes of compressed blocks copied.
    pub bytes_copied: u64,
    /// Wall time in seconds.
    pub seconds: f64,
}

impl MergeReport {
    /// A short text summary.
    pub fn summary(&self) -> String {
        let mut s = format!(
            "{}: {} bands, {}x{}, {:.1} MiB of blocks copied in {:.2} s\n  energy ledger   channel      in            out x S^2     rel.err\n",
            self.output,
            self.bands,
            self.width,
            self.height,
            self.bytes_copied as f64 / (1 << 20) as f64,
            self.seconds
        );
        for (k, c) in self.channels.iter().enumerate() {
            s.push_str(&format!(
                "                  {:<8} {:>13.6e} {:>13.6e}  {:>9.2e}\n",
                c, self.energy_in[k], self.energy_out[k], self.energy_rel_error[k]
            ));
        }
        s
    }
}

/// Refuse bands that are not of one run: each records the fingerprint of
/// its input and of its settings ([`crate::io::provenance`]); the value most
/// bands share is the run's, and a band that differs is named.
fn same_run(bands: &[BandFile]) -> Result<()> {
    let fingerprints: Vec<Option<&Fingerprint>> =
        bands.iter().map(|b| b.fingerprint.as_ref()).collect();
    if fingerprints.iter().all(Option::is_none) {
        return Ok(()); // bands of an epfilt that did not record them
    }
    let odd_one = |key: &dyn Fn(&Fingerprint) -> &str, what: &str| -> Result<()> {
        let keys: Vec<Option<&str>> = fingerprints.iter().map(|f| f.map(key)).collect();
        let count = |k: Option<&str>| keys.iter().filter(|x| **x == k).count();
        // The most common value (the first band's when tied).
        let common = keys
            .iter()
            .copied()
            .max_by_key(|k| {
                (
                    count(*k),
                    std::cmp::Reverse(keys.iter().position(|x| x == k)),
                )
            })
            .flatten();
        let same: Vec<String> = bands
            .iter()
            .zip(&keys)
            .filter(|(_, k)| **k == common)
            .map(|(b, _)| b.k.to_string())
            .collect();
        if let Some((b, k)) = bands.iter().zip(&keys).find(|(_, k)| **k != common) {
            return Err(Error::Config(format!(
                "{}: band {}/{} was made {} than band(s) {} ({what} fingerprint {} against {}): not one run's bands",
                b.path.display(),
                b.k,
                b.n,
                if what == "input" { "from another input" } else { "with other settings" },
                same.join(", "),
                k.unwrap_or("missing"),
                common.unwrap_or("missing"),
            )));
        }
        Ok(())
    };
    odd_one(&|f| f.input.as_str(), "input")?;
    odd_one(&|f| f.settings.as_str(), "settings")
}

/// Bands sorted by number that are one run's and cover its rows once.
fn cover_once(bands: &[BandFile]) -> Result<()> {
    let first = &bands[0];
    let n = first.n;
    let mut next = 0;
    for (i, b) in bands.iter().enumerate() {
        if b.n != n || b.of != first.of || b.s != first.s {
            return Err(Error::Config(format!(
                "{} is band {}/{} of {} rows, {} band {}/{} of {}: not one run's bands",
                b.path.display(),
                b.k,
                b.n,
                b.of,
                first.path.display(),
                first.k,
                first.n,
                first.of
            )));
        }
        if b.k != i + 1 || b.rows.0 != next {
            let have: Vec<String> = bands.iter().map(|b| b.k.to_string()).collect();
            return Err(Error::Config(format!(
                "the bands do not cover the image once: have {} of {n} (bands {}), rows from {} expected",
                bands.len(),
                have.join(", "),
                next
            )));
        }
        if !b.same_layout(first) {
            return Err(Error::Config(format!(
                "{} was not made by the same command as {} (its header differs: method, settings, channels or compression)",
                b.path.display(),
                first.path.display()
            )));
        }
        next = b.rows.1;
    }
    if bands.len() != n || next != first.of {
        return Err(Error::Config(format!(
            "{} of {n} bands given (rows 0-{next} of {}); merge needs all of them",
            bands.len(),
            first.of
        )));
    }
    Ok(())
}

/// Merge `parts` (in any order) into `output` (`format`: `--format`, for
/// a name that does not end in `.exr`); `progress(rows, of)` as blocks are
/// copied.
pub fn merge(
    parts: &[PathBuf],
    output: &Path,
    format: Option<crate::io::Format>,
    progress: crate::pipeline::Progress<'_>,
) -> Result<MergeReport> {
    let start = Instant::now();
    if parts.is_empty() {
        return Err(Error::Config(
            "merge needs the band files and an output".into(),
        ));
    }
    crate::io::format::output_format(
        output,
        format,
        Some(crate::io::Format::Exr),
        &[crate::io::Format::Exr],
        "merge",
    )?;
    for p in parts {
        crate::job::check_not_same_file(p, output)?;
    }
    let mut bands = parts
        .iter()
        .map(|p| BandFile::read(p))
        .collect::<Result<Vec<_>>>()?;
    same_run(&bands)?;
    bands.sort_by_key(|b| b.k);
    cover_once(&bands)?;
    let (first, n) = (&bands[0], bands[0].n);
    let staged = crate::io::Staged::new(output, ".exr.tmp")?;
    let copied = crate::io::bands::write_merged(&bands, output, &staged, progress)?;
    // The ledger: the bands' shares added up.
    let names: Vec<String> = first.ledger.iter().map(|l| l.0.clone()).collect();
    let mut sum_in = vec![CompensatedSum::default(); names.len()];
    let mut sum_out = vec![CompensatedSum::default(); names.len()];
    for b in &bands {
        for (c, (_, i, o)) in b.ledger.iter().enumerate().take(names.len()) {
            sum_in[c].add(*i);
            sum_out[c].add(*o);
        }
    }
    let energy_in: Vec<f64> = sum_in.iter().map(|s| s.value()).collect();
    let energy_out: Vec<f64> = sum_out.iter().map(|s| s.value()).collect();
    let energy_rel_error = energy_in
        .iter()
        .zip(&energy_out)
        .map(|(i, o)| {
            if *i == 0.0 {
                (o - i).abs()
            } else {
                ((o - i) / i).abs()
            }
        })
        .collect();
    staged.commit()?;
    Ok(MergeReport {
        output: output.display().to_string(),
        bands: n,
        width: first.width(),
        height: first.of,
        channels: names,
        energy_in,
        energy_out,
        energy_rel_error,
        bytes_copied: copied,
        seconds: start.elapsed().as_secs_f64(),
    })
}
