"""selection.png: the target beside every candidate's final prediction, each with its figures."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..io import write_png
from ..pictures import PANEL_MIN_WIDTH, face_image

COLUMNS = 4


def _pix(rec) -> np.ndarray:
    """The picture layout: a slab's top face (else its first face); for a mesh, its texels in order, row by row
    (a colour mosaic, not a view)."""
    if rec.pix:
        return np.asarray(rec.pix["top"] if "top" in rec.pix else rec.pix[rec.faces[0]])
    n = len(rec.target_rgb)
    w = math.ceil(math.sqrt(n))
    pix = np.arange(w * math.ceil(n / w))
    pix[pix >= n] = -1
    return pix.reshape(-1, w)


def selection_figure(path: Path, rec, predictions) -> Path:
    """``rec``: the scene's ``SceneRecord``; ``predictions``: [(candidate entry of selection.json, rgb (I, 3)
    linear)], best first. The target comes first, then the candidates, ``COLUMNS`` to a row."""
    from PIL import Image, ImageDraw

    pix = _pix(rec)
    h, w = pix.shape
    s = max(1, math.ceil(PANEL_MIN_WIDTH / w))
    pw, ph, gap, band = w * s, h * s, 8, 44
    cells = [("target", "", rec.target_rgb)]
    for c, rgb in predictions:
        inks = ",".join(c["inks"])
        figures = (
            f"{c['iterations']} it, loss {c['loss']:.4g}\ndE76 {c['delta_e76_mean']:.2f}  dE2000 "
            f"{c['delta_e2000_mean']:.2f}  SSIM {c['ssim']:.3f}"
        )
        cells.append((inks, figures, rgb))
    cols = min(COLUMNS, len(cells))
    rows = math.ceil(len(cells) / cols)
    canvas = Image.new("RGB", (cols * (pw + gap) + gap, rows * (ph + band + gap) + gap), (255, 255, 255))
    draw = ImageDraw.Draw(canvas)
    for j, (title, figures, rgb) in enumerate(cells):
        r, c = divmod(j, cols)
        x0, y0 = gap + c * (pw + gap), gap + r * (ph + band + gap)
        draw.text((x0, y0), title, fill=(0, 0, 0))
        draw.text((x0, y0 + 12), figures, fill=(60, 60, 60))
        img = np.repeat(np.repeat(face_image(rgb, pix), s, 0), s, 1)
        canvas.paste(Image.fromarray(img), (x0, y0 + band))
    return write_png(path, canvas)
