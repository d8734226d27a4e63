"""epfilt: energy-preserving non-linear filters (Rushmeier & Ward 1994) for HDR renders.

Each noisy Monte Carlo sample is spread over a region just wide enough that its
influence on any output pixel stays below a tolerance; every sample's weights
sum to one, so the image's energy is exact, and real features (lamps, rims,
highlights) are kept.

    import numpy as np, epfilt
    image, report = epfilt.filter(samples, supersample=3)        # (H, W, C) float32/16/64, 3x3 super-sampled
    report = epfilt.filter_file("render_3x.exr", "out.exr", tolerance=0.08)

Settings are the command line's options with underscores (``support_region=8``,
``threads=4``, ``channel_rule=["Z=average"]``); see ``epfilt filter --help``.
Every call releases the GIL while it works, and Ctrl-C stops it, leaving no output.
"""

from . import _epfilt

__version__ = _epfilt.__version__

__all__ = [
    "filter",
    "filter_file",
    "restore",
    "restore_file",
    "denoise_file",
    "info",
    "compare",
    "read",
    "Error",
    "InputError",
    "ConfigError",
    "IoError",
    "__version__",
]


class Error(Exception):
    """Any error epfilt reports (the message is the command line's one line)."""


class InputError(Error):
    """An input epfilt cannot filter: damaged, unsupported, NaN/inf samples, missing channels."""


class ConfigError(Error, ValueError):
    """Settings that do not fit: an unknown option, a bad value, a wrong array shape or dtype."""


class IoError(Error, OSError):
    """Reading or writing a file failed, or the output path cannot be written. Where the
    operating system said why, ``errno`` and ``filename`` are set, and the error is also the
    ``OSError`` subclass Python gives that errno (a missing file is a ``FileNotFoundError``)."""


_OS_ERRORS = {}


def _os_error(errno, strerror, filename):
    """An ``IoError`` for an operating system's ``errno`` on ``filename``: also the OSError
    subclass Python maps that errno to (called by the native module)."""
    base = type(OSError(errno, strerror))
    if base is OSError:
        return IoError(errno, strerror, filename)
    cls = _OS_ERRORS.get(base)
    if cls is None:
        cls = type(base.__name__, (IoError, base), {"__module__": __name__, "__doc__": IoError.__doc__})
        _OS_ERRORS[base] = cls
    return cls(errno, strerror, filename)


def filter(samples, supersample=None, method=None, *, channels=None, variance=None, spp=None, **settings):
    """Filter samples held in memory: a render at final resolution, or a super-sampled one.

    samples: numpy array (height, width, channels), or (height, width) for one channel, of
        float32 or float16 (the result keeps it), or float64 (rounded to float32, as a float
        EXR holds it; the result is float32), any strides; 1 channel is Y, 2 Y A, 3 R G B,
        4 R G B A (or name them with ``channels``).
    supersample: samples per output pixel along each axis (default: 1, the array is at pixel
        resolution and is never reduced unless asked). The height and width must be multiples of it.
    method: ``ep-gauss``, ``ep-box``, ``gauss``, ``box``, ``clamp``, ``median``, ``alpha-trim``
        (default: ``ep-box`` where ``variance`` is given at supersample 1, else ``ep-gauss``).
        Arrays carry no guide passes: write a file with them and use ``filter_file``.
    variance, spp: ep-box's per-pixel statistics:
        variance an array (height, width) of the luminance's variance or (height, width, 3),
        of single samples unless ``variance_kind`` says ``mean`` or ``moment``; spp a number or
        an array (height, width) of sample counts.
    settings: the command line's options with underscores (``tolerance=0.08``, ``quality="best"``,
        ``threads=2``, ``nonfinite="zero"``); options about files raise ConfigError.

    Returns ``(image, report)``: the filtered (height / S, width / S, channels) array (float32,
    or float16 for float16 samples unless ``pixel_type="f32"``), bit-identical to what
    ``epfilt filter`` writes for the same samples, and the ``--report`` fields as a dict
    (energy ledger, counts, settings, version).
    """
    return _epfilt.filter(
        samples, supersample, method, channels=channels, variance=variance, spp=spp, **settings
    )


def filter_file(input, output, *, progress=None, **settings):
    """Filter an EXR (or Radiance picture) into another, streamed in constant memory.

    input, output: paths; frame sequences as on the command line (``r.####.exr``), with
        ``frames=``, ``task_index=``/``task_count=``; one band with ``band="3/8"``.
    settings: the command line's options with underscores (``method="ep-box"``,
        ``compression="zip"``, ``skip_existing=True``, ``threads=8``).
    progress: a callable ``progress(done, total)`` (output rows, twice over when ep-box reads
        the input once before filtering it; frames of a sequence),
        called from the calling thread as the run advances; an exception it raises stops
        the run, leaving no output.

    The output is written whole or not at all. Returns the ``--report`` fields as a dict
    (a sequence's report for a sequence; ``{"skipped": True, ...}`` when ``skip_existing``
    found a complete output).
    """
    return _epfilt.filter_file(str(input), str(output), progress=progress, **settings)


def restore(denoised, energy, scale=None, *, emission=None, variance=None, spp=None,
            channels=None, **settings):
    """A denoiser's output with ``energy``'s energy put back, closer to the truth than
    either, and the report.

    ``denoised`` is any denoiser's output (OIDN, OptiX, ...) and ``energy`` the image
    whose energy is right (the render, or ``filter``'s output of it), both float32,
    float16 or float64 (rounded to float32) arrays of the same shape (height, width,
    channels), or (height, width) for one channel. The render is an unbiased
    but noisy estimate of every region's energy, the denoiser's a steady but biased one:
    each block of ``scale`` x ``scale`` pixels (default 32), and each block of twice,
    four times ... that side up to the whole image, gets the render's energy where the
    render is sure and the denoiser's where it is not, children summing to their parent
    and the whole to the render's total exactly (report ``levels``, ``ledger``). The
    render's uncertainty comes from ``variance`` (the sample variance of single samples:
    (H, W) of the luminance or (H, W, 3) per channel, with ``spp``, a number or an (H, W)
    array of counts, as ``filter`` takes them) or, without it, from its residual against
    the denoiser. A bright pixel the denoiser dimmed stays in place only on evidence
    (report ``counts``, ``kept_share``): ``emission``, the render's directly visible
    emission pass (same shape as ``energy``); agreeing samples (``variance``); or a peak
    the denoiser kept. A firefly, which has none, joins its region's energy. Pass
    ``keep_gain=1`` where ``energy`` is ``filter``'s ep-gauss or ep-box output (its
    fireflies already spread: what still exceeds the denoiser is a feature).
    ``nonfinite``: "error" refuses NaN or infinite values (of either image, naming the
    pixel), "zero" counts them as zero. ``settings``: ``restore_file``'s but those naming
    files (``keep_gain``, ``nonfinite``, ``threads``, ``guides``). The result is float32.

    With Intel OIDN as its users run it, with the render's albedo and normal
    (``pip install epfilt[oidn]``; ``denoise_file`` does all of this for a file)::

        import numpy as np, pyoidn, epfilt
        render, _ = epfilt.read("render.exr")                      # R, G, B
        aux, _ = epfilt.read("render.exr", ["albedo.R", "albedo.G", "albedo.B", "N.X", "N.Y", "N.Z"])
        albedo, normal = aux[:, :, 3:6].copy(), aux[:, :, 6:9].copy()
        denoised = pyoidn.denoise(render, albedo, normal, hdr=True, quality="high")
        restored, report = epfilt.restore(np.asarray(denoised, np.float32), render)
    """
    return _epfilt.restore(denoised, energy, scale, emission=emission, variance=variance,
                           spp=spp, channels=channels, **settings)


def denoise_file(render, output, *, denoised=None, quality="high", **restore_settings):
    """Intel OIDN, run as its users run it, then ``restore_file``: ``render`` (an EXR that
    fits in memory) denoised with its albedo and normal passes where it has them (found by
    the names renderers give them, as ``info`` reports them in ``guide_channels``), and
    the result written to ``output`` with the render's energy put back. ``denoised``: a
    path to keep OIDN's own output at (else a temporary file). ``quality``: OIDN's.
    ``restore_settings`` go to ``restore_file`` (``scale``, ``threads``, ...). Returns
    ``restore_file``'s report with ``oidn`` added: the passes OIDN was given.

    Needs ``pyoidn`` (``pip install epfilt[oidn]``): ImportError names it otherwise.
    """
    import os
    import tempfile

    import numpy as np

    try:
        import pyoidn
    except ImportError as e:  # a message that says what to install
        raise ImportError("denoise_file runs Intel OIDN: pip install epfilt[oidn] (pyoidn)") from e
    part = info(render)["parts"][0]
    guides = part.get("guide_channels", {})
    aux = [guides[k] for k in ("albedo", "normal") if len(guides.get(k, ())) == 3]
    samples, names = read(render, [c for k in aux for c in k])
    colour = [i for i, n in enumerate(names[: len(names) - 3 * len(aux)])
              if n.rsplit(".", 1)[-1] in ("R", "G", "B")]
    if len(colour) != 3:
        raise ConfigError(f"{render}: OIDN denoises R, G, B; the beauty has {names}")
    rgb = np.ascontiguousarray(samples[:, :, colour])
    passes = {}
    base = len(names) - 3 * len(aux)
    for k, kind in enumerate(k for k in ("albedo", "normal") if len(guides.get(k, ())) == 3):
        passes[kind] = np.ascontiguousarray(samples[:, :, base + 3 * k:base + 3 * k + 3])
    result = np.asarray(pyoidn.denoise(rgb, passes.get("albedo"), passes.get("normal"),
                                       hdr=True, quality=quality), np.float32)
    with tempfile.TemporaryDirectory() as tmp:
        path = denoised or os.path.join(tmp, "denoised.pfm")
        _write_pfm(path, result)
        report = restore_file(path, render, output, **restore_settings)
    report["oidn"] = {"passes": sorted(passes), "quality": quality}
    return report


def _write_pfm(path, rgb):
    """A portable float map (OIDN's own format, which every command reads): bottom row
    first, little-endian."""
    import numpy as np

    h, w, _ = rgb.shape
    with open(path, "wb") as f:
        f.write(f"PF\n{w} {h}\n-1.0\n".encode("ascii"))
        f.write(np.ascontiguousarray(rgb[::-1], dtype="<f4").tobytes())


def restore_file(denoised, energy, output, *, progress=None, **settings):
    """``restore`` from file to file, streamed: ``epfilt restore DENOISED ENERGY OUTPUT``.

    ``settings``: the command line's options with underscores (``epfilt restore --help``:
    ``scale``, ``keep_gain``, ``guides``, ``guide``, ``part``, ``layer``, ``channel_rule``,
    ``compression``, ``threads``, ``max_memory``, ``nonfinite``), with its defaults and
    checks.

    Both files are read twice (first every block's energy, then the result): memory grows
    with the width and ``scale`` (and, a few words per block, with the height), so a render
    too large for ``read`` can be restored. The render's variance pass and sample count,
    where it has them (found as ``filter`` finds them), measure its uncertainty (the
    report's ``variance_pass``, ``uncertainty_from``, ``levels``). A keep gain applies
    beside the evidence only where the energy file is ``filter``'s ep-gauss or ep-box
    output (1, read from its header) or ``keep_gain`` says. ``guides``/``guide``: the
    energy file's emission guide pass ("auto": found by name; agreeing samples of a
    variance pass keep pixels too; "none": neither; ``guide=["emission=ViewLayer.Emit"]``
    names it).
    ``part``/``layer``: the energy file's part and beauty layer; its other channels (depth,
    normals, ids, light AOVs) are carried as it has them, bit for bit, but those a
    ``channel_rule=["PATTERN=drop"]`` matches (the report's ``carried_channels``). ``compression``: the
    output's (default the energy file's). ``progress(done, total)``: output rows, as for
    ``filter_file`` (the two passes' rows: twice the height). ``max_memory``: MiB the run may hold by its estimate (default half
    the machine's memory, or of its cgroup limit where less); below its floor it raises, naming the floor. The output is
    written whole or not at all. Returns the ``--report`` fields as a dict.
    """
    return _epfilt.restore_file(str(denoised), str(energy), str(output), progress=progress,
                                **settings)


def info(path):
    """What an EXR file or Radiance picture holds, as ``epfilt info --json`` prints it."""
    return _epfilt.info(str(path))


def compare(a, b):
    """Image file ``a`` against reference ``b``: rmse, rel_mse, psnr, energy_ratio, identical, ..."""
    return _epfilt.compare(str(a), str(b))


def read(path, extra=None):
    """The samples ``filter_file`` would filter (the beauty's channels, then the ``extra``
    channels named, e.g. ``["variance.R", "variance.G", "variance.B"]``) as a float32 array
    (height, width, channels), and the channel names. The whole image is held in memory."""
    return _epfilt.read(str(path), extra)
