"""The map between a label grid's printer texels and a scene's texels, shared by the evaluation's printed results
(``evaluation.printed``) and the refinement on the printed prediction (``printing.refine``).

A printer texel is a textured face of a printer voxel (meshes: one per printer surface voxel). Each is assigned to
the scene texel of the same face whose face centre is nearest in mm (meshes: the nearest scene texel), i.e. the
scene texel whose footprint contains it; a scene texel's colour is the mean of its printer texels (one that gets
none takes its nearest printer texel). Conventions: docs/conventions.md.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..model import Texels, Volume


def map_texels(printer: Texels, voxel_mm_printer, scene: Texels, voxel_mm_scene, per_face: bool = True):
    """Scene texel (int64 (Ip,)) of each printer texel, and for every scene texel the printer texel that stands in
    for it when none maps to it (int64 (I,), -1 where some do). Nearest face centre in mm, within the same face
    id if ``per_face`` (slabs), else over all texels (meshes)."""
    ps, pp = scene.position_mm(voxel_mm_scene), printer.position_mm(voxel_mm_printer)
    to_scene = np.full(len(printer), -1, np.int64)
    stand_in = np.full(len(scene), -1, np.int64)
    groups = np.unique(scene.face) if per_face else [None]
    for f in groups:
        s_idx = np.flatnonzero(scene.face == f) if f is not None else np.arange(len(scene))
        p_idx = np.flatnonzero(printer.face == f) if f is not None else np.arange(len(printer))
        if len(p_idx) == 0:
            raise ValueError(f"the quantized volume has no texels on face {int(f)} of the scene")
        _, near = cKDTree(ps[s_idx]).query(pp[p_idx], workers=-1)
        to_scene[p_idx] = s_idx[near]
        cnt = np.bincount(near, minlength=len(s_idx))
        empty = np.flatnonzero(cnt == 0)
        if len(empty):
            _, back = cKDTree(pp[p_idx]).query(ps[s_idx[empty]], workers=-1)
            stand_in[s_idx[empty]] = p_idx[back]
    if np.any(to_scene < 0):
        raise ValueError("the quantized volume has texels on faces the scene does not texture")
    return to_scene, stand_in


def average_to_scene(rgb_p, var_p, to_scene, stand_in, n_scene: int):
    """Per-scene-texel mean (I, C) of printer texel colours (P, C) (C = 3, or a spectral render's bands), and the
    variance of that mean (I, C). Printer texels with ``to_scene`` -1 (a sample's stand-ins of no sampled texel's
    own) only stand in."""
    on = to_scene >= 0
    if not on.all():
        to_scene, rgb_on, var_on = to_scene[on], rgb_p[on], var_p[on]
    else:
        rgb_on, var_on = rgb_p, var_p
    cnt = np.bincount(to_scene, minlength=n_scene).astype(np.float64)
    rgb = np.stack([np.bincount(to_scene, rgb_on[:, c], n_scene) for c in range(rgb_p.shape[1])], 1)
    var = np.stack([np.bincount(to_scene, var_on[:, c], n_scene) for c in range(rgb_p.shape[1])], 1)
    has = cnt > 0
    rgb[has] /= cnt[has, None]
    var[has] /= (cnt[has] ** 2)[:, None]
    miss = np.flatnonzero(~has)
    rgb[miss], var[miss] = rgb_p[stand_in[miss]], var_p[stand_in[miss]]
    return rgb, var


def printer_texels(qvol: Volume, scene: Texels, kind: str) -> Texels:
    """The printer texels of labels volume ``qvol`` for a scene of ``kind`` ("mesh": every printer surface voxel;
    else the printer voxels' faces of the faces ``scene`` textures)."""
    if kind == "mesh":
        return Texels.for_volume(qvol)
    return Texels.for_volume(qvol, sorted({int(f) for f in np.unique(scene.face)}))
