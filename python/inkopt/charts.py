"""Procedural test charts (sRGB uint8 pictures): colour patches with a hue gradient, and the paper's zebra
stripes (docs/method.md §8). Used by the demo, the tests and the benchmarks, so nothing needs downloading."""

from __future__ import annotations

from pathlib import Path

import numpy as np

# A few saturated and neutral patch colours (sRGB 0-255).
PATCHES = np.array(
    [
        [220, 40, 40],
        [40, 160, 60],
        [40, 70, 200],
        [240, 200, 30],
        [30, 30, 30],
        [250, 250, 250],
        [0, 170, 200],
        [200, 40, 160],
        [240, 130, 20],
        [128, 128, 128],
        [120, 70, 30],
        [170, 200, 240],
    ],
    np.uint8,
)


def colour_chart(width: int, height: int) -> np.ndarray:
    """(height, width, 3) uint8: a 4 x 3 grid of patches over the top 3/4, a hue ramp below."""
    img = np.zeros((height, width, 3), np.uint8)
    top = (3 * height) // 4
    rows, cols = 3, 4
    for k, col in enumerate(PATCHES):
        r, c = divmod(k, cols)
        img[r * top // rows : (r + 1) * top // rows, c * width // cols : (c + 1) * width // cols] = col
    from matplotlib.colors import hsv_to_rgb

    h = np.linspace(0, 1, width, endpoint=False)
    ramp = hsv_to_rgb(np.stack([h, np.full_like(h, 0.8), np.full_like(h, 0.9)], -1))
    img[top:] = (ramp[None] * 255 + 0.5).astype(np.uint8)
    return img


def zebra(width: int, height: int, stripes=(30, 15, 10, 5, 3, 1)) -> np.ndarray:
    """(height, width, 3) uint8 black/white stripes: one band per stripe width (in pixels = voxels), stacked
    vertically, stripes running vertically."""
    img = np.zeros((height, width, 3), np.uint8)
    for b, s in enumerate(stripes):
        y0, y1 = b * height // len(stripes), (b + 1) * height // len(stripes)
        on = (np.arange(width) // s) % 2 == 0
        img[y0:y1, on] = 255
    return img


def save(img: np.ndarray, path: str | Path) -> Path:
    """Write a chart as PNG (atomically)."""
    from .io import write_png

    return write_png(path, img)
