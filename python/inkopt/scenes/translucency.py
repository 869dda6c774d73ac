"""Translucency constraints: regions that must hold a fixed share of transparent ink
(docs/lighting-and-translucency.md).

A *mask* gives, per picture pixel (slabs: the top picture) or texture texel (meshes), the required share
``s`` in [0, 1] of the transparent ink (``rundir.TRANSPARENT_INKS``): the grey level of a PNG (8 or 16 bit;
colour images are converted to grey), or a float ``.npy`` (H, W) array; for meshes also the texture's alpha
channel (``s = 1 - alpha``, Brunton et al. 2018). ``s = 0`` leaves a voxel unconstrained.

Which voxels: slabs, the voxel columns under the top face's texels, from the top down ``depth_mm`` (rounded to
whole voxels, at least one; None: the whole slab), each with the mask resampled to the face's texel grid like the
picture. Meshes: every inside voxel at most ``depth_mm`` below the surface along the inward normal (the signed
distance, ``-sdf <= depth_mm``; None: the whole object) takes the share of its nearest texel (the texel's
closest surface point's mask value, looked up through the uv coordinates like the colour).

The constraint is a fixed ink share (``optim/param.py``: mixture = fixed + (1 - sum fixed) * p(x)):
``fixed[..., transparent] = s``, the optimiser picks the rest. Voxels that are otherwise fixed white (a mesh's
core below ``--shell-mm``) and that a region reaches become ``s`` transparent + ``1 - s`` white
(``rundir.Translucency.apply``); voxels outside the object are never constrained (they stay white and unrendered).
The constraint is stored sparsely in scene.npz (``rundir.Translucency``), so evaluation and the baselines rebuild
the same fixed shares.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..model import InkTable
from ..rundir import Translucency, transparent_ink

ALPHA = "alpha"  # --translucency alpha: the mesh texture's alpha channel


def translucency_fields(tr: Translucency | None) -> dict:
    """Report fields of a translucency constraint (none without one)."""
    if tr is None:
        return {}
    return {"translucency": {"source": tr.source, "ink": tr.ink, "depth_mm": tr.depth_mm,
                             "voxels": int(len(tr.index)), "mean_share": float(tr.share.mean())}}


def check_depth(depth_mm: float | None) -> float | None:
    if depth_mm is not None and not (np.isfinite(depth_mm) and depth_mm > 0):
        raise ValueError(f"--translucency-depth-mm must be a positive depth in mm, got {depth_mm}")
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
        raise ValueError(f"{name}: shares must lie in 0..1, got {a[i, j]:g} at row {i}, column {j} "
                         f"({int(bad.sum())} values outside)")
    return a


def load_mask(path) -> np.ndarray:
    """A mask file -> (H, W) float32 shares in [0, 1]: the grey level of an image (8-bit / 255, 16-bit / 65535,
    float images as they are) or a float .npy array."""
    from PIL import Image, UnidentifiedImageError

    p = Path(path)
    if not p.is_file():
        raise ValueError(f"translucency mask {path} does not exist")
    if p.suffix.lower() == ".npy":
        try:
            a = np.load(p, allow_pickle=False)
        except Exception as exc:
            raise ValueError(f"cannot read translucency mask {path}: {exc}") from None
        return check_mask(a, f"translucency mask {path}")
    try:
        with Image.open(p) as im:
            if im.mode in ("I", "I;16", "I;16B", "I;16L"):
                a = np.asarray(im, np.float64) / 65535.0
            elif im.mode == "F":
                a = np.asarray(im, np.float64)
            else:
                a = np.asarray(im.convert("L"), np.float64) / 255.0
    except (UnidentifiedImageError, OSError) as exc:
        raise ValueError(f"cannot read translucency mask {path}: {' '.join(str(exc).split())}") from None
    return check_mask(a, f"translucency mask {path}")


def _constraint(inks: InkTable, shape, share: np.ndarray, depth_mm, source: str) -> Translucency | None:
    """The sparse constraint of a (z, y, x) share grid, or None if no voxel is constrained."""
    idx = np.flatnonzero(share.reshape(-1) > 0)
    if len(idx) == 0:
        return None
    return Translucency(transparent_ink(inks), shape, idx, share.reshape(-1)[idx], depth_mm, source)


def slab_translucency(mask: np.ndarray, top_shape: tuple, shape, voxel_z_mm: float, inks: InkTable,
                      depth_mm: float | None = None, source: str = "") -> Translucency | None:
    """The constraint of a slab of ``shape`` (z, y, x) from ``mask`` (H, W) in the top picture's pixels
    (``top_shape`` (H, W), which it must match)."""
    from .slab import resample

    transparent_ink(inks)  # the one-line error first
    mask = check_mask(mask, f"translucency mask {source}".strip())
    if mask.shape != tuple(top_shape):
        raise ValueError(f"translucency mask {source}: {mask.shape[1]}x{mask.shape[0]} px, but the top picture is "
                         f"{top_shape[1]}x{top_shape[0]} px; they must be the same size".replace(" :", ":"))
    depth_mm = check_depth(depth_mm)
    nz, ny, nx = shape
    face = np.clip(resample(np.repeat(mask[..., None], 3, -1), ny, nx)[..., 0], 0.0, 1.0)[::-1]  # row 0 = max y
    layers = nz if depth_mm is None else int(np.clip(round(depth_mm / voxel_z_mm), 1, nz))
    share = np.zeros(shape, np.float32)
    share[nz - layers:] = face
    return _constraint(inks, shape, share, depth_mm, source)


def mesh_texel_share(mesh, vox, mask: np.ndarray | None = None) -> np.ndarray:
    """(I,) float32 required share at each texel of a voxelized mesh: ``1 - alpha`` of the texture at the texel's
    closest surface point, or ``mask`` (H, W) looked up there through the uv coordinates."""
    from .mesh.load import barycentric

    if mesh.uv is None or (mask is None and mesh.texture_alpha is None):
        what = "no uv coordinates" if mesh.uv is None else "a texture without an alpha channel"
        raise ValueError(f"--translucency {'MASK' if mask is not None else ALPHA}: {mesh.source} has {what}; "
                         f"give a texture with alpha or a mask in texture space")
    bary = barycentric(mesh.solid_vertices[mesh.solid_faces[vox.face_index]], vox.closest_mm)
    if mask is None:
        return (1.0 - mesh.alpha_at(vox.face_index, bary)).astype(np.float32)
    return np.clip(mesh.sample_at(check_mask(mask), vox.face_index, bary), 0.0, 1.0).astype(np.float32)


def mesh_translucency(vox, texel_share: np.ndarray, inks: InkTable, depth_mm: float | None = None,
                      source: str = "") -> Translucency | None:
    """The constraint of a voxelized mesh (its ``sdf`` still present when ``depth_mm`` is given): inside voxels
    within ``depth_mm`` of the surface take their nearest texel's share ``texel_share`` (I,)."""
    from scipy.spatial import cKDTree

    transparent_ink(inks)
    depth_mm = check_depth(depth_mm)
    sel = vox.inside.copy()
    if depth_mm is not None:
        sel &= vox.sdf >= -np.float32(depth_mm)
    sel[tuple(vox.texels.voxel.T)] = True
    share = np.zeros(vox.inside.shape, np.float32)
    if np.any(texel_share > 0):
        pts = np.argwhere(sel)
        _, near = cKDTree(vox.texels.voxel * vox.voxel_mm[::-1]).query(pts * vox.voxel_mm[::-1], workers=-1)
        share[tuple(pts.T)] = texel_share[near]
    return _constraint(inks, vox.inside.shape, share, depth_mm, source)
