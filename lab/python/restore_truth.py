"""`epfilt restore` against the truth: is OIDN (run as its users run it, with the render's albedo
and normal) then `restore` closer to the reference than both the render and OIDN?

For every `<scene>_px_<res>_spp<N>.exr` beside its `<scene>_ref_<res>.exr` in the folders given,
and for each render with an emission guide a copy without it (`no guide`):

* **OIDN+aux**: `pyoidn`, RT filter, HDR, quality high, with the render's albedo and normal
  passes where it has them (found as `epfilt info` reports them, `guide_channels`);
* **restore**: `epfilt restore OIDN.pfm render.exr` (the command, at its defaults: it reads the
  render's guide and variance passes), and the same with `--base`'s binary where given.

Measures, each against the reference:

* **error**: relMSE = mean (x - ref)^2 / (ref^2 + 1e-2) over pixels and channels, over OIDN's;
* **blocks at B**: the root mean square over the B x B blocks of the relative error of a block's
  energy (summed over channels; relative to the reference's, floored at 1e-3 of the mean block),
  over the smaller of the render's and OIDN's (at most 1.05: closer to the truth than both);
* **peaks**: the mean luminance of the reference's brightest 0.1% of pixels, the output's over the
  render's (restore promises the render's values where it keeps a pixel);
* **floor at B**: the error over OIDN's of OIDN's picture carried onto the reference's own B x B
  block energies by restore's field and carrier (here in numpy, the whole image at once): what
  pinning the true block energies costs the pixels. Above 1.1, no target for those blocks keeps
  the error within 1.1x OIDN's while the picture stays the denoiser's.

Writes `restore-truth.md` into `--out` (default docs/bench) with the command, machine, versions
and date, and prints it. Run by `scripts/restore-truth`.
"""

import argparse
import datetime
import glob
import importlib.metadata
import json
import os
import platform
import re
import subprocess
import sys
import tempfile

import numpy as np
import OpenEXR
import pyoidn

import epfilt

LUM = np.array([0.2126, 0.7152, 0.0722])
# relMSE's floor in the denominator, as the renders' evaluation has it.
REL_EPS = 1e-2
# The block sides the target names, pixels.
BLOCKS = (16, 32, 64)
# The reference's brightest pixels whose values the peaks measure.
PEAK_SHARE = 1e-3
# A block's reference energy floor, as a share of the mean block: a black block has no relative
# error to speak of.
BLOCK_FLOOR = 1e-3
# The targets: error at most this over OIDN's; blocks at most this over the better of the two.
ERROR_TARGET, BLOCK_TARGET = 1.1, 1.05


def channels(path, names):
    f = OpenEXR.File(str(path), separate_channels=True)
    ch = f.channels()
    if not all(n in ch for n in names):
        return None
    return np.stack([np.asarray(ch[n].pixels, np.float64) for n in names], axis=-1)


def rgb(path):
    if str(path).endswith(".pfm"):
        with open(path, "rb") as f:
            assert f.readline().strip() == b"PF"
            w, h = map(int, f.readline().split())
            scale = float(f.readline())
            data = np.frombuffer(f.read(), "<f4" if scale < 0 else ">f4").reshape(h, w, 3)
        return data[::-1].astype(np.float64)
    return channels(path, ["R", "G", "B"])


def rel_mse(x, ref):
    return float(np.mean((x - ref) ** 2 / (ref ** 2 + REL_EPS)))


def block_sums(x, b):
    h, w = x.shape[:2]
    nby, nbx = -(-h // b), -(-w // b)
    pad = [(0, nby * b - h), (0, nbx * b - w)] + [(0, 0)] * (x.ndim - 2)
    return np.pad(x, pad).reshape(nby, b, nbx, b, *x.shape[2:]).sum(axis=(1, 3))


def block_error(x, ref, b):
    o, r = block_sums(x.sum(-1), b), block_sums(ref.sum(-1), b)
    return float(np.sqrt(np.mean(((o - r) / np.maximum(r, BLOCK_FLOOR * r.mean())) ** 2)))


def peaks(x, render, ref):
    lum = ref @ LUM
    top = np.argsort(lum.ravel())[-max(1, int(PEAK_SHARE * lum.size)):]
    return float((x @ LUM).ravel()[top].mean() / (render @ LUM).ravel()[top].mean())


def field_floor(denoised, ref, b, iters=20):
    """OIDN's picture carried onto the reference's b x b block energies as restore carries a
    target: c = s + t (f - 1), t = s^2 / m where a block needs more than s holds, s where less
    (bilinear between block centres), f bilinear coefficients solved by Jacobi steps, then each
    block's exact factor."""
    h, w, nc = denoised.shape
    out = np.zeros_like(denoised)

    def tent(n):
        nb = -(-n // b)
        c = (np.arange(n) + 0.5) / b - 0.5
        i0 = np.clip(np.floor(c), 0, nb - 1).astype(int)
        w1 = np.where((c <= 0) | (i0 + 1 >= nb), 0.0, np.clip(c - i0, 0, 1))
        return i0, np.minimum(i0 + 1, nb - 1), 1 - w1, w1

    (y0, y1, wy0, wy1), (x0, x1, wx0, wx1) = tent(h), tent(w)

    def interp(f):
        a = f[y0][:, x0] * wx0 + f[y0][:, x1] * wx1
        c = f[y1][:, x0] * wx0 + f[y1][:, x1] * wx1
        return a * wy0[:, None] + c * wy1[:, None]

    for ch in range(nc):
        s = np.maximum(denoised[..., ch], 0)
        target = block_sums(ref[..., ch], b)
        held = block_sums(s, b)
        m = held / block_sums(np.ones_like(s), b)
        more = interp((target > held).astype(float))
        mi = interp(m)
        t = np.where((s > 0) & (mi > 0), s * (1 - more + more * s / np.maximum(mi, 1e-300)), 0.0)
        goal = target - held + block_sums(t, b)
        f = np.ones_like(target)
        for _ in range(iters):
            reach = block_sums(t * interp(f), b)
            f = np.where((reach > 0) & (goal > 0), f * goal / np.maximum(reach, 1e-300), f)
        c = np.maximum(s + t * (interp(f) - 1), 0)
        got = block_sums(c, b)
        g = np.where(got > 0, target / np.maximum(got, 1e-300), 0.0)
        out[..., ch] = c * np.repeat(np.repeat(g, b, 0), b, 1)[:h, :w]
    return out


def denoise(path, tmp):
    """OIDN with the render's albedo and normal where it has them: its output as a PFM, and
    the passes it was given."""
    guides = epfilt.info(path)["parts"][0].get("guide_channels", {})
    aux = {k: channels(path, guides[k]) for k in ("albedo", "normal") if len(guides.get(k, ())) == 3}
    x = np.ascontiguousarray(rgb(path), np.float32)
    a = {k: np.ascontiguousarray(v, np.float32) for k, v in aux.items()}
    d = np.asarray(pyoidn.denoise(x, a.get("albedo"), a.get("normal"), hdr=True, quality="high"),
                   np.float32)
    out = os.path.join(tmp, "oidn.pfm")
    with open(out, "wb") as f:
        f.write(f"PF\n{d.shape[1]} {d.shape[0]}\n-1.0\n".encode())
        f.write(np.ascontiguousarray(d[::-1], "<f4").tobytes())
    return out, sorted(aux)


# A render whose emission guide holds at least this share of its energy (lamps in view) is also
# restored without the guide: what a render from a renderer that writes none gets.
GUIDED_SHARE = 0.01


def without_emission(path, tmp):
    """A copy of the render without its emission guide (None where it has none, or one with
    little light in it)."""
    f = OpenEXR.File(str(path), separate_channels=True)
    kept = {k: v.pixels for k, v in f.channels().items() if not k.startswith("emission.")}
    emitted = sum(np.asarray(v.pixels, np.float64).sum() for k, v in f.channels().items()
                  if k.startswith("emission."))
    if len(kept) == len(f.channels()) or emitted < GUIDED_SHARE * rgb(path).sum():
        return None
    header = {k: v for k, v in f.header().items() if k in ("compression", "type") or k.startswith("epfilt")}
    out = os.path.join(tmp, os.path.basename(path))
    OpenEXR.File(header, kept).write(out)
    return out


def restore(binary, denoised, render, tmp):
    out, rep = os.path.join(tmp, "restored.exr"), os.path.join(tmp, "r.json")
    subprocess.run([binary, "restore", "-q", denoised, render, out, "--report", rep], check=True)
    return rgb(out), json.load(open(rep))


def measure(render, ref, denoised, tmp, binaries):
    R, ref_img, D = rgb(render), rgb(ref), rgb(denoised)
    row = {"oidn_over_input": rel_mse(D, ref_img) / rel_mse(R, ref_img)}
    for b in BLOCKS:
        row[f"render_b{b}"], row[f"oidn_b{b}"] = block_error(R, ref_img, b), block_error(D, ref_img, b)
    for name, binary in binaries:
        out, rep = restore(binary, denoised, render, tmp)
        row[f"{name}_error"] = rel_mse(out, ref_img) / rel_mse(D, ref_img)
        row[f"{name}_over_input"] = rel_mse(out, ref_img) / rel_mse(R, ref_img)
        for b in BLOCKS:
            row[f"{name}_b{b}"] = block_error(out, ref_img, b) / min(row[f"render_b{b}"], row[f"oidn_b{b}"])
        row[f"{name}_peaks"] = peaks(out, R, ref_img)
        row[f"{name}_ledger"] = max(abs(l["rel_error"]) for l in rep["ledger"])
        row[f"{name}_kept"] = rep["kept_share"]
        levels = rep.get("levels")
        row[f"{name}_follow"] = (levels[0]["following_render"] / levels[0]["blocks"]) if levels else None
    for b in (32, 64):
        row[f"floor_b{b}"] = rel_mse(field_floor(D, ref_img, b), ref_img) / rel_mse(D, ref_img)
    return row


def renders(folders):
    for d in folders:
        for p in sorted(glob.glob(os.path.join(d, "*_px_*_spp*.exr"))):
            m = re.match(r"(.*)_px_(\d+)_spp(\d+)\.exr$", os.path.basename(p))
            ref = os.path.join(d, f"{m.group(1)}_ref_{m.group(2)}.exr")
            if os.path.exists(ref):
                yield p, ref


def git(*args):
    try:
        return subprocess.run(["git", *args], capture_output=True, text=True).stdout.strip()
    except OSError:
        return "?"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--renders", action="append", required=True, help="a folder of renders (repeatable)")
    ap.add_argument("--bin", default="target/release/epfilt")
    ap.add_argument("--base", help="another epfilt binary to compare (an earlier commit's)")
    ap.add_argument("--out", default="docs/bench")
    ap.add_argument("--command", default="scripts/restore-truth")
    a = ap.parse_args()
    binaries = [("restore", a.bin)] + ([("base", a.base)] if a.base else [])
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        os.makedirs(os.path.join(tmp, "bare"))
        for render, ref in renders(a.renders):
            denoised, passes = denoise(render, tmp)
            name = os.path.basename(render)[:-4]
            variants = [(name, render)]
            bare = without_emission(render, os.path.join(tmp, "bare"))
            if bare:
                variants.append((name + " (no guide)", bare))
            for label, path in variants:
                row = {"input": label, "oidn_passes": "+".join(passes) or "colour"}
                row.update(measure(path, ref, denoised, tmp, binaries))
                rows.append(row)
                print(f"{label}: done", file=sys.stderr)
    text = report(rows, a, binaries)
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.out, "restore-truth.md"), "w") as f:
        f.write(text)
    print(text)


def report(rows, a, binaries):
    cpu = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name")),
               platform.processor())
    lines = ["# restore against the truth\n",
             f"Made by `{a.command}` ({', '.join(a.renders)}) on {cpu} ({os.cpu_count()} cores), epfilt "
             f"{epfilt.__version__} ({git('rev-parse', '--short', 'HEAD')})"
             + (f", base `{a.base}`" if a.base else "")
             + f", OIDN through pyoidn {importlib.metadata.version('pyoidn')}, numpy {np.__version__}, "
             f"Python {platform.python_version()}, {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC. "
             "`lab/python/restore_truth.py` defines every measure.\n",
             f"**error**: relMSE over OIDN+aux's (target: at most {ERROR_TARGET}); **16/32/64**: RMS relative "
             f"block-energy error over the smaller of the render's and OIDN's (target: at most {BLOCK_TARGET}); "
             "**peaks**: the reference's brightest 0.1%, over the render's values there; **ledger**: the "
             "largest relative difference of a channel's total from the render's; **follow**: the share of "
             "the 32 x 32 blocks' targets nearer the render's energy; **floor 32/64**: OIDN's picture on the "
             "reference's own blocks of that side, error over OIDN's (the field and carrier alone, with "
             "nothing kept in place: on renders whose lamps the denoiser removed, d3 and l1, it says "
             "nothing). A render whose emission guide holds lamps is also restored from a copy without "
             "the guide (**no guide**).\n"]
    names = [n for n, _ in binaries]
    head = ["input", "OIDN passes", "OIDN over input"]
    for n in names:
        head += [f"{n} error", "16", "32", "64", "peaks", "ledger", "follow"]
    head += ["floor 32", "floor 64"]
    lines.append("| " + " | ".join(head) + " |")
    lines.append("|" + "---|" * len(head))
    for r in rows:
        cells = [r["input"], r["oidn_passes"], f"{r['oidn_over_input']:.3f}"]
        for n in names:
            follow = r[f"{n}_follow"]
            cells += [f"{r[f'{n}_error']:.3f}"] + [f"{r[f'{n}_b{b}']:.2f}" for b in BLOCKS]
            cells += [f"{r[f'{n}_peaks']:.2f}", f"{r[f'{n}_ledger']:.0e}",
                      "-" if follow is None else f"{follow:.0%}"]
        cells += [f"{r['floor_b32']:.2f}", f"{r['floor_b64']:.2f}"]
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    for n in names:
        err = [r[f"{n}_error"] for r in rows]
        over = [r[f"{n}_over_input"] for r in rows]
        lines.append(f"**{n}**: error over OIDN's geometric mean {np.exp(np.mean(np.log(err))):.3f}, worst "
                     f"{max(err):.3f} ({rows[int(np.argmax(err))]['input']}), {sum(e <= ERROR_TARGET for e in err)} "
                     f"of {len(err)} within {ERROR_TARGET}; over the input's at most {max(over):.3f}; blocks within "
                     + ", ".join(f"{sum(r[f'{n}_b{b}'] <= BLOCK_TARGET for r in rows)} of {len(rows)} at {b}"
                                 for b in BLOCKS)
                     + f"; ledger at most {max(r[f'{n}_ledger'] for r in rows):.0e}.\n")
    hard = [r["input"] for r in rows if min(r["floor_b32"], r["floor_b64"]) > ERROR_TARGET]
    lines.append(f"Renders whose true 32 and 64 px block energies, carried by OIDN's picture, already cost "
                 f"more than {ERROR_TARGET}x OIDN's error: {', '.join(hard) if hard else 'none'}.\n")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
