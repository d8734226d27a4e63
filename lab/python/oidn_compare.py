"""When to use epfilt, Intel OIDN or both, measured on renders at final resolution.

For every `<scene>_px_<res>_spp<N>.exr` beside its `<scene>_ref_<res>.exr` in the folders given:

* **OIDN**: Intel Open Image Denoise (`pyoidn`, the RT filter, HDR, quality high), with the
  render's albedo and normal passes where it has them, as its users run it;
* **epfilt**: `epfilt.filter_file` with its defaults (the file decides: ep-box where it holds
  variance, else ep-gauss; the guide passes it finds);
* **ep-gauss**: the same with `method="ep-gauss"`, what a render without a variance pass gets;
* **epfilt then OIDN**: OIDN on epfilt's output;
* **OIDN then restore**: `epfilt.restore` of OIDN's output with the render's energy, at its
  default scale (every 32 x 32 block and the total hold the render's energy), and the same at
  other scales for the scale's trade; with the render's emission guide where it has one
  (`emission=`, as `epfilt restore` reads it from the file);
* **OIDN then restore onto epfilt**: the same with epfilt's output as the energy (its fireflies
  already spread; its blocks are epfilt's, not the render's), at the keep gain `restore` takes
  from such a file's header (`KEEP_GAIN_FILTERED`).

* **restore by luminance**: the choice `restore` did not take, measured: OIDN's output restored
  on luminance (one channel, with the render's energy and emission guide as luminance), then its
  colour kept (each pixel's channels scaled by the restored luminance over OIDN's); luminance is
  exact, each channel not.

Measures, each against the reference:

* **error**: relMSE(output) / relMSE(input), relMSE = mean (x - ref)^2 / (ref^2 + 1e-2) over
  pixels and channels (below 1: less error than the render had);
* **energy**: sum(output) / sum(input) - 1 over every channel (epfilt's ledger makes it 0 before
  rounding; the input's own energy against the reference's is in the `input` column);
* **peaks**: over the reference's brightest 0.1% of pixels by luminance, the output's mean
  luminance over the reference's (1: the brightest features kept at their true values);
* **blocks**: the largest relative difference, over the 32 x 32 blocks, between the output's
  energy and the input's (what a lighting study reads off a region);
* **peaks in**: the same brightest pixels, the output's mean luminance over the input's (what
  restore keeps: the render's own values there);
* **block floor**: the least relMSE any image can have whose 32 x 32 blocks hold the energy
  image's energy within 2% (the issue's block target), in closed form: per block, the part of the
  energy image's difference from the reference's beyond 2%, squared, over the block's sum of the
  relMSE weights `ref^2 + 1e-2` (the least-squares correction of the reference onto the block's sum),
  summed and taken over OIDN's relMSE: how much of restore's error the block target itself forces.

Writes `oidn.md` and `oidn.csv` into `--out` (default docs/bench) with the command, machine,
versions and date, and prints the Markdown. Run by `scripts/oidn-compare`.
"""

import argparse
import csv
import importlib.metadata
import datetime
import glob
import io
import os
import platform
import re
import subprocess
import sys
import tempfile

import numpy as np
import pyoidn

import epfilt

# The reference's brightest pixels whose values the peaks measure: 0.1%.
PEAK_SHARE = 1e-3
# Blocks whose energy the blocks column compares, in pixels.
BLOCK = 32
# restore's scales whose trade the last table measures (block sides, pixels).
SCALES = (8, 16, 32, 64, 128)
# The keep gain `epfilt restore` takes where the energy image is epfilt's ep-gauss or ep-box
# output (filter::restore::KEEP_GAIN_FILTERED; arrays carry no header to say so).
KEEP_GAIN_FILTERED = 1.0
# relMSE's floor in the denominator, as the renders evaluation has it.
REL_EPS = 1e-2
LUM = np.array([0.2126, 0.7152, 0.0722])


def rgb(path):
    samples, names = epfilt.read(path)
    idx = [names.index(c) for c in ("R", "G", "B")]
    return np.ascontiguousarray(samples[:, :, idx].astype(np.float32))


def emission_of(path):
    """The render's emission guide (R, G, B), or None where it has none."""
    try:
        samples, _ = epfilt.read(path, ["emission.R", "emission.G", "emission.B"])
    except (epfilt.InputError, epfilt.ConfigError, ValueError):
        return None
    return np.ascontiguousarray(samples[:, :, 3:6])


def rel_mse(x, ref):
    return float(np.mean((x.astype(np.float64) - ref) ** 2 / (ref.astype(np.float64) ** 2 + REL_EPS)))


def block_sums(x):
    h, w = x.shape[:2]
    hb, wb = h // BLOCK, w // BLOCK
    y = x[: hb * BLOCK, : wb * BLOCK].astype(np.float64).sum(axis=2)
    return y.reshape(hb, BLOCK, wb, BLOCK).sum(axis=(1, 3))


def block_floor(energy, ref, tol=0.02):
    """The least relMSE of any image whose block sums lie within `tol` of `energy`'s (see above)."""
    r = ref.astype(np.float64)
    h, w = r.shape[:2]
    weights = (r[: h // BLOCK * BLOCK, : w // BLOCK * BLOCK] ** 2 + REL_EPS).sum(axis=2)
    weights = weights.reshape(h // BLOCK, BLOCK, w // BLOCK, BLOCK).sum(axis=(1, 3))
    e, t = block_sums(energy), block_sums(ref)
    beyond = np.maximum(0.0, np.abs(e - t) - tol * np.abs(e))
    return float((beyond ** 2 / weights).sum() / r.size)


def measures(out, inp, ref, top):
    lum = out.astype(np.float64) @ LUM
    rlum = ref.astype(np.float64) @ LUM
    bi, bo = block_sums(inp), block_sums(out)
    return {
        "error": rel_mse(out, ref) / rel_mse(inp, ref),
        "energy": float(out.astype(np.float64).sum() / inp.astype(np.float64).sum() - 1.0),
        "peaks": float(lum[top].mean() / rlum[top].mean()),
        "blocks": float(np.max(np.abs(bo - bi) / np.maximum(np.abs(bi), 1e-12))),
        "peaks_in": float(lum[top].mean() / (inp.astype(np.float64) @ LUM)[top].mean()),
    }


def restore_by_luminance(denoised, energy, emission):
    """`restore` on luminance with the denoiser's colour kept (see above): the image, and the most
    a channel's total moved against the energy's."""
    y = lambda a: np.ascontiguousarray((a.astype(np.float64) @ LUM).astype(np.float32)[..., None])
    yd = y(denoised)
    ry, _ = epfilt.restore(yd, y(energy), emission=None if emission is None else y(emission),
                           channels=["Y"])
    out = (denoised * np.where(yd > 0, ry / np.maximum(yd, 1e-30), 1.0)).astype(np.float32)
    moved = out.astype(np.float64).sum(axis=(0, 1)) / energy.astype(np.float64).sum(axis=(0, 1)) - 1
    return out, float(np.abs(moved).max())


def aux_of(path):
    """The render's albedo and normal passes (found as `epfilt info` reports them), each None
    where it has none: OIDN as its users run it."""
    guides = epfilt.info(path)["parts"][0].get("guide_channels", {})
    out = []
    for kind in ("albedo", "normal"):
        names = guides.get(kind, [])
        if len(names) == 3:
            samples, _ = epfilt.read(path, names)
            out.append(np.ascontiguousarray(samples[:, :, -3:]))
        else:
            out.append(None)
    return tuple(out)


def oidn(x, aux=(None, None)):
    albedo, normal = aux
    return np.ascontiguousarray(pyoidn.denoise(x, albedo, normal, hdr=True, quality="high"),
                                dtype=np.float32)


def inputs(folders):
    found = []
    for d in folders:
        for p in sorted(glob.glob(os.path.join(d, "*_px_*_spp*.exr"))):
            m = re.match(r"(.*)_px_(\d+)_spp(\d+)\.exr$", os.path.basename(p))
            ref = os.path.join(d, f"{m.group(1)}_ref_{m.group(2)}.exr")
            if os.path.exists(ref):
                found.append((p, ref, m.group(1), int(m.group(3))))
    return found


def out(cmd):
    try:
        return subprocess.run(cmd, capture_output=True, text=True).stdout.strip()
    except OSError:
        return "?"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--renders", action="append", required=True, help="a folder of renders (repeatable)")
    ap.add_argument("--out", default="docs/bench")
    ap.add_argument("--command", default="scripts/oidn-compare")
    a = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for path, ref_path, scene, spp in inputs(a.renders):
            inp, ref = rgb(path), rgb(ref_path)
            rlum = ref.astype(np.float64) @ LUM
            k = max(1, int(round(PEAK_SHARE * rlum.size)))
            top = np.unravel_index(np.argsort(rlum, axis=None)[-k:], rlum.shape)
            filtered = os.path.join(tmp, "ep.exr")
            report = epfilt.filter_file(path, filtered)
            ep = rgb(filtered)
            epfilt.filter_file(path, filtered, method="ep-gauss")
            gauss = rgb(filtered)
            row = {"input": os.path.basename(path)[:-4], "spp": spp, "method": report["method"],
                   "input_rel_mse": rel_mse(inp, ref),
                   "input_energy_vs_ref": float(inp.astype(np.float64).sum() / ref.astype(np.float64).sum() - 1),
                   "input_peaks": measures(inp, inp, ref, top)["peaks"]}
            aux = aux_of(path)
            denoised = oidn(inp, aux)
            em = emission_of(path)
            row["emission_guide"] = em is not None
            restored, rep = epfilt.restore(denoised, inp, emission=em)
            row["restore_kept_share"] = rep["kept_share"]
            onto_ep, rep = epfilt.restore(denoised, ep, keep_gain=KEEP_GAIN_FILTERED, emission=em)
            row["restore_ep_kept_share"] = rep["kept_share"]
            oidn_rel = rel_mse(denoised, ref)
            row["floor_render"] = block_floor(inp, ref) / oidn_rel
            row["floor_ep"] = block_floor(ep, ref) / oidn_rel
            for name, img in (("oidn", denoised), ("epfilt", ep), ("ep_gauss", gauss),
                              ("epfilt_oidn", oidn(ep, aux)), ("oidn_restore", restored),
                              ("oidn_restore_ep", onto_ep)):
                for key, v in measures(img, inp, ref, top).items():
                    row[f"{name}_{key}"] = v
            for k in SCALES:
                img, _ = epfilt.restore(denoised, inp, k, emission=em)
                for key, v in measures(img, inp, ref, top).items():
                    row[f"restore{k}_{key}"] = v
            by_lum, moved = restore_by_luminance(denoised, inp, em)
            row["restore_luminance_error"] = rel_mse(by_lum, ref) / rel_mse(inp, ref)
            row["restore_luminance_channel_moved"] = moved
            rows.append(row)
            print(f"{row['input']}: done", file=sys.stderr)
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.out, "oidn.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)
    md = io.StringIO()
    cpu = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name")),
               platform.processor())
    print("# When to use epfilt, OIDN or both\n", file=md)
    print(f"Made by `{a.command}` ({', '.join(a.renders)}) on {cpu} ({os.cpu_count()} cores), epfilt "
          f"{epfilt.__version__} ({out(['git', 'rev-parse', '--short', 'HEAD'])}), OIDN through pyoidn "
          f"{importlib.metadata.version('pyoidn')}, numpy {np.__version__}, Python {platform.python_version()}, "
          f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC. "
          "`lab/python/oidn_compare.py` defines every measure.\n", file=md)
    print("**error**: relMSE(output) / relMSE(input) against the reference (below 1: less error than the "
          "render had); **energy**: the output's total over the input's, less 1; **peaks**: the mean "
          "luminance of the reference's brightest 0.1% of pixels, output over reference (1: kept at their "
          "true values; the input's own in its column); **blocks**: the largest relative change of a 32 x 32 "
          "block's energy against the input. OIDN: with the render's albedo and normal where it has them, HDR, quality high. epfilt: `filter_file` "
          "at its defaults (method and guides from the file; the method is named beside each input); "
          "ep-gauss: the same without the variance, as a render without a variance pass gets.\n", file=md)
    names = (("oidn", "OIDN"), ("epfilt", "epfilt"), ("ep_gauss", "ep-gauss"),
             ("epfilt_oidn", "epfilt then OIDN"), ("oidn_restore", "OIDN then restore"),
             ("oidn_restore_ep", "OIDN then restore onto epfilt"))
    formats = {"error": "{:.3f}", "energy": "{:+.3%}", "peaks": "{:.2f}", "blocks": "{:.1%}",
               "peaks_in": "{:.2f}"}
    for key, title in (("error", "Error (relMSE over the input's)"), ("energy", "Energy moved"),
                       ("peaks", "The brightest 0.1%, over the reference's"),
                       ("peaks_in", "The brightest 0.1%, over the input's"),
                       ("blocks", "The most a 32 x 32 block's energy moved")):
        print(f"## {title}\n", file=md)
        extra = {"error": "relMSE in", "energy": "input over reference", "peaks": "input",
                 "blocks": "", "peaks_in": ""}[key]
        head = ["input"] + ([extra] if extra else []) + [label for _, label in names]
        print("| " + " | ".join(head) + " |", file=md)
        print("|" + "---|" * len(head), file=md)
        for r in rows:
            lead = {"error": f"{r['input_rel_mse']:.4f}", "energy": f"{r['input_energy_vs_ref']:+.2%}",
                    "peaks": f"{r['input_peaks']:.2f}", "blocks": None, "peaks_in": None}[key]
            cells = [r["input"] + (f" ({r['method']})" if key == "error" else "")]
            cells += [lead] if lead is not None else []
            cells += [formats[key].format(r[f"{n}_{key}"]) for n, _ in names]
            print("| " + " | ".join(cells) + " |", file=md)
        print("", file=md)
    print("", file=md)

    def summary(n):
        e = [r[n + "_error"] for r in rows]
        en = [abs(r[n + "_energy"]) for r in rows]
        pk = [abs(r[n + "_peaks"] - 1) for r in rows]
        bl = [r[n + "_blocks"] for r in rows]
        return (f"error {min(e):.3f} to {max(e):.3f} (geometric mean {np.exp(np.mean(np.log(e))):.3f}); "
                f"energy moved up to {max(en):.2%}; peaks off by up to {max(pk):.0%}; blocks up to {max(bl):.1%}")
    print(f"Over {len(rows)} renders:\n", file=md)
    for n, label in names:
        print(f"* **{label}**: {summary(n)}.", file=md)
    print("", file=md)
    print("## restore's scale\n", file=md)
    print("OIDN then `restore` with the render's energy in blocks of each side: error over OIDN's "
          "alone (geometric mean and worst over the renders, and how many within 1.2x), the most a "
          "32 x 32 block's energy moved against the input, and the brightest 0.1% of the reference's "
          "pixels against the input's values there (mean distance from 1, and the farthest). Small "
          "blocks: energy exact in small regions, the render's grain back; large: OIDN's look, "
          "energy exact over large regions only.\n", file=md)
    print("| scale | error over OIDN's (geometric mean) | worst | within 1.2x | blocks moved (most) | "
          "peaks over the input's (mean distance) | farthest |", file=md)
    print("|---|---|---|---|---|---|---|", file=md)
    for k in SCALES:
        ratio = [r[f"restore{k}_error"] / r["oidn_error"] for r in rows]
        blocks = max(r[f"restore{k}_blocks"] for r in rows)
        pk = [abs(r[f"restore{k}_peaks_in"] - 1) for r in rows]
        print(f"| {k} | {np.exp(np.mean(np.log(ratio))):.2f}x | {max(ratio):.2f}x | "
              f"{sum(x <= 1.2 for x in ratio)} of {len(ratio)} | {blocks:.1%} | {np.mean(pk):.1%} | "
              f"{max(pk):.0%} |", file=md)
    ratio = [r["oidn_restore_error"] / r["oidn_error"] for r in rows]
    onto = [r["oidn_restore_ep_error"] / r["oidn_error"] for r in rows]
    print("\nAt the default scale, per render: error over OIDN's, peaks over the input's, the "
          "share of the energy kept in place (what OIDN lost: lamps, bulbs, highlights), and the block "
          "floor (the least error over OIDN's that any image with the energy's 32 x 32 blocks within 2% "
          "has: what the block target alone forces); then the same with epfilt's output as the energy "
          "(its peaks over the input's). Restore reads the render's emission guide where it has one "
          "(named beside the input).\n", file=md)
    print("| input | error over OIDN's | OIDN's peaks over the input's | restore's | kept in place | "
          "block floor | onto epfilt: error over OIDN's | peaks | kept in place | block floor |", file=md)
    print("|---|---|---|---|---|---|---|---|---|---|", file=md)
    for r, x, y in zip(rows, ratio, onto):
        guide = " (emission guide)" if r["emission_guide"] else ""
        print(f"| {r['input']}{guide} | {x:.2f}x | {r['oidn_peaks_in']:.2f} | {r['oidn_restore_peaks_in']:.2f} | "
              f"{r['restore_kept_share']:.1%} | {r['floor_render']:.3f}x | {y:.2f}x | "
              f"{r['oidn_restore_ep_peaks_in']:.2f} | {r['restore_ep_kept_share']:.1%} | "
              f"{r['floor_ep']:.3f}x |", file=md)
    for label, xs, fl in (("the render's", ratio, "floor_render"), ("epfilt's", onto, "floor_ep")):
        print(f"\nWith {label} energy: error over OIDN's geometric mean "
              f"{np.exp(np.mean(np.log(xs))):.2f}x, worst {max(xs):.2f}x, "
              f"{sum(x <= 1.2 for x in xs)} of {len(xs)} within 1.2x; the block floor at most "
              f"{max(r[fl] for r in rows):.3f}x.", file=md)
    print("\n## Per channel or by luminance\n", file=md)
    print("`restore` corrects each channel (every channel's energy exact). By luminance with OIDN's "
          "colour kept (luminance exact, each channel not), with the render's energy: error over "
          "OIDN's, and the most a channel's total moved.\n", file=md)
    lum = [r["restore_luminance_error"] / r["oidn_error"] for r in rows]
    moved = [r["restore_luminance_channel_moved"] for r in rows]
    print(f"Per channel: geometric mean {np.exp(np.mean(np.log(ratio))):.3f}x, worst {max(ratio):.2f}x; "
          f"by luminance: geometric mean {np.exp(np.mean(np.log(lum))):.3f}x, worst {max(lum):.2f}x, "
          f"{sum(x < y for x, y in zip(lum, ratio))} of {len(lum)} renders below per channel, a channel's "
          f"total moved by up to {max(moved):.2%} (median {np.median(moved):.2%}).", file=md)
    text = md.getvalue()
    with open(os.path.join(a.out, "oidn.md"), "w") as f:
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()
