"""Pictures a user looks at: per-face panels, target | prediction | ΔE76 figures and loss curves.

Inputs are per-texel linear RGB (I, 3) and, for a face, ``pix`` (H, W) int: the texel index shown at each pixel
(row 0 = top of the picture; negative = no texel, drawn grey). Files are written atomically (``inkopt.io``).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .color import to_srgb8
from .io import save_figure

if TYPE_CHECKING:
    from PIL import Image

PANEL_MIN_WIDTH = 256


def face_image(rgb, pix) -> np.ndarray:
    """Per-texel linear RGB (I, 3) -> (H, W, 3) uint8 sRGB picture of a face (``pix`` (H, W) texel indices)."""
    pix = np.asarray(pix, np.int64)
    img = to_srgb8(np.asarray(rgb, np.float64)[np.maximum(pix, 0)])
    img[pix < 0] = 128
    return img


def panels(items, pix) -> Image.Image:
    """Side-by-side labelled panels: items = [(label, rgb (I, 3) linear)]; nearest-neighbour upscaling to at
    least ``PANEL_MIN_WIDTH`` px per panel."""
    from PIL import Image, ImageDraw

    h, w = np.asarray(pix).shape
    s = max(1, int(np.ceil(PANEL_MIN_WIDTH / w)))
    gap, band = 8, 20
    pw, ph = w * s, h * s
    canvas = Image.new("RGB", (len(items) * pw + (len(items) + 1) * gap, ph + band + gap), (255, 255, 255))
    draw = ImageDraw.Draw(canvas)
    for j, (label, rgb) in enumerate(items):
        img = np.repeat(np.repeat(face_image(rgb, pix), s, 0), s, 1)
        x0 = gap + j * (pw + gap)
        canvas.paste(Image.fromarray(img), (x0, band))
        draw.text((x0, 4), label, fill=(0, 0, 0))
    return canvas


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def error_figure(path: Path, title: str, target_rgb, pred_rgb, delta_e, pix) -> Path:
    """target | predicted print | ΔE76 heat map of one face (``delta_e`` (I,) per texel)."""
    plt = _pyplot()
    pix = np.asarray(pix)
    fig, ax = plt.subplots(1, 3, figsize=(13, 4.6 * pix.shape[0] / pix.shape[1] + 0.8))
    ax[0].imshow(face_image(target_rgb, pix), interpolation="nearest")
    ax[0].set_title(f"{title}: target")
    ax[1].imshow(face_image(pred_rgb, pix), interpolation="nearest")
    ax[1].set_title("predicted print")
    im = ax[2].imshow(
        delta_e[pix], cmap="magma", vmin=0, vmax=max(10.0, float(np.percentile(delta_e, 99))), interpolation="nearest"
    )
    ax[2].set_title(f"ΔE76 (mean {delta_e[pix].mean():.2f})")
    fig.colorbar(im, ax=ax[2], fraction=0.046, pad=0.04)
    for a in ax:
        a.set_xticks([])
        a.set_yticks([])
    save_figure(path, fig)
    plt.close(fig)
    return Path(path)


def loss_figure(path: Path, loss, delta_e76) -> Path:
    """The loss (log scale) and the training mean ΔE76 per iteration."""
    plt = _pyplot()
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    it = np.arange(1, len(loss) + 1)
    ax[0].plot(it, loss, lw=1)
    ax[0].set_yscale("log")
    ax[0].set_xlabel("iteration")
    ax[0].set_title("loss E")
    ax[1].plot(it, delta_e76, lw=1, color="C1")
    ax[1].set_xlabel("iteration")
    ax[1].set_title("mean ΔE76 (training spp)")
    for a in ax:
        a.grid(alpha=0.3)
    save_figure(path, fig)
    plt.close(fig)
    return Path(path)
