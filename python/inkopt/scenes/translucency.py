"""Translucency constraints: regions that must hold a fixed share of transparent ink
(docs/lighting-and-translucency.md).

A *mask* gives, per picture pixel (slabs: the top picture) or texture texel (meshes), the required share
``s`` in [0, 1] of the transparent ink (``model.TRANSPARENT_INKS``): the grey level of a PNG (8 or 16 bit;
colour images are converted to grey), or a float ``.npy`` (H, W) array; for meshes also the texture's alpha
channel (``s = 1 - alpha``, Brunton et al. 2018). ``s = 0`` leaves a voxel unconstrained.

Which voxels: slabs, the voxel columns under the top face's texels, from the top down ``depth_mm`` (rounded to
whole voxels, at least one; None: the whole slab), each with the mask resampled to the face's texel grid like the
picture. Meshes: every inside voxel at most ``depth_mm`` below the surface along the inward normal (the signed
distance, ``-sdf <= depth_mm``; None: the whole object) takes the share of its nearest texel (the texel's
closest surface point's mask value, looked up through the uv coordinates like the colour; ``mesh/translucency.py``).

The constraint is a fixed ink share (``optim/param.py``: mixture = fixed + (1 - sum fixed) * p(x)):
``fixed[..., transparent] = s``, the optimiser picks the rest. Voxels that are otherwise fixed white (a mesh's
core below ``--shell-mm``) and that a region reaches become ``s`` transparent + ``1 - s`` white
(``model.Translucency.applied``); voxels outside the object are never constrained (they stay white and unrendered).
The constraint is stored sparsely in scene.npz (``model.Translucency``), so evaluation and the baselines rebuild
the same fixed shares.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import ParameterError
from ..images import open_image
from ..io import load_array
from ..model import InkTable, Translucency, transparent_ink
from .picture import resample

ALPHA = "alpha"  # translucency "alpha": the mesh texture's alpha channel


def translucency_fields(tr: Translucency | None) -> dict:
    """Report fields of a translucency constraint (none without one)."""
    if tr is None:
        return {}
    return {
        "translucency": {
            "source": tr.source,
            "ink": tr.ink,
            "depth_mm": tr.depth_mm,
            "voxels": int(len(tr.index)),
            "mean_share": float(tr.share.mean()),
        }
    }


def check_depth(depth_mm: float | None) -> float | None:
    if depth_mm is not None and not (np.isfinite(depth_mm) and depth_mm > 0):
        raise ParameterError(f"`translucency_depth_mm` must be a positive depth in mm, got {depth_mm}")
    return None if depth_mm is None else float(depth_mm)


def check_mask(mask, name: str = "translucency mask") -> np.ndarray:
    """``mask`` as (H, W) float32 shares; one-line ValueError unless 2-D and every value in [0, 1]."""
    a = np.asarray(mask)
    if a.ndim != 2 or min(a.shape) < 1:
        raise ValueError(f"{name}: must be a grey (H, W) image, got shape {a.shape}")
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer) or a.dtype == bool):
        raise ValueError(f"{name}: values must be numbers, got dtype {a.dtype}")
    a = a.astype(np.float32)
    bad = ~np.isfinite(a) | (a < 0) | (a > 1)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise ValueError(
            f"{name}: shares must lie in 0..1, got {a[i, j]:g} at row {i}, column {j} ({int(bad.sum())} values outside)"
        )
    return a


def load_mask(path) -> np.ndarray:
    """A mask file -> (H, W) float32 shares in [0, 1]: the grey level of an image (8-bit / 255, 16-bit / 65535,
    float images as they are) or a float .npy array."""
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"translucency mask {path} does not exist")
    if p.suffix.lower() == ".npy":
        a = load_array(p, "translucency mask")
        return check_mask(a, f"translucency mask {path}")
    with open_image(p, f"translucency mask {path}") as im:
        if im.mode in ("I", "I;16", "I;16B", "I;16L"):
            a = np.asarray(im, np.float64) / 65535.0
        elif im.mode == "F":
            a = np.asarray(im, np.float64)
        else:
            a = np.asarray(im.convert("L"), np.float64) / 255.0
    return check_mask(a, f"translucency mask {path}")


def share_constraint(inks: InkTable, shape, share: np.ndarray, depth_mm, source: str) -> Translucency | None:
    """The sparse constraint of a (z, y, x) share grid, or None if no voxel is constrained."""
    idx = np.flatnonzero(share.reshape(-1) > 0)
    if len(idx) == 0:
        return None
    return Translucency(transparent_ink(inks), shape, idx, share.reshape(-1)[idx], depth_mm, source)


def slab_translucency(
    mask: np.ndarray,
    top_shape: tuple,
    shape,
    voxel_z_mm: float,
    inks: InkTable,
    depth_mm: float | None = None,
    source: str = "",
) -> Translucency | None:
    """The constraint of a slab of ``shape`` (z, y, x) from ``mask`` (H, W) in the top picture's pixels
    (``top_shape`` (H, W), which it must match)."""
    transparent_ink(inks)  # the one-line error first
    mask = check_mask(mask, f"translucency mask {source}".strip())
    if mask.shape != tuple(top_shape):
        raise ValueError(
            f"translucency mask {source}: {mask.shape[1]}x{mask.shape[0]} px, but the top picture is "
            f"{top_shape[1]}x{top_shape[0]} px; they must be the same size".replace(" :", ":")
        )
    depth_mm = check_depth(depth_mm)
    nz, ny, nx = shape
    face = np.clip(resample(np.repeat(mask[..., None], 3, -1), ny, nx)[..., 0], 0.0, 1.0)[::-1]  # row 0 = max y
    layers = nz if depth_mm is None else int(np.clip(round(depth_mm / voxel_z_mm), 1, nz))
    share = np.zeros(shape, np.float32)
    share[nz - layers :] = face
    return share_constraint(inks, shape, share, depth_mm, source)
