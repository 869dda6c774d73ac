"""Naive baselines: what a print shop does without this project (docs/method.md §8).

Both colour the object from the ink set's colour -> mixture table (``colour_table``).
``surface_baseline``: each scene texel's mapped mixture in its own voxel (voxels with several texels, e.g. box
edges, get their mean), white everywhere else inside. ``extrusion_baseline``: every inside voxel takes the
mapped mixture of its nearest scene texel (Euclidean distance in mm between the voxel centre and the texel's
face centre), so a slab textured on top and bottom is filled from the top in its upper half and from the bottom
in its lower half. Where the scene fixes an ink share (``fixed_share``, e.g. a translucent core), both keep it
and scale the baseline mixture into the remaining share.

Conventions (docs/conventions.md): arrays (z, y, x[, ink]); colours linear RGB; CIELAB via ``inkopt.color``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..model import InkTable, Texels, Volume
from .colour_table import ColourTable, colour_table


# ----------------------------------------------------------------------------------------------- baselines
def _targets(texels: Texels, target_rgb) -> np.ndarray:
    target = np.asarray(target_rgb, np.float64)
    if target.shape != (len(texels), 3):
        raise ValueError(f"target_rgb has shape {target.shape}, expected ({len(texels)}, 3)")
    return target


def white_mixture(inks: InkTable, table: ColourTable | None = None) -> np.ndarray:
    """(N,) float32: the ink named "white", else the table entry with the highest L*."""
    if "white" in inks.names:
        out = np.zeros(len(inks), np.float32)
        out[inks.names.index("white")] = 1.0
        return out
    if table is None:
        raise ValueError("the ink set has no 'white' ink; pass a colour table to pick the lightest mixture")
    return table.mixtures[int(np.argmax(table.lab[:, 0]))].astype(np.float32)


def _check(volume: Volume, table: ColourTable):
    if volume.inks is None:  # only the geometry and the ink table are used, not the medium
        raise ValueError(f"baselines need a volume with an ink table, got a {volume.form} volume")
    if tuple(table.ink_names) != tuple(volume.inks.names):
        raise ValueError(
            f"colour table inks {list(table.ink_names)} differ from the volume's {list(volume.inks.names)}"
        )


def _finish(volume: Volume, fixed_share, out: np.ndarray) -> np.ndarray:
    """Apply the fixed ink shares (z, y, x, N) (or None) and zero the outside."""
    if fixed_share is not None:
        fixed = np.asarray(fixed_share, np.float32)
        if fixed.shape != out.shape:
            raise ValueError(f"fixed_share has shape {fixed.shape}, expected {out.shape}")
        if np.any(fixed):
            out = fixed + np.clip(1.0 - fixed.sum(-1, keepdims=True), 0.0, 1.0) * out
    if volume.inside is not None:
        out[~volume.inside] = 0.0
    return np.ascontiguousarray(out, np.float32)


def surface_baseline(
    volume: Volume,
    texels: Texels,
    target_rgb,
    fixed_share=None,
    table: ColourTable | None = None,
    refine: bool = True,
    progress: bool = False,
) -> np.ndarray:
    """Mixture (z, y, x, N) float32: each scene texel's mapped mixture in its voxel, white elsewhere inside.

    volume: the run's volume (grid, inks, g, ior; mixture or labels: its medium is not used); texels and their
    target_rgb (I, 3) linear; fixed_share (z, y, x, N) or None: the run's constraints (``SceneRecord.fixed_share``),
    kept by the baseline. table: default ``colour_table`` of the volume's inks.
    """
    table = table or colour_table(volume.inks, volume.g, volume.ior, progress=progress)
    _check(volume, table)
    target = _targets(texels, target_rgb)
    mix_t = table.lookup(target, refine=refine)
    n = len(volume.inks)
    out = np.broadcast_to(white_mixture(volume.inks, table), volume.shape + (n,)).copy()
    flat = np.ravel_multi_index(tuple(texels.voxel.T), volume.shape)
    vox, inv = np.unique(flat, return_inverse=True)
    cnt = np.bincount(inv, minlength=len(vox)).astype(np.float64)
    acc = np.stack([np.bincount(inv, mix_t[:, c], minlength=len(vox)) for c in range(n)], 1)
    out.reshape(-1, n)[vox] = (acc / cnt[:, None]).astype(np.float32)
    return _finish(volume, fixed_share, out)


def extrusion_baseline(
    volume: Volume,
    texels: Texels,
    target_rgb,
    fixed_share=None,
    table: ColourTable | None = None,
    refine: bool = True,
    progress: bool = False,
    chunk: int = 1 << 20,
) -> np.ndarray:
    """Mixture (z, y, x, N) float32: every inside voxel takes the mapped mixture of its nearest scene texel
    (distance in mm from the voxel centre to the texel's face centre). Arguments as ``surface_baseline``."""
    table = table or colour_table(volume.inks, volume.g, volume.ior, progress=progress)
    _check(volume, table)
    target = _targets(texels, target_rgb)
    mix_t = table.lookup(target, refine=refine)
    tree = cKDTree(texels.position_mm(volume.voxel_mm))
    inside = volume.inside_mask()
    out = np.zeros(volume.shape + (len(volume.inks),), np.float32)
    flat = np.flatnonzero(inside.ravel())
    vmm = np.asarray(volume.voxel_mm, np.float64)
    flat_out = out.reshape(-1, out.shape[-1])
    for a in range(0, len(flat), chunk):  # bounded temporary memory on big meshes
        idx = np.stack(np.unravel_index(flat[a : a + chunk], volume.shape), 1)
        _, near = tree.query((idx[:, ::-1] + 0.5) * vmm, workers=-1)
        flat_out[flat[a : a + chunk]] = mix_t[near]
    return _finish(volume, fixed_share, out)


BASELINES = {"surface": surface_baseline, "extrusion": extrusion_baseline}


def baseline_mixture(kind: str, volume: Volume, texels: Texels, target_rgb, fixed_share=None, **kw) -> np.ndarray:
    """The (z, y, x, N) mixture of baseline ``kind`` ("surface" or "extrusion")."""
    if kind not in BASELINES:
        raise ValueError(f"unknown baseline '{kind}'; use one of {tuple(BASELINES)}")
    return BASELINES[kind](volume, texels, target_rgb, fixed_share, **kw)
