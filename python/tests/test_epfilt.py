"""epfilt's Python bindings against the command line, on `epfilt synth` scenes.

The CLI binary is EPFILT_BIN, else the repository's target/release/epfilt, else
target/debug/epfilt (`.ci/run` builds the release one before pytest).
"""

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import epfilt

ROOT = Path(__file__).resolve().parents[2]

# The ledger's bound (the library checks 1e-9 before writing; its own sums
# reach a few ulps): every run here must balance to this.
LEDGER_TOL = 1e-12

# The energy-preserving methods, then the foils that lose energy by design.
EXACT = ["ep-gauss", "gauss", "box"]
METHODS = EXACT + ["clamp", "median", "alpha-trim"]


def cli():
    for p in (
        os.environ.get("EPFILT_BIN"),
        ROOT / "target" / "release" / "epfilt",
        ROOT / "target" / "debug" / "epfilt",
    ):
        if p and Path(p).is_file():
            return str(p)
    pytest.fail("no epfilt binary: run `cargo build --release` first (or set EPFILT_BIN)")


def run(*args):
    subprocess.run([cli(), *map(str, args)], check=True, capture_output=True)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A 120x90-pixel `mixed` scene at S = 3 (fireflies, a light edge, a caustic)."""
    path = tmp_path_factory.mktemp("scene") / "mixed.exr"
    run("synth", "-q", "--scene", "mixed", "--size", "120x90", "-o", path)
    return path


@pytest.fixture(scope="module")
def variance_scene(tmp_path_factory):
    """The `lights` scene as 16-spp pixel means with per-pixel variance (ep-box's input)."""
    path = tmp_path_factory.mktemp("var") / "lights.exr"
    run("synth", "-q", "--scene", "lights", "--size", "96x80", "--spp", "16", "--variance", "-o", path)
    return path


def cli_filter(src, dst, *args):
    report = dst.with_suffix(".json")
    run("filter", "-q", src, dst, "--report", report, *args)
    return json.loads(report.read_text())


def assert_bits_equal(a, b):
    assert a.shape == b.shape and a.dtype == b.dtype
    assert np.array_equal(a.view(np.uint32 if a.dtype == np.float32 else np.uint16),
                          b.view(np.uint32 if b.dtype == np.float32 else np.uint16))


@pytest.mark.parametrize("method", METHODS)
def test_arrays_are_bit_identical_to_the_cli(scene, tmp_path, method):
    samples, names = epfilt.read(scene)
    assert names == ["R", "G", "B"]
    image, report = epfilt.filter(samples, supersample=3, method=method, threads=2)
    out = tmp_path / "cli.exr"
    cli_report = cli_filter(scene, out, "-s", "3", "--method", method)
    want, _ = epfilt.read(out)
    assert_bits_equal(image, want)
    assert report["digest"] == cli_report["digest"]
    assert report["settings"] == cli_report["settings"]
    assert report["energy_rel_error"] == cli_report["energy_rel_error"]
    assert report["version"] == epfilt.__version__


def test_ep_box_with_per_pixel_statistics_is_bit_identical_to_the_cli(variance_scene, tmp_path):
    both, names = epfilt.read(variance_scene, extra=["variance.R", "variance.G", "variance.B"])
    assert names[:3] == ["R", "G", "B"]
    samples, variance = np.ascontiguousarray(both[:, :, :3]), both[:, :, 3:]
    image, report = epfilt.filter(samples, method="ep-box", variance=variance, spp=16)
    # Without a method, the variance picks ep-box, as the file's does for the CLI.
    auto, auto_report = epfilt.filter(samples, variance=variance, spp=16)
    assert auto_report["method"] == "ep-box" and auto.shape == samples.shape
    assert_bits_equal(auto, image)
    out = tmp_path / "cli.exr"
    cli_report = cli_filter(variance_scene, out)
    assert cli_report["method"] == "ep-box"
    want, _ = epfilt.read(out)
    assert_bits_equal(image, want)
    assert report["ep_box"]["l_tvis"] == cli_report["ep_box"]["l_tvis"]
    assert report["samples_spread"] == cli_report["samples_spread"] > 0
    assert max(abs(e) for e in report["energy_rel_error"]) <= LEDGER_TOL


def test_energy_is_exact_for_every_energy_preserving_method(scene):
    samples, _ = epfilt.read(scene)
    for method in EXACT:
        image, report = epfilt.filter(samples, supersample=3, method=method)
        total_in = samples.astype(np.float64).sum(axis=(0, 1))
        total_out = image.astype(np.float64).sum(axis=(0, 1)) * 9
        # After rounding to f32 the sums move by about an ulp per pixel.
        assert np.allclose(total_out, total_in, rtol=1e-6)
        assert max(abs(e) for e in report["energy_rel_error"]) <= LEDGER_TOL


def test_strided_and_half_inputs(scene, tmp_path):
    samples, _ = epfilt.read(scene)
    # A view with negative and non-unit strides filters as its copy.
    flipped = samples[::-1, :, ::-1]
    assert not flipped.flags["C_CONTIGUOUS"]
    a, _ = epfilt.filter(flipped, supersample=3)
    b, _ = epfilt.filter(np.ascontiguousarray(flipped), supersample=3)
    assert_bits_equal(a, b)
    # float16 in, float16 out, as the CLI does for a half file.
    half_file = tmp_path / "half.exr"
    run("filter", "-q", scene, half_file, "-s", "1", "--method", "box", "--pixel-type", "f16")
    half, _ = epfilt.read(half_file)
    image, report = epfilt.filter(half.astype(np.float16), supersample=3)
    assert image.dtype == np.float16 and report["settings"]["pixel_type"] == "f16"
    out = tmp_path / "cli.exr"
    cli_filter(half_file, out, "-s", "3")
    want, _ = epfilt.read(out)
    assert_bits_equal(image.astype(np.float32), want)
    image32, _ = epfilt.filter(half.astype(np.float16), pixel_type="f32")
    assert image32.dtype == np.float32


def test_errors_raise_the_right_exceptions(scene, tmp_path):
    samples, _ = epfilt.read(scene)
    with pytest.raises(epfilt.ConfigError, match="shape"):
        epfilt.filter(samples[:, 0, 0])
    with pytest.raises(ValueError):  # ConfigError is a ValueError too
        epfilt.filter(samples[:, :10], supersample=3)
    with pytest.raises(epfilt.ConfigError, match="float32, float16 or float64"):
        epfilt.filter(samples.astype(np.int16))
    with pytest.raises(epfilt.ConfigError, match='unknown setting "tolerence"'):
        epfilt.filter(samples, tolerence=0.1)
    with pytest.raises(epfilt.ConfigError, match="tolerance"):
        epfilt.filter(samples, tolerance="lots")
    with pytest.raises(epfilt.ConfigError, match="applies to files"):
        epfilt.filter(samples, compression="zip")
    nan = samples.copy()
    nan[4, 7, 1] = np.nan
    with pytest.raises(epfilt.InputError, match="non-finite"):
        epfilt.filter(nan)
    _, report = epfilt.filter(nan, nonfinite="zero")
    assert report["nonfinite_zeroed"] == [0, 1, 0]
    with pytest.raises(epfilt.IoError):
        epfilt.filter_file(tmp_path / "missing.exr", tmp_path / "out.exr")
    damaged = tmp_path / "damaged.exr"
    damaged.write_bytes(scene.read_bytes()[:5000])
    with pytest.raises(epfilt.InputError):
        epfilt.filter_file(damaged, tmp_path / "out.exr")
    assert not (tmp_path / "out.exr").exists()
    assert issubclass(epfilt.IoError, OSError) and issubclass(epfilt.InputError, epfilt.Error)


def test_filter_file_info_and_compare(scene, tmp_path):
    out = tmp_path / "py.exr"
    with pytest.warns(UserWarning, match="no effect"):
        report = epfilt.filter_file(scene, out, method="gauss", tolerance=0.1, threads=1)
    cli = tmp_path / "cli.exr"
    cli_report = cli_filter(scene, cli, "--method", "gauss")
    assert report["digest"] == cli_report["digest"]
    assert epfilt.compare(out, cli)["identical"]
    info = epfilt.info(out)
    assert info["parts"][0]["width"] == 120
    # A band of the output, as on the command line.
    band = epfilt.filter_file(scene, tmp_path / "band.exr", band="2/3")
    assert (band["band"]["index"], band["band"]["count"]) == (2, 3)


def test_the_gil_is_released_while_filtering():
    rng = np.random.default_rng(7)
    samples = np.full((1800, 1800, 3), 0.2, np.float32)
    hot = rng.random(samples.shape[:2]) < 0.01
    samples[hot] = 1e4
    ticks = []
    stop = threading.Event()

    def count():
        while not stop.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.001)

    t = threading.Thread(target=count)
    t.start()
    try:
        # At least half a second of filtering, whatever this machine's speed
        # (one call took 0.2 to 1 s on the machines tried).
        start = time.perf_counter()
        calls = 0
        while time.perf_counter() - start < 0.5:
            epfilt.filter(samples, threads=1)
            calls += 1
        end = time.perf_counter()
    finally:
        stop.set()
        t.join()
    during = [x for x in ticks if start < x < end]
    # A thread that got the GIL only between calls would tick a few times
    # per call; released, it ticks about every millisecond.
    assert end - start >= 0.5
    assert len(during) >= max(0.25 * (end - start) / 0.001 / 4, 20 * calls), (
        len(during),
        end - start,
        calls,
    )


def test_ctrl_c_interrupts_a_run_and_leaves_no_output(tmp_path):
    big = tmp_path / "big.exr"
    run("synth", "-q", "--scene", "mixed", "--size", "1400x1400", "-o", big)
    out = tmp_path / "out" / "filtered.exr"
    out.parent.mkdir()
    # Python's own SIGINT handler, as in a terminal (a shell that starts
    # pytest in the background leaves SIGINT ignored, and interrupt_main
    # then does nothing).
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.3, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    start = time.perf_counter()
    try:
        with pytest.raises(KeyboardInterrupt):
            epfilt.filter_file(big, out, threads=1)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    assert time.perf_counter() - start < 5.0
    assert list(out.parent.iterdir()) == []


ANON_PROBE = """
import subprocess, sys, threading, time
import epfilt

def anon(pid="self"):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("RssAnon:"):
                return int(line.split()[1]) * 1024
    return 0

src, dst, who, cli = sys.argv[1:5]
args = ["--threads", "1", "--strip-rows", "24"]
if who == "cli":
    p = subprocess.Popen([cli, "filter", "-q", src, dst, *args])
    peak = 0
    while p.poll() is None:
        try:
            peak = max(peak, anon(p.pid))
        except OSError:
            pass
        time.sleep(0.002)
    print(peak)
else:
    base, peak, done = anon(), [0], threading.Event()

    def watch():
        while not done.is_set():
            peak[0] = max(peak[0], anon())
            time.sleep(0.002)

    t = threading.Thread(target=watch)
    t.start()
    epfilt.filter_file(src, dst, threads=1, strip_rows=24)
    done.set()
    t.join()
    print(peak[0] - base)
"""


def test_filter_file_memory_grows_with_height_as_the_clis_does(tmp_path):
    """The heap (RssAnon: mapped file pages left out) that filter_file adds
    while it runs, against the CLI's own, on the same two heights."""
    if not Path("/proc/self/status").read_text().count("RssAnon:"):
        pytest.skip("needs Linux's /proc/PID/status RssAnon")
    growth = {}
    for who in ("py", "cli"):
        peaks = []
        # Both heights past the reader's two batches (24 MiB each: 1165
        # pixel rows here), which a shorter image does not fill.
        for h in (1600, 6400):
            src = tmp_path / f"h{h}.exr"
            if not src.exists():
                run("synth", "-q", "--scene", "mixed", "--size", f"200x{h}", "-o", src)
            probe = subprocess.run(
                [sys.executable, "-c", ANON_PROBE, str(src), str(tmp_path / f"{who}{h}.exr"), who, cli()],
                check=True, capture_output=True, text=True,
            )
            peaks.append(int(probe.stdout.split()[-1]))
        growth[who] = peaks[1] - peaks[0]
    # 4x the rows: holding the image would add 600x14400 samples of 3 f32
    # channels (104 MB) and its output; the bindings add no memory of their
    # own per row (a few MiB of allocator noise between the processes).
    held = 600 * 14400 * 3 * 4
    print("heap growth", growth)
    assert growth["py"] < growth["cli"] + (6 << 20), growth
    assert growth["py"] < held // 2, growth


def test_filter_file_reports_progress_and_a_failing_callback_stops_it(tmp_path):
    src = tmp_path / "in.exr"
    run("synth", "-q", "--scene", "mixed", "--size", "800x800", "-o", src)
    seen = []
    report = epfilt.filter_file(src, tmp_path / "out.exr", threads=1, strip_rows=24,
                                progress=lambda done, total: seen.append((done, total)))
    assert report["out_height"] == 800
    assert len(seen) >= 2, seen
    assert all(t == seen[0][1] for _, t in seen)
    assert [d for d, _ in seen] == sorted(d for d, _ in seen)

    class Stop(Exception):
        pass

    def stop(done, total):
        raise Stop

    out = tmp_path / "stopped" / "out.exr"
    out.parent.mkdir()
    with pytest.raises(Stop):
        epfilt.filter_file(src, out, threads=1, progress=stop)
    assert list(out.parent.iterdir()) == []


def test_restore_puts_the_energy_back_at_any_thread_count():
    rng = np.random.default_rng(7)
    energy = (rng.random((40, 52, 3)) + 0.2).astype(np.float32)
    energy[5, 9] = 500.0  # a firefly the "denoiser" removed
    denoised = np.full_like(energy, 0.5)
    denoised[:, :10] = 0.0  # and a region it left black
    out, report = epfilt.restore(denoised, energy, 8)
    assert out.shape == energy.shape and out.dtype == np.float32
    for l in report["ledger"]:
        assert l["rel_error"] <= LEDGER_TOL
    total = energy.astype(np.float64).sum(axis=(0, 1))
    assert np.allclose(out.astype(np.float64).sum(axis=(0, 1)), total, rtol=1e-6)
    assert report["counts"]["unshaped"] > 0
    # The same digest at any thread count.
    _, again = epfilt.restore(denoised, energy, 8, threads=1)
    assert again["digest"] == report["digest"]
    with pytest.raises(epfilt.ConfigError):
        epfilt.restore(denoised[:, :-1], energy)
    with pytest.raises(epfilt.ConfigError):
        epfilt.restore(denoised, energy, 1)
    bad = energy.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(epfilt.InputError):
        epfilt.restore(denoised, bad)
    _, rep = epfilt.restore(denoised, bad, nonfinite="zero")
    assert rep["nonfinite_zeroed"] == 1
    # Arrays say nothing of how they were made: a render's evidence alone
    # unless told; the firefly is not kept in place.
    assert report["keep_gain"] is None
    assert out[5, 9, 0] < 5.0
    _, low = epfilt.restore(denoised, energy, 8, keep_gain=2.0)
    assert low["keep_gain"] == 2.0 and low["kept_share"] >= report["kept_share"]
    with pytest.raises(epfilt.ConfigError):
        epfilt.restore(denoised, energy, keep_gain=0.5)


def test_float64_and_two_dimensional_arrays_are_taken():
    rng = np.random.default_rng(3)
    grey = rng.random((30, 40)) + 0.5  # float64, (H, W)
    grey[7, 9] = 400.0
    out, report = epfilt.filter(grey)
    assert out.shape == grey.shape and out.dtype == np.float32
    as32, _ = epfilt.filter(grey.astype(np.float32)[:, :, None])
    assert np.array_equal(out, as32[:, :, 0])
    restored, rep = epfilt.restore(np.full_like(grey, grey.mean()), grey, 8)
    assert restored.shape == grey.shape
    for l in rep["ledger"]:
        assert l["rel_error"] <= LEDGER_TOL
    with pytest.raises(epfilt.ConfigError):
        epfilt.filter(grey.astype(np.int32))


def test_os_errors_are_oserrors_with_errno_and_filename(tmp_path):
    missing = tmp_path / "missing.exr"
    with pytest.raises(FileNotFoundError) as e:
        epfilt.filter_file(missing, tmp_path / "out.exr")
    assert isinstance(e.value, epfilt.IoError) and isinstance(e.value, epfilt.Error)
    assert e.value.errno == 2 and e.value.filename == str(missing)


def test_restore_reads_a_variance_pass_as_restore_file_does(variance_scene):
    render, names = epfilt.read(variance_scene, ["variance.R", "variance.G", "variance.B"])
    energy, variance = render[:, :, :3].copy(), render[:, :, 3:].copy()
    spp = epfilt.info(variance_scene)["parts"][0]["attributes"]["spp"][1]
    denoised = np.full_like(energy, energy.mean())
    out, report = epfilt.restore(denoised, energy, 16, variance=variance, spp=float(spp))
    assert report["uncertainty_from"] == "variance pass" and "variance.R" in report["variance_pass"]
    assert report["levels"][-1]["exact"] == report["levels"][-1]["blocks"]
    _, residual = epfilt.restore(denoised, energy, 16)
    assert residual["uncertainty_from"] == "residual" and residual["digest"] != report["digest"]
    for l in report["ledger"]:
        assert l["rel_error"] <= LEDGER_TOL
    with pytest.raises(epfilt.ConfigError):
        epfilt.restore(denoised, energy, variance=variance)  # no spp
    with pytest.raises(epfilt.ConfigError):
        epfilt.restore(denoised, energy, spp=16)  # no variance


def test_denoise_file_runs_oidn_with_the_renders_passes(tmp_path):
    pytest.importorskip("pyoidn", reason="denoise_file needs pip install epfilt[oidn]")
    render = tmp_path / "r.exr"
    run("synth", "-q", "--spp", "16", "--size", "64x48", "-o", render)
    out = tmp_path / "out.exr"
    report = epfilt.denoise_file(render, out, denoised=tmp_path / "oidn.pfm", scale=16)
    assert out.exists() and (tmp_path / "oidn.pfm").exists()
    assert report["oidn"]["passes"] == []  # a synth render has no albedo or normal pass
    for l in report["ledger"]:
        assert l["rel_error"] <= LEDGER_TOL


def test_restore_keeps_the_emission_guides_lamp_in_place():
    energy = np.ones((24, 24, 3), np.float32)
    energy[9, 12] = 101.0  # a lamp the denoiser removed
    emission = np.zeros_like(energy)
    emission[9, 12] = 100.0
    denoised = np.ones_like(energy)
    spread, plain = epfilt.restore(denoised, energy, 8)
    kept, guided = epfilt.restore(denoised, energy, 8, emission=emission)
    assert plain["emission_guide"] == [] and guided["emission_guide"] == ["emission"]
    # All but the denoiser's share around (a flat 1 over the kernel's centre
    # weight, about 25) stays in place; without the guide it is spread.
    assert spread[9, 12, 0] < 20.0 and kept[9, 12, 0] > 70.0
    for l in guided["ledger"]:
        assert l["rel_error"] <= LEDGER_TOL
    with pytest.raises(epfilt.ConfigError):
        epfilt.restore(denoised, energy, emission=emission[:, :-1])


def test_restore_file_is_the_cli_streamed(variance_scene, tmp_path):
    denoised = tmp_path / "d.exr"
    cli_filter(variance_scene, denoised, "--method", "gauss", "-s", "1")
    out, cli = tmp_path / "py.exr", tmp_path / "cli.exr"
    seen = []
    report = epfilt.restore_file(denoised, variance_scene, out, scale=16, threads=2,
                                 progress=lambda done, total: seen.append((done, total)))
    cli_report = tmp_path / "cli.json"
    run("restore", "-q", denoised, variance_scene, cli, "--scale", "16", "--report", cli_report)
    assert report["digest"] == json.loads(cli_report.read_text())["digest"]
    assert epfilt.compare(out, cli)["identical"]
    assert all(abs(l["rel_error"]) <= LEDGER_TOL for l in report["ledger"])
    assert report["emission_guide"] == [] and report["copied_channels"] == []
    # The variance pass is carried as the render has it, unless dropped.
    carried = report["carried_channels"]
    assert carried and all(c.startswith("variance.") for c in carried), carried
    bare = epfilt.restore_file(denoised, variance_scene, tmp_path / "bare.exr", scale=16,
                               channel_rule=["variance.*=drop"])
    assert bare["carried_channels"] == [] and bare["digest"] != report["digest"]
    assert epfilt.compare(tmp_path / "bare.exr", out)["identical"]
    # Two passes over the 80 rows.
    if seen:
        assert seen[-1] == (160, 160) and all(t == 160 for _, t in seen)
    # Asked for, an absent guide is an error, and no output is left.
    with pytest.raises(epfilt.Error, match="emission guide"):
        epfilt.restore_file(denoised, variance_scene, tmp_path / "none.exr", guides="emission")
    assert not (tmp_path / "none.exr").exists()
    # Below its floor of memory: an error naming it, and no output.
    with pytest.raises(epfilt.Error, match="at least about"):
        epfilt.restore_file(denoised, variance_scene, tmp_path / "none.exr", max_memory=1)
    assert not (tmp_path / "none.exr").exists()


def test_the_stubs_settings_are_the_librarys():
    """The stubs' settings (`FilterSettings`, `ArraySettings`, `RestoreSettings`,
    `RestoreArraySettings`) name every setting the library's table gives each
    command, typed by how each takes its value: a stub that drifts fails here."""
    import ast
    import pathlib

    stub = pathlib.Path(epfilt.__file__).with_name("__init__.pyi")
    tree = ast.parse(stub.read_text())
    classes = {node.name: node for node in tree.body if isinstance(node, ast.ClassDef)}

    def keys(name):
        """A TypedDict's keys, its bases' included."""
        node = classes[name]
        own = {a.target.id: ast.unparse(a.annotation) for a in node.body if isinstance(a, ast.AnnAssign)}
        for base in node.bases:
            if isinstance(base, ast.Name) and base.id in classes:
                own = {**keys(base.id), **own}
        return own

    names = ("FilterSettings", "ArraySettings", "RestoreSettings", "RestoreArraySettings")
    typed = {name: keys(name) for name in names}
    kinds = {"flag": "bool", "value": "_Value", "list": "Sequence[str]"}
    table = epfilt._epfilt.settings()
    assert len(table) > 50

    def of(command, arrays=False, explicit=()):
        """The settings `command` takes, those naming files left out for arrays."""
        return {name: kinds[kind] for name, kind, files, takes in table
                if takes in (command, "both") and not (arrays and files) and name not in explicit}

    assert typed["FilterSettings"] == of("filter")
    # filter's and restore's own parameters are not among the keywords.
    assert typed["ArraySettings"] == of("filter", True, {"supersample", "method", "spp"})
    assert typed["RestoreSettings"] == of("restore")
    assert typed["RestoreArraySettings"] == of("restore", True, {"scale"})


def test_restore_takes_the_command_lines_settings_and_names_the_others(tmp_path):
    """restore and restore_file read their settings from the library's table:
    a setting of filter's alone, or one naming files given to arrays, is a
    ConfigError that says what restore takes."""
    rng = np.random.default_rng(5)
    energy = rng.random((24, 32, 3)).astype(np.float32)
    denoised = np.full_like(energy, energy.mean())
    with pytest.raises(epfilt.ConfigError, match="restore's settings are: .*keep_gain"):
        epfilt.restore(denoised, energy, tolerance=0.1)
    with pytest.raises(epfilt.ConfigError, match="restore_file"):
        epfilt.restore(denoised, energy, part="0")
    out, rep = epfilt.restore(denoised, energy, 8, threads="1", nonfinite="zero")
    assert max(abs(line["rel_error"]) for line in rep["ledger"]) < LEDGER_TOL
    with pytest.raises(epfilt.ConfigError, match="restore's settings"):
        epfilt.restore_file(tmp_path / "d.exr", tmp_path / "e.exr", tmp_path / "o.exr", radius=2)
