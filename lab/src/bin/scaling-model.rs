//! Predict a run on more cores from its `epfilt filter --trace` file: work
//! `T1`, span `T∞`, and the wall time and speed-up on each number of cores
//! (`epfilt_lab::model`; `scripts/scaling-model`, `scripts/bench-scaling`).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Parser;
use epfilt_lab::model::{Model, Prediction, JOIN_S};

#[derive(Parser)]
#[command(
    name = "scaling-model",
    about = "Predict a run on more cores from its `epfilt filter --trace` file"
)]
struct Args {
    /// The trace (`epfilt filter --trace FILE`).
    trace: PathBuf,
    /// Numbers of cores to predict.
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8,16,32,64")]
    cores: Vec<usize>,
    /// What the end of a parallel loop costs its lane, in microseconds per
    /// doubling of the cores (waking the threads that wait for it; fitted on
    /// the one 16-core machine measured). 0: the replay of the tasks alone.
    #[arg(long, default_value_t = JOIN_S * 1e6, value_parser = join_us)]
    join_us: f64,
    /// Strips the filter works on at once, as `epfilt filter
    /// --strips-in-flight` sets them: 1 or 2 (a strip's first passes beside
    /// the rest of the one before, `epfilt_lab::model`). Give it a trace
    /// taken with one strip in flight.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=2))]
    strips_in_flight: u8,
    /// Print JSON: {"work_s", "span_s", "predicted_s": {"1": .., ...}, ...}.
    #[arg(long)]
    json: bool,
}

/// `--join-us`: a finite number of microseconds, not negative.
fn join_us(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("{s:?} is not a number of microseconds (0 or more)")),
    }
}

fn main() -> Result<()> {
    let a = Args::parse();
    let events = epfilt::trace::read(&a.trace).with_context(|| format!("{}", a.trace.display()))?;
    let model = match a.strips_in_flight {
        1 => Model::from_events(&events),
        _ => Model::from_events_in_flight(&events),
    }
    .with_context(|| format!("{}", a.trace.display()))?;
    let p = Prediction::of(&model, &a.cores, a.join_us * 1e-6);
    if a.json {
        println!("{}", serde_json::to_string_pretty(&p)?);
    } else {
        print!("{}", p.table(&a.cores));
    }
    Ok(())
}
