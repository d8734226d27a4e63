"""What a render's variance pass does for `epfilt restore` where the render has no guide passes.

For every `<scene>_px_<res>_spp<N>.exr` beside its `<scene>_ref_<res>.exr` in the folders given,
OIDN (`pyoidn`, HDR, colour only, quality high) denoises the render and `epfilt restore` (the
command line, on OIDN's output written as a PFM, as `oidnDenoise` writes it) restores it three ways:

* **as written**: onto the render as the renderer wrote it (its emission guide where it has one,
  else its variance pass);
* **no guide, variance**: onto a copy of the render without its `emission.*` channels, so that
  its variance pass and sample count stand in (`variance_guide` in the report);
* **no guide, gain only**: the same copy with `--guides none`: the keep gain alone tells lamps
  from fireflies.

Each figure is relMSE(restored) / relMSE(OIDN) against the reference (relMSE = mean (x - ref)^2 /
(ref^2 + 1e-2)); "kept" is the share of the energy kept in place. Prints Markdown; run by
`scripts/restore-variance`.
"""

import argparse
import glob
import json
import os
import re
import subprocess
import sys
import tempfile

import numpy as np
import OpenEXR
import pyoidn

import epfilt


def rel_mse(x, ref):
    return float(np.mean((x.astype(np.float64) - ref) ** 2 / (ref.astype(np.float64) ** 2 + 1e-2)))


def write_pfm(path, img):
    h, w, _ = img.shape
    with open(path, "wb") as f:
        f.write(b"PF\n%d %d\n-1.0\n" % (w, h))
        f.write(np.ascontiguousarray(img[::-1].astype("<f4")).tobytes())


def without_guide(src, dst):
    """`src` without its emission guide channels, every other channel and attribute kept."""
    f = OpenEXR.File(src)
    channels = {k: v for k, v in f.channels().items() if not k.startswith("emission")}
    OpenEXR.File(dict(f.header()), channels).write(dst)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--renders", action="append", required=True, help="a folder of renders (repeatable)")
    ap.add_argument("--bin", default="target/release/epfilt")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        d_path, e_path, o_path = (os.path.join(tmp, n) for n in ("d.pfm", "e.exr", "o.exr"))

        def restore(energy, *extra):
            rep = json.loads(subprocess.run(
                [a.bin, "restore", "-q", d_path, energy, o_path, "--report", "-", *extra],
                capture_output=True, check=True, text=True).stdout)
            return epfilt.read(o_path)[0][:, :, :3], rep

        print("| render | reference spp | OIDN's error | as written | guide | no guide, variance | kept | "
              "no guide, gain only | kept |")
        print("|---|---|---|---|---|---|---|---|---|")
        for folder in a.renders:
            # The references' sample counts, as the folder's manifest gives them
            # (`render-scenes --quick` renders them at 1/16 of the samples).
            try:
                with open(os.path.join(folder, "manifest.json")) as f:
                    spp = {e["file"]: e.get("spp") for e in json.load(f)["files"]}
            except (OSError, ValueError, KeyError):
                spp = {}
            for path in sorted(glob.glob(os.path.join(folder, "*_px_*_spp*.exr"))):
                m = re.match(r"(.*)_px_(\d+)_spp(\d+)\.exr$", os.path.basename(path))
                ref_path = os.path.join(folder, f"{m.group(1)}_ref_{m.group(2)}.exr")
                if not os.path.exists(ref_path):
                    continue
                ref = epfilt.read(ref_path)[0][:, :, :3].astype(np.float64)
                inp = np.ascontiguousarray(epfilt.read(path)[0][:, :, :3])
                d = np.ascontiguousarray(pyoidn.denoise(inp, hdr=True, quality="high"), dtype=np.float32)
                write_pfm(d_path, d)
                oidn = rel_mse(d, ref)
                without_guide(path, e_path)
                written, rw = restore(path)
                var, rv = restore(e_path)
                gain, rg = restore(e_path, "--guides", "none")
                guide = "emission" if rw["emission_guide"] else "variance" if rw["variance_guide"] else "none"
                ref_spp = spp.get(os.path.basename(ref_path), "?")
                print(f"| {os.path.basename(path)[:-4]} | {ref_spp} | {oidn:.4f} | {rel_mse(written, ref) / oidn:.3f} | "
                      f"{guide} | {rel_mse(var, ref) / oidn:.3f} | {rv['kept_share']:.3f} | "
                      f"{rel_mse(gain, ref) / oidn:.3f} | {rg['kept_share']:.3f} |", flush=True)
                print(f"{m.group(0)}: done", file=sys.stderr)


if __name__ == "__main__":
    main()
