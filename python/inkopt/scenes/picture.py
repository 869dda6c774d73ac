"""Input pictures on a face's texel grid: what a slab's pictures and its translucency mask share."""

from __future__ import annotations

import numpy as np


def resample(picture: np.ndarray, ny: int, nx: int) -> np.ndarray:
    """(H, W, 3) float32 -> (ny, nx, 3) float32, bilinear with anti-aliasing (in whatever space it is given:
    linear light for colours)."""
    from skimage.transform import resize  # scikit-image is slow to import; only slabs need it

    return resize(picture, (ny, nx, 3), order=1, anti_aliasing=True, mode="edge").astype(np.float32)
