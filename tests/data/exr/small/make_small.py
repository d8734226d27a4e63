#!/usr/bin/env python3
"""Write the small files of tests/data/exr/small/ with the reference OpenEXR library.

They fill what the corpus subset beside them lacks at a size fit for the
repository: DWAA, DWAB and B44 scan lines and tiles, NaN/Inf samples, and a
multi-layer render (beauty + light AOVs that sum to it, depth, normals, ids).
Written by the PyPI `openexr` 3.5.3 bindings (OpenEXR 3.5.3), never by the Rust
`exr` crate, so the reader is tested against another writer. Deterministic.

Run from tests/data/exr:   python3 small/make_small.py
Needs: pip install openexr==3.5.3 numpy
"""
import os

import numpy as np
import OpenEXR

OUT = "small"


def tiles(x, y):
    t = OpenEXR.TileDescription()
    t.xSize, t.ySize, t.mode, t.roundingMode = x, y, OpenEXR.ONE_LEVEL, OpenEXR.ROUND_DOWN
    return t


def write(name, header, channels):
    header = dict(header)
    header.setdefault("type", OpenEXR.scanlineimage)
    with OpenEXR.File(header, channels) as f:
        f.write(os.path.join(OUT, name))


def main():
    os.makedirs(OUT, exist_ok=True)
    # A real picture: the top-left 66x48 of DisplayWindow/t01.exr (B,G,R half).
    with OpenEXR.File("DisplayWindow/t01.exr") as src:
        px = src.channels()["RGB"].pixels  # rows x columns x (R, G, B)
        rgb = {c: np.array(px[100:148, 120:186, k], dtype=np.float16) for k, c in enumerate("RGB")}
    h, w = rgb["R"].shape
    yy, xx = np.mgrid[0:h, 0:w]
    alpha = np.clip((xx + yy) / float(w + h) * 1.5, 0.0, 1.0).astype(np.float16)
    depth = (10.0 + xx * 0.25 + yy * 0.125).astype(np.float32)

    # DWAA: R,G,B go through the lossy DCT (AC and DC sections), A through RLE.
    write("dwaa_half_rgba.exr", {"compression": OpenEXR.DWAA_COMPRESSION},
          {**rgb, "A": alpha})
    # DWAB with a float channel: Z lands in the UNKNOWN (zlib) section.
    write("dwab_half_rgb_float_z.exr", {"compression": OpenEXR.DWAB_COMPRESSION},
          {**rgb, "Z": depth})
    # Tiled DWAA.
    write("dwaa_tiled_half_rgb.exr",
          {"compression": OpenEXR.DWAA_COMPRESSION, "type": OpenEXR.tiledimage,
           "tiles": tiles(32, 16)}, dict(rgb))
    write("b44_half_rgb.exr", {"compression": OpenEXR.B44_COMPRESSION}, dict(rgb))
    write("b44a_half_rgba.exr", {"compression": OpenEXR.B44A_COMPRESSION},
          {**rgb, "A": alpha})

    # NaN and infinities among ordinary samples (half), ZIP.
    bad = {c: v.copy() for c, v in rgb.items()}
    bad["R"][3, 4] = np.float16("nan")
    bad["G"][10, 20] = np.float16("inf")
    bad["B"][30, 60] = np.float16("-inf")
    write("nan_inf_half_rgb.exr", {"compression": OpenEXR.ZIP_COMPRESSION}, bad)

    # A multi-layer render, 48x48 float: light AOVs whose sum is the beauty,
    # depth, normals and an object id, as renderers write them.
    n = 48
    yy, xx = np.mgrid[0:n, 0:n]
    rng = np.random.default_rng(7)
    diffuse = {c: (0.2 + 0.1 * k + 0.3 * np.sin(xx / 5.0 + k) ** 2).astype(np.float32)
               for k, c in enumerate("RGB")}
    specular = {c: np.where(rng.random((n, n)) < 0.03, 50.0 * (k + 1), 0.02).astype(np.float32)
                for k, c in enumerate("RGB")}
    emission = {c: np.where((xx - 30) ** 2 + (yy - 12) ** 2 < 4, 200.0, 0.0).astype(np.float32)
                for c in "RGB"}
    beauty = {c: (diffuse[c] + specular[c] + emission[c]).astype(np.float32) for c in "RGB"}
    layers = {**beauty, "A": np.ones((n, n), np.float32)}
    for name, aov in (("diffuse", diffuse), ("specular", specular), ("emission", emission)):
        layers.update({f"{name}.{c}": v for c, v in aov.items()})
    layers["Z"] = (5.0 + xx * 0.1).astype(np.float32)
    nz = np.sqrt(np.maximum(0.0, 1.0 - 0.25 - 0.25)).astype(np.float32)
    layers.update({"N.X": np.full((n, n), 0.5, np.float32),
                   "N.Y": np.full((n, n), 0.5, np.float32),
                   "N.Z": np.full((n, n), nz, np.float32)})
    layers["id"] = ((xx // 12) + 10 * (yy // 12)).astype(np.uint32)
    write("aovs_multilayer.exr", {"compression": OpenEXR.ZIP_COMPRESSION}, layers)


if __name__ == "__main__":
    main()
