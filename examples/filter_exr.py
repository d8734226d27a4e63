#!/usr/bin/env python3
"""Filter a super-sampled EXR with epfilt's Python bindings, reading and writing it
with the OpenEXR package (pip install ./python OpenEXR), and print the energy ledger.

    python examples/filter_exr.py render_3x.exr filtered.exr [--supersample 3] [--tolerance 0.08]

Without arguments it makes its own input first (`epfilt synth`, if the binary is on PATH
or built in target/release).
"""

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import OpenEXR

import epfilt


def read_rgb(path):
    """The image's R, G, B samples as a (height, width, 3) array (float32 or float16)."""
    with OpenEXR.File(str(path)) as f:
        channels = f.channels()
        if "RGB" in channels:
            return channels["RGB"].pixels
        if "RGBA" in channels:
            return channels["RGBA"].pixels[:, :, :3]
        return np.dstack([channels[c].pixels for c in "RGB"])


def write_rgb(path, pixels):
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": pixels}) as f:
        f.write(str(path))


def demo_input(folder):
    exe = shutil.which("epfilt") or Path(__file__).resolve().parents[1] / "target/release/epfilt"
    path = Path(folder) / "mixed_3x.exr"
    subprocess.run([str(exe), "synth", "-q", "--scene", "mixed", "--size", "320x200", "-o", str(path)], check=True)
    return path


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("input", nargs="?")
    ap.add_argument("output", nargs="?", default="filtered.exr")
    ap.add_argument("--supersample", type=int, default=3)
    ap.add_argument("--tolerance", type=float, default=None, help="Relation 14's tolerance (default: the library's)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(args.input) if args.input else demo_input(tmp)
        samples = read_rgb(src)
        print(f"{src}: {samples.shape[1]}x{samples.shape[0]} samples, {samples.dtype}")
        try:
            image, report = epfilt.filter(samples, supersample=args.supersample, tolerance=args.tolerance)
        except epfilt.Error as e:
            sys.exit(f"epfilt: {e}")
        write_rgb(args.output, image)
    print(f"{args.output}: {image.shape[1]}x{image.shape[0]} pixels in {report['seconds']:.2f} s, "
          f"{report['samples_spread']} samples spread, {report['samples_kept']} kept as features")
    print("channel  energy in            energy out           relative error")
    for name, e_in, e_out, err in zip(report["channels"], report["energy_in"], report["energy_out"],
                                      report["energy_rel_error"]):
        print(f"{name:8} {e_in:<20.12g} {e_out:<20.12g} {err:.1e}")


if __name__ == "__main__":
    main()
