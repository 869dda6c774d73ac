"""Translucency constraints of a voxelized mesh (``scenes.translucency`` describes the masks and the regions):
the required share at each texel, from the texture's alpha channel or a mask in texture space, and the inside
voxels within a depth of the surface that take their nearest texel's share."""

from __future__ import annotations

import numpy as np

from ...errors import ParameterError
from ...model import InkTable, Translucency, transparent_ink
from ..translucency import ALPHA, check_depth, check_mask, share_constraint
from .load import barycentric


def mesh_texel_share(mesh, vox, mask: np.ndarray | None = None) -> np.ndarray:
    """(I,) float32 required share at each texel of a voxelized mesh: ``1 - alpha`` of the texture at the texel's
    closest surface point, or ``mask`` (H, W) looked up there through the uv coordinates."""
    if mesh.uv is None or (mask is None and mesh.texture_alpha is None):
        what = "no uv coordinates" if mesh.uv is None else "a texture without an alpha channel"
        raise ParameterError(
            f"`translucency` {'MASK' if mask is not None else ALPHA}: {mesh.source} has {what}; "
            f"give a texture with alpha or a mask in texture space"
        )
    bary = barycentric(mesh.solid_vertices[mesh.solid_faces[vox.face_index]], vox.closest_mm)
    if mask is None:
        return (1.0 - mesh.alpha_at(vox.face_index, bary)).astype(np.float32)
    return np.clip(mesh.sample_at(check_mask(mask), vox.face_index, bary), 0.0, 1.0).astype(np.float32)


def mesh_translucency(
    vox, texel_share: np.ndarray, inks: InkTable, depth_mm: float | None = None, source: str = ""
) -> Translucency | None:
    """The constraint of a voxelized mesh (its ``depth`` still present when ``depth_mm`` is given): inside voxels
    within ``depth_mm`` of the surface take their nearest texel's share ``texel_share`` (I,)."""
    from scipy.spatial import cKDTree

    transparent_ink(inks)
    depth_mm = check_depth(depth_mm)
    if depth_mm is None:
        sel = vox.inside.dense()
    else:
        sel = np.zeros(vox.inside.shape, bool)
        sel.reshape(-1)[vox.depth.within(depth_mm)] = True
    sel[tuple(vox.texels.voxel.T)] = True
    share = np.zeros(vox.inside.shape, np.float32)
    if np.any(texel_share > 0):
        pts = np.argwhere(sel)
        _, near = cKDTree(vox.texels.voxel * vox.voxel_mm[::-1]).query(pts * vox.voxel_mm[::-1], workers=-1)
        share[tuple(pts.T)] = texel_share[near]
    return share_constraint(inks, vox.inside.shape, share, depth_mm, source)
