"""The figure at the top of the README: one render at final resolution, as epfilt, Intel OIDN
(run as its users run it, with the render's albedo and normal), OIDN then `epfilt restore`, and
the reference leave it, each panel labelled with its error and energy against the reference.

* error: relMSE = mean (x - ref)^2 / (ref^2 + 1e-2) over pixels and channels (as
  restore_truth.py);
* energy: the panel's total over the reference's, summed over R, G and B.

Writes `figure.png` (by `epfilt preview --montage`) and `figure.md` (the same figures as a table,
with the command, machine, versions and date) into `--out` (default docs). Run by
`scripts/readme-figure`.
"""

import argparse
import datetime
import os
import platform
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from restore_truth import denoise, rel_mse, rgb  # noqa: E402


def run(binary, *args):
    subprocess.run([binary, *args], check=True)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--render", required=True, help="<scene>_px_<res>_spp<N>.exr, with guide passes")
    p.add_argument("--ref", required=True, help="its reference")
    p.add_argument("--binary", default="target/release/epfilt")
    p.add_argument("--out", default="docs")
    p.add_argument("--width", type=int, default=256, help="each panel's width in the PNG")
    p.add_argument("--command", default="scripts/readme-figure")
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        filtered = os.path.join(tmp, "epfilt.exr")
        run(a.binary, "filter", "-q", a.render, filtered)
        oidn, aux = denoise(a.render, tmp)
        restored = os.path.join(tmp, "restored.exr")
        run(a.binary, "restore", "-q", oidn, a.render, restored)
        panels = [
            ("render", a.render),
            ("epfilt", filtered),
            ("OIDN", oidn),
            ("OIDN + restore", restored),
            ("reference", a.ref),
        ]
        ref = rgb(a.ref)
        rows = []
        for name, path in panels:
            x = rgb(path)
            rows.append((name, path, rel_mse(x, ref), float(x.sum() / ref.sum())))
        labels = [f"{n}\nrelMSE {e:.4f}\nenergy {g:.4f}" for n, _, e, g in rows]
        png = os.path.join(a.out, "figure.png")
        run(a.binary, "preview", "--montage", "--width", str(a.width), "--labels", ",".join(labels),
            *[path for _, path, _, _ in rows], png)
    version = subprocess.run([a.binary, "--version"], capture_output=True, text=True).stdout.strip()
    cpu = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name")),
               platform.processor())
    md = [
        "# figure",
        "",
        f"Made by `{a.command}` on {cpu} ({os.cpu_count()} cores), {version}, numpy {np.__version__}, "
        f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC.",
        "",
        f"![the render, epfilt, OIDN, OIDN + restore, the reference](figure.png)",
        "",
        f"`{os.path.basename(a.render)}` against `{os.path.basename(a.ref)}`. epfilt: `epfilt filter` at "
        f"its defaults. OIDN: pyoidn, HDR, quality high, with the render's {' and '.join(aux) or 'colour alone'}. "
        "OIDN + restore: `epfilt restore` at its defaults. relMSE = mean (x - ref)^2 / (ref^2 + 1e-2); "
        "energy: the total over the reference's.",
        "",
        "| panel | relMSE | energy / reference's |",
        "|---|---|---|",
    ]
    md += [f"| {n} | {e:.5f} | {g:.5f} |" for n, _, e, g in rows]
    text = "\n".join(md) + "\n"
    with open(os.path.join(a.out, "figure.md"), "w") as f:
        f.write(text)
    print(text, end="")


if __name__ == "__main__":
    main()
