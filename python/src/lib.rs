//! epfilt for Python: numpy arrays in and out (`filter`, `restore`), the
//! streaming file filter (`filter_file`), `info`, `compare` and `read`. Every call releases
//! the GIL while it works; Ctrl-C stops it (no output is left); the
//! library's errors become `epfilt.Error` subclasses, with its message.
//!
//! The settings are the command line's options, named with underscores:
//! keyword arguments become the library's named settings, which
//! [`FilterOptions::from_settings`] types, defaults and checks for both.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

use epfilt::job::array::{filter_array, ArrayInput, ArrayStats};
use epfilt::job::{Existing, FilterOptions, Setting};
use epfilt::pipeline::{Precision, Source};
use half::f16;
use numpy::{PyArray1, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn};
use pyo3::exceptions::PyKeyboardInterrupt;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyList, PyTuple};

/// How often a running call looks for Ctrl-C (and lets other Python
/// threads run: it holds the GIL only while it looks).
const SIGNAL_POLL: Duration = Duration::from_millis(20);

/// The `epfilt` exception class for a library error: configuration,
/// input, I/O, or the base class.
fn to_py(e: epfilt::Error) -> PyErr {
    use epfilt::Error as E;
    let class = match &e {
        E::Interrupted => return PyKeyboardInterrupt::new_err(e.to_string()),
        E::Config(_) => "ConfigError",
        E::InvalidFile { .. }
        | E::InvalidPicture { .. }
        | E::InvalidFloatMap { .. }
        | E::Unsupported { .. }
        | E::Channels { .. }
        | E::Value { .. }
        | E::StreamValue { .. }
        | E::Mismatch { .. } => "InputError",
        E::Io { .. } | E::Output { .. } => "IoError",
        _ => "Error",
    };
    let line = epfilt::error::one_line(&e);
    // An operating system's error: its errno and file, and the OSError
    // subclass Python gives that errno (FileNotFoundError, ...).
    let os = match &e {
        E::Io { path, source } => source
            .raw_os_error()
            .map(|n| (n, source.to_string(), path.display().to_string())),
        _ => None,
    };
    Python::with_gil(|py| {
        let made = match &os {
            Some((errno, text, file)) => py
                .import("epfilt")
                .and_then(|m| m.getattr("_os_error"))
                .and_then(|f| f.call1((*errno, format!("{text} ({line})"), file.clone()))),
            None => py
                .import("epfilt")
                .and_then(|m| m.getattr(class))
                .and_then(|c| c.call1((line.clone(),))),
        };
        match made {
            Ok(exc) => PyErr::from_value(exc),
            Err(import_failed) => import_failed,
        }
    })
}

fn config_error(text: impl Into<String>) -> PyErr {
    to_py(epfilt::Error::Config(text.into()))
}

/// Run `work` with the GIL released, on a thread of its own, looking for
/// Ctrl-C every [`SIGNAL_POLL`]: a signal sets the run's cancel flag, the
/// run stops (leaving no output) and the signal's exception is raised.
fn detached<T: Send>(
    py: Python<'_>,
    work: impl FnOnce(Arc<AtomicBool>) -> epfilt::Result<T> + Send,
) -> PyResult<T> {
    detached_with(py, work, |_| Ok(()))
}

/// [`detached`], calling `tick` with the GIL at every look (a progress
/// callback): an exception it raises stops the run as Ctrl-C does.
fn detached_with<T: Send>(
    py: Python<'_>,
    work: impl FnOnce(Arc<AtomicBool>) -> epfilt::Result<T> + Send,
    mut tick: impl FnMut(Python<'_>) -> PyResult<()> + Send,
) -> PyResult<T> {
    let cancel = Arc::new(AtomicBool::new(false));
    let flag = cancel.clone();
    let (result, signal) = py.allow_threads(move || {
        std::thread::scope(|s| {
            let handle = s.spawn(move || work(flag));
            let mut signal: Option<PyErr> = None;
            while !handle.is_finished() {
                std::thread::sleep(SIGNAL_POLL);
                if signal.is_none() {
                    if let Err(e) = Python::with_gil(|py| py.check_signals().and_then(|_| tick(py)))
                    {
                        cancel.store(true, Ordering::SeqCst);
                        signal = Some(e);
                    }
                }
            }
            (handle.join(), signal)
        })
    });
    if let Some(e) = signal {
        return Err(e);
    }
    match result {
        Ok(r) => r.map_err(to_py),
        Err(panic) => {
            let what = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            Err(to_py(epfilt::Error::Internal(format!("panic: {what}"))))
        }
    }
}

/// Keyword settings as the library's: True/False switch, a list repeats
/// the option, anything else is its `str()`; None leaves a setting unset.
fn settings_of(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Vec<(String, Setting)>> {
    let mut out = Vec::new();
    let Some(kwargs) = kwargs else {
        return Ok(out);
    };
    for (k, v) in kwargs.iter() {
        let name: String = k.extract()?;
        if v.is_none() {
            continue;
        }
        let setting = if let Ok(b) = v.downcast::<PyBool>() {
            Setting::Flag(b.is_true())
        } else if v.downcast::<PyList>().is_ok() || v.downcast::<PyTuple>().is_ok() {
            let items: Vec<Bound<'_, PyAny>> = v.try_iter()?.collect::<PyResult<_>>()?;
            Setting::List(
                items
                    .iter()
                    .map(|i| i.str().map(|s| s.to_string()))
                    .collect::<PyResult<_>>()?,
            )
        } else {
            Setting::Value(v.str()?.to_string())
        };
        out.push((name, setting));
    }
    Ok(out)
}

/// A report (any of the library's serialisable ones) as a Python dict,
/// the `--report` JSON's fields.
fn to_dict<'py>(py: Python<'py>, value: &impl serde::Serialize) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(value)
        .map_err(|e| to_py(epfilt::Error::Internal(format!("report: {e}"))))?;
    py.import("json")?.call_method1("loads", (text,))
}

/// Pass the library's warnings on as Python `UserWarning`s.
fn warn_all(py: Python<'_>, warnings: &[String]) -> PyResult<()> {
    let category = py.get_type::<pyo3::exceptions::PyUserWarning>();
    for w in warnings {
        PyErr::warn(py, &category, &std::ffi::CString::new(w.as_str())?, 2)?;
    }
    Ok(())
}

/// A numpy array of float32 or float16 values as f32 in C order (any
/// strides), its shape, and whether it held half floats.
fn samples_of(a: &Bound<'_, PyAny>, what: &str) -> PyResult<(Vec<f32>, Vec<usize>, bool)> {
    if let Ok(arr) = a.downcast::<PyArrayDyn<f32>>() {
        let ro: PyReadonlyArrayDyn<'_, f32> = arr.readonly();
        let v = ro.as_array();
        return Ok((v.iter().copied().collect(), v.shape().to_vec(), false));
    }
    if let Ok(arr) = a.downcast::<PyArrayDyn<f16>>() {
        let ro: PyReadonlyArrayDyn<'_, f16> = arr.readonly();
        let v = ro.as_array();
        return Ok((
            v.iter().map(|h| h.to_f32()).collect(),
            v.shape().to_vec(),
            true,
        ));
    }
    // float64 (what imageio and OIIO often hand out) is rounded to float32,
    // as a float EXR holds it: the result is float32.
    if let Ok(arr) = a.downcast::<PyArrayDyn<f64>>() {
        let ro: PyReadonlyArrayDyn<'_, f64> = arr.readonly();
        let v = ro.as_array();
        return Ok((
            v.iter().map(|&x| x as f32).collect(),
            v.shape().to_vec(),
            false,
        ));
    }
    let dtype = a
        .getattr("dtype")
        .and_then(|d| d.str().map(|s| s.to_string()))
        .unwrap_or_else(|_| a.get_type().to_string());
    Err(config_error(format!(
        "{what} must be a numpy array of float32, float16 or float64, not {dtype} (convert with .astype(numpy.float32))"
    )))
}

/// An image's (height, width, channels) from its array's shape: (H, W, C),
/// or (H, W) as one channel (whether it was: the result takes its shape).
fn image_shape(shape: &[usize], what: &str) -> PyResult<([usize; 3], bool)> {
    match shape[..] {
        [h, w, c] => Ok(([h, w, c], false)),
        [h, w] => Ok(([h, w, 1], true)),
        _ => Err(config_error(format!(
            "{what} must have shape (height, width, channels) or (height, width), not {shape:?}"
        ))),
    }
}

/// `values` as an array of the image's shape (`flat`: (H, W)).
fn shaped<'py, T: numpy::Element>(
    py: Python<'py>,
    values: Vec<T>,
    [h, w, c]: [usize; 3],
    flat: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let arr = PyArray1::from_vec(py, values);
    Ok(if flat {
        arr.reshape([h, w])?.into_any()
    } else {
        arr.reshape([h, w, c])?.into_any()
    })
}

/// The channel names of an image of `c` channels.
fn default_channels(c: usize) -> PyResult<Vec<String>> {
    let names: &[&str] = match c {
        1 => &["Y"],
        2 => &["Y", "A"],
        3 => &["R", "G", "B"],
        4 => &["R", "G", "B", "A"],
        _ => {
            return Err(config_error(format!(
                "samples have {c} channels: 1 (Y), 2 (Y A), 3 (R G B) or 4 (R G B A)"
            )))
        }
    };
    Ok(names.iter().map(|s| s.to_string()).collect())
}

/// The names given for `c` channels, or the defaults for `c`.
fn channel_names(names: Option<Vec<String>>, c: usize) -> PyResult<Vec<String>> {
    match names {
        Some(names) if names.len() == c => Ok(names),
        Some(names) => Err(config_error(format!(
            "{} channel names for {c} channels",
            names.len()
        ))),
        None => default_channels(c),
    }
}

/// A variance pass given as arrays: the variance of single samples,
/// (h, w) of the luminance or (h, w, k) per colour channel, and its values
/// per pixel; the sample counts per pixel (an (h, w) array); one count for
/// the image (a number).
type Statistics = (Option<(Vec<f32>, usize)>, Option<Vec<f32>>, Option<f64>);

/// `variance=` and `spp=` checked against an image of (h, w) pixels.
fn statistics_of(
    variance: Option<&Bound<'_, PyAny>>,
    spp: Option<&Bound<'_, PyAny>>,
    (h, w): (usize, usize),
) -> PyResult<Statistics> {
    let (mut counts, mut fixed) = (None, None);
    if let Some(n) = spp {
        if n.hasattr("shape")? {
            let (v, shape, _) = samples_of(n, "spp")?;
            if shape != [h, w] {
                return Err(config_error(format!(
                    "spp has shape {shape:?}, not ({h}, {w})"
                )));
            }
            counts = Some(v);
        } else {
            fixed = Some(n.extract::<f64>()?);
        }
    }
    let variance = match variance {
        Some(v) => {
            let (v, shape, _) = samples_of(v, "variance")?;
            let nv = match shape[..] {
                [vh, vw] if (vh, vw) == (h, w) => 1,
                [vh, vw, k] if (vh, vw) == (h, w) => k,
                _ => {
                    return Err(config_error(format!(
                        "variance has shape {shape:?}, not ({h}, {w}) or ({h}, {w}, 3)"
                    )))
                }
            };
            Some((v, nv))
        }
        None if counts.is_some() || fixed.is_some() => {
            return Err(config_error("spp= without variance="))
        }
        None => None,
    };
    Ok((variance, counts, fixed))
}

/// Filter samples held in a numpy array; see the stub.
#[pyfunction]
#[pyo3(signature = (samples, supersample=None, method=None, *, channels=None, variance=None, spp=None, **settings))]
#[allow(clippy::too_many_arguments)]
fn filter<'py>(
    py: Python<'py>,
    samples: &Bound<'py, PyAny>,
    supersample: Option<usize>,
    method: Option<&str>,
    channels: Option<Vec<String>>,
    variance: Option<&Bound<'py, PyAny>>,
    spp: Option<&Bound<'py, PyAny>>,
    settings: Option<&Bound<'py, PyDict>>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let (data, shape, half) = samples_of(samples, "samples")?;
    let ([h, w, c], flat) = image_shape(&shape, "samples")?;
    let channels = channel_names(channels, c)?;
    let mut pairs = settings_of(settings)?;
    if let Some(m) = method {
        pairs.push(("method".into(), Setting::Value(m.into())));
    }
    if let Some(s) = supersample {
        pairs.push(("supersample".into(), Setting::Value(s.to_string())));
    }
    let (variance, spp_counts, spp_fixed) = statistics_of(variance, spp, (h, w))?;
    // One count for the image is the `spp` setting.
    if let Some(n) = spp_fixed {
        pairs.push(("spp".into(), Setting::Value(n.to_string())));
    }
    let (opts, given) = FilterOptions::from_settings(pairs).map_err(to_py)?;
    let out = detached(py, |cancel| {
        let input = ArrayInput {
            samples: &data,
            width: w,
            height: h,
            channels: &channels,
            half,
            stats: variance.as_ref().map(|(v, nv)| ArrayStats {
                variance: v,
                variance_channels: *nv,
                spp: spp_counts.as_deref(),
            }),
        };
        filter_array(&input, &opts, &given, Some(cancel))
    })?;
    warn_all(py, &out.report.warnings)?;
    let dims = [out.height, out.width, c];
    let image = match out.precision {
        Precision::F16 => {
            let v: Vec<f16> = out.samples.iter().map(|&x| f16::from_f32(x)).collect();
            shaped(py, v, dims, flat)?
        }
        _ => shaped(py, out.samples, dims, flat)?,
    };
    Ok((image, to_dict(py, &out.report)?))
}

/// The run's rows done and in all (what it reports) and the tick that
/// passes them on to `progress(done, total)` with the GIL, when they change.
fn ticker(
    progress: Option<PyObject>,
) -> (
    impl FnMut(Python<'_>) -> PyResult<()> + Send,
    impl Fn(usize, usize) + Sync,
) {
    let rows = Arc::new((AtomicUsize::new(0), AtomicUsize::new(0)));
    let seen = rows.clone();
    let mut last = (usize::MAX, usize::MAX);
    let tick = move |py: Python<'_>| -> PyResult<()> {
        let now = (
            seen.0.load(Ordering::Relaxed),
            seen.1.load(Ordering::Relaxed),
        );
        match &progress {
            Some(f) if now != last && now.1 > 0 => {
                last = now;
                f.call1(py, now).map(|_| ())
            }
            _ => Ok(()),
        }
    };
    let report_rows = move |done: usize, total: usize| {
        rows.1.store(total, Ordering::Relaxed);
        rows.0.store(done, Ordering::Relaxed);
    };
    (tick, report_rows)
}

/// Filter a file (or a frame sequence) into another, streamed; see the stub.
#[pyfunction]
#[pyo3(signature = (input, output, *, progress=None, **settings))]
fn filter_file<'py>(
    py: Python<'py>,
    input: PathBuf,
    output: PathBuf,
    progress: Option<PyObject>,
    settings: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let (tick, report_rows) = ticker(progress);
    let (opts, given) = FilterOptions::from_settings(settings_of(settings)?).map_err(to_py)?;
    let env = |k: &str| std::env::var(k).ok();
    let share = opts.share(&env).map_err(to_py)?;
    let (job, warnings) = opts
        .job(input, output, share.band, &given, None)
        .map_err(to_py)?;
    warn_all(py, &warnings)?;
    if let Some(seq) = opts.sequence(job.clone(), share.task).map_err(to_py)? {
        let report = detached_with(
            py,
            move |cancel| {
                let mut seq = seq;
                seq.template.pipeline.cancel = Some(cancel);
                epfilt::sequence::run_sequence(&seq, &|_| {}, &report_rows)
            },
            tick,
        )?;
        return to_dict(py, &report);
    }
    job.output_format().map_err(to_py)?;
    epfilt::io::Destination::resolve(&job.output).map_err(to_py)?;
    let file = epfilt::io::InputFile::open(&job.input).map_err(to_py)?;
    if opts.skip_existing
        && epfilt::job::existing_output(&job, &file).map_err(to_py)? == Existing::Done
    {
        let skipped = PyDict::new(py);
        skipped.set_item("skipped", true)?;
        skipped.set_item("output", job.output.display().to_string())?;
        return Ok(skipped.into_any());
    }
    let report = detached_with(
        py,
        move |cancel| {
            let mut job = job;
            job.pipeline.cancel = Some(cancel);
            epfilt::filter_opened(&job, &file, &report_rows)
        },
        tick,
    )?;
    warn_all(py, &report.warnings)?;
    to_dict(py, &report)
}

/// What a file holds (`epfilt info --json`); see the stub.
#[pyfunction]
fn info<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyAny>> {
    let described = detached(py, move |_| epfilt::io::info::describe(&path))?;
    to_dict(py, &described)
}

/// Every setting `filter_file` and `restore_file` take by name, with how it
/// takes its value (`flag`, `value` or `list`), whether it names files or
/// their layout (the array functions take the others) and which of them
/// takes it (`filter`, `restore` or `both`): the library's tables, which the
/// stubs' settings are checked against.
#[pyfunction]
fn settings() -> Vec<(&'static str, &'static str, bool, &'static str)> {
    use epfilt::job::options::{Command, Kind, OptionDef, OPTIONS};
    let kind = |k: Kind| match k {
        Kind::Flag => "flag",
        Kind::Value => "value",
        Kind::List => "list",
    };
    let commands = |d: &OptionDef| match (d.takes(Command::Filter), d.takes(Command::Restore)) {
        (true, true) => "both",
        (false, true) => "restore",
        _ => "filter",
    };
    (OPTIONS.iter())
        .map(|d| (d.name, kind(d.kind), d.files_only, commands(d)))
        .chain(
            epfilt::filter::settings::KNOBS
                .iter()
                .map(|k| (k.name, "value", false, "filter")),
        )
        .collect()
}

/// Image `a` against reference `b` (`epfilt compare --json`); see the stub.
#[pyfunction]
fn compare<'py>(py: Python<'py>, a: PathBuf, b: PathBuf) -> PyResult<Bound<'py, PyAny>> {
    let cmp = detached(py, move |_| {
        epfilt::compare::compare_files(&a, &b, &epfilt::io::Selection::default(), &|_, _| {})
    })?;
    to_dict(py, &cmp)
}

/// The samples of a file's image (the channels `filter` reads, then
/// `extra` ones) as a float32 array (height, width, channels) and their
/// names; see the stub.
#[pyfunction]
#[pyo3(signature = (path, extra=None))]
fn read<'py>(
    py: Python<'py>,
    path: PathBuf,
    extra: Option<Vec<String>>,
) -> PyResult<(Bound<'py, PyAny>, Vec<String>)> {
    let (data, w, h, names) = detached(py, move |cancel| {
        let mut input = epfilt::io::ExrInput::open(&path, None)?;
        input.add_aux_channels(&extra.unwrap_or_default())?;
        let (w, h) = input.size();
        let mut names = input.channels();
        names.extend(input.aux_channels());
        let nch = names.len();
        // Checked before anything is allocated: the whole image is held.
        let bytes = (w as u64) * (h as u64) * (nch as u64) * 4;
        let limit = epfilt::host::default_max_memory();
        if bytes > limit {
            return Err(epfilt::Error::Config(format!(
                "{}: {w}x{h} of {nch} channels is {} MiB, more than the {} MiB read() may hold: use filter_file, which streams",
                path.display(),
                bytes >> 20,
                limit >> 20
            )));
        }
        let mut data = vec![0.0f32; w * h * nch];
        let mut src = input.source();
        while let Some(strip) = src.next_strip(64)? {
            if cancel.load(Ordering::Relaxed) {
                return Err(epfilt::Error::Interrupted);
            }
            for (k, row) in strip.data.chunks_exact(w * nch).enumerate() {
                let y = strip.y0 + k;
                for c in 0..nch {
                    for (x, &v) in row[c * w..(c + 1) * w].iter().enumerate() {
                        data[(y * w + x) * nch + c] = v;
                    }
                }
            }
        }
        Ok((data, w, h, names))
    })?;
    let nch = names.len();
    let arr = PyArray1::from_vec(py, data).reshape([h, w, nch])?;
    Ok((arr.into_any(), names))
}

/// A denoiser's output with the energy of `energy` put back; see the stub.
/// Its settings are `restore_file`'s but those naming files. (Python's
/// keyword arguments, one each.)
#[allow(clippy::too_many_arguments)]
#[pyfunction]
#[pyo3(signature = (denoised, energy, scale=None, *, emission=None, variance=None, spp=None, channels=None, **settings))]
fn restore<'py>(
    py: Python<'py>,
    denoised: &Bound<'py, PyAny>,
    energy: &Bound<'py, PyAny>,
    scale: Option<usize>,
    emission: Option<&Bound<'py, PyAny>>,
    variance: Option<&Bound<'py, PyAny>>,
    spp: Option<&Bound<'py, PyAny>>,
    channels: Option<Vec<String>>,
    settings: Option<&Bound<'py, PyDict>>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let mut named = settings_of(settings)?;
    if let Some(s) = scale {
        named.push(("scale".into(), Setting::Value(s.to_string())));
    }
    let opts = epfilt::job::FilterOptions::for_restore(named).map_err(to_py)?;
    let files = opts.files_only_given();
    if !files.is_empty() {
        return Err(config_error(format!(
            "{} appl{} to files: use restore_file",
            files.join(", "),
            if files.len() == 1 { "ies" } else { "y" }
        )));
    }
    let (d, dshape, _) = samples_of(denoised, "denoised")?;
    let (e, eshape, _) = samples_of(energy, "energy")?;
    let em = match emission {
        Some(a) => {
            let (g, gshape, _) = samples_of(a, "emission")?;
            if gshape != eshape {
                return Err(config_error(format!(
                    "emission has shape {gshape:?} and energy {eshape:?}: the guide is the energy image's own"
                )));
            }
            Some(g)
        }
        None => None,
    };
    if dshape != eshape {
        return Err(config_error(format!(
            "denoised has shape {dshape:?} and energy {eshape:?}: restore needs the denoiser's output of that very image"
        )));
    }
    let ([h, w, c], flat) = image_shape(&eshape, "energy")?;
    let (variance, spp_counts, spp_fixed) = statistics_of(variance, spp, (h, w))?;
    let channels = channel_names(channels, c)?;
    let (threads, capped) = epfilt::job::options::cap_threads(opts.threads);
    warn_all(py, capped.as_slice())?;
    let (scale, keep_gain, nonfinite) = (opts.scale, opts.keep_gain, opts.nonfinite);
    let (out, report) = detached(py, |cancel| {
        let input = epfilt::job::restore::RestoreArrays {
            denoised: &d,
            energy: &e,
            emission: em.as_deref(),
            stats: variance.as_ref().map(|(v, nv)| ArrayStats {
                variance: v,
                variance_channels: *nv,
                spp: spp_counts.as_deref(),
            }),
            spp: spp_fixed,
            size: (w, h),
            channels: &channels,
        };
        epfilt::job::restore::restore_array(
            &input,
            (scale, keep_gain),
            threads,
            nonfinite,
            Some(cancel),
        )
    })?;
    let image = shaped(py, out, [h, w, c], flat)?;
    Ok((image, to_dict(py, &report)?))
}

/// `restore` from file to file, streamed; see the stub. Its settings are
/// the command line's, by the library's table.
#[pyfunction]
#[pyo3(signature = (denoised, energy, output, *, progress=None, **settings))]
fn restore_file<'py>(
    py: Python<'py>,
    denoised: PathBuf,
    energy: PathBuf,
    output: PathBuf,
    progress: Option<PyObject>,
    settings: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let opts = epfilt::job::FilterOptions::for_restore(settings_of(settings)?).map_err(to_py)?;
    let (mut job, capped) = opts
        .restore_job((denoised, energy, output), None)
        .map_err(to_py)?;
    warn_all(py, capped.as_slice())?;
    let (tick, report_rows) = ticker(progress);
    let report = detached_with(
        py,
        move |cancel| {
            job.cancel = Some(cancel);
            epfilt::restore_file(&job, &report_rows)
        },
        tick,
    )?;
    to_dict(py, &report)
}

/// The native module (`epfilt._epfilt`); `epfilt/__init__.py` is the API.
#[pymodule]
fn _epfilt(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(filter, m)?)?;
    m.add_function(wrap_pyfunction!(filter_file, m)?)?;
    m.add_function(wrap_pyfunction!(info, m)?)?;
    m.add_function(wrap_pyfunction!(settings, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(read, m)?)?;
    m.add_function(wrap_pyfunction!(restore, m)?)?;
    m.add_function(wrap_pyfunction!(restore_file, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
