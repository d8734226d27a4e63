"""Radiance pictures written by OpenCV (its rgbe.cpp, from Greg Ward's
rgbe.c), for tests/behaviour/rgbe.rs. Each NAME.hdr comes with NAME.f32: the
values OpenCV reads back, little-endian f32, rows top to bottom, R G B per
pixel. OpenCV decodes a mantissa m as m * 2^(e-136); Radiance (and epfilt)
as (m + 0.5) * 2^(e-136).

    pip install opencv-python-headless numpy && python make_opencv.py
"""
import cv2
import numpy as np

def image(w, h):
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    r = 0.01 + 3.0 * np.exp(-((x - w / 3) ** 2 + (y - h / 2) ** 2) / 20.0)
    g = np.where((x // 4) % 2 == 0, 0.5, 0.5 + 0.1 * x)  # runs and literals
    b = 10.0 ** (-3 + 6 * ((x * 7 + y * 3) % 11) / 10.0)  # 1e-3 .. 1e3
    r[0, 0] = 0.0
    return np.dstack([r, g, b]).astype(np.float32)

for name, (w, h) in {"opencv_rle": (37, 6), "opencv_flat": (5, 3)}.items():
    rgb = image(w, h)
    assert cv2.imwrite(name + ".hdr", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    back = cv2.imread(name + ".hdr", cv2.IMREAD_UNCHANGED)
    back = cv2.cvtColor(back, cv2.COLOR_BGR2RGB).astype("<f4")
    back.tofile(name + ".f32")
