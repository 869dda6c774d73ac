"""Naive baselines: what a print shop does without this project (docs/method.md §8).

Both colour the object from the ink set's colour -> mixture table (``colour_table``).
``surface_baseline``: each scene texel's mapped mixture in its own voxel (voxels with several texels, e.g. box
edges, get their mean), white everywhere else inside. ``extrusion_baseline``: every inside voxel takes the
mapped mixture of its nearest scene texel (Euclidean distance in mm between the voxel centre and the texel's
face centre), so a slab textured on top and bottom is filled from the top in its upper half and from the bottom
in its lower half. Mesh texels sit at voxel centres: their nearest texel comes from the exact Euclidean distance
transform of the grid (12 s for Spot 40 mm's mixture, where a k-d tree search from deep inside the body visits
most of the surface and would take ~10 min: bench/results/extrusion_nearest_40mm.json); other texels (face
centres) from a k-d tree. Between equidistant texels either may be taken. Where the scene fixes an ink share
(``fixed_share``, e.g. a translucent core), both keep it and scale the baseline mixture into the remaining share.

Conventions (docs/conventions.md): arrays (z, y, x[, ink]); colours linear RGB; CIELAB via ``inkopt.color``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .. import _core
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


class BaselineLayers:
    """Baseline ``kind``'s mixture one (y, x, N) float32 layer at a time: ``[z]`` equals layer z of
    ``baseline_mixture(kind, ...)`` bit for bit, without the (z, y, x, N) array (a layer source for
    ``printing.quantize.quantize``, which asks for layers in increasing z). ``shape`` (z, y, x, N), ``dtype``.

    Held: the per-texel mixtures (surface: per textured voxel), a k-d tree of the texel centres or the nearest
    texel of each voxel it fills (extrusion: int32, 4 B a voxel) and references to the volume's inside mask and
    ``fixed_share``; not the volume's medium (extrusion fills the voxels of ``volume.inside_mask()``). Arguments as
    ``surface_baseline``; ``kind`` "surface" or "extrusion"; ``only`` (keyword; default every voxel): sorted flat
    (z, y, x) int64 indices of the voxels whose mixture is read (a run's free voxels): extrusion then fills only
    those, bit for bit as without it, and leaves the layer's other voxels 0, so that a run with a band keeps 4 B
    per band voxel instead of per inside voxel."""

    def __init__(self, kind: str, volume: Volume, texels: Texels, target_rgb, fixed_share=None, table=None, **kw):
        if kind not in BASELINES:
            raise ValueError(f"unknown baseline '{kind}'; use one of {tuple(BASELINES)}")
        refine, progress, only = kw.pop("refine", True), kw.pop("progress", False), kw.pop("only", None)
        if kw:
            raise TypeError(f"unexpected arguments {sorted(kw)}")
        table = table or colour_table(volume.inks, volume.g, volume.ior, progress=progress)
        _check(volume, table)
        mix_t = table.lookup(_targets(texels, target_rgb), refine=refine)
        n = len(volume.inks)
        self.kind, self.shape, self.dtype = kind, tuple(volume.shape) + (n,), np.dtype(np.float32)
        self.inside = volume.inside  # zeroed outside, as the volume's mask says
        self.fill = self.inside if self.inside is not None or volume.form != "labels" else volume.inside_mask()
        self.fixed = fixed_share
        if fixed_share is not None and tuple(fixed_share.shape) != self.shape:
            raise ValueError(f"fixed_share has shape {tuple(fixed_share.shape)}, expected {self.shape}")
        if kind == "surface":
            self.white = white_mixture(volume.inks, table)
            flat = np.ravel_multi_index(tuple(texels.voxel.T), volume.shape)
            vox, inv = np.unique(flat, return_inverse=True)
            cnt = np.bincount(inv, minlength=len(vox)).astype(np.float64)
            acc = np.stack([np.bincount(inv, mix_t[:, c], minlength=len(vox)) for c in range(n)], 1)
            self.vox, self.vox_mix = vox, (acc / cnt[:, None]).astype(np.float32)  # sorted flat voxel indices
        else:
            self.mix_t = mix_t
            self.vmm = np.asarray(volume.voxel_mm, np.float64)
            self.tree, self.near, self.offsets = None, None, None
            self.only = None if only is None else np.asarray(only, np.int64)
            if texels.centred and self.fill is not None:
                self.near, self.offsets = _nearest_centred(texels, self.fill, self.vmm, self.only)
            else:
                self.tree = cKDTree(texels.position_mm(volume.voxel_mm))

    def __getitem__(self, z: int) -> np.ndarray:
        z = int(z)
        if not 0 <= z < self.shape[0]:
            raise IndexError(f"layer {z} outside 0..{self.shape[0] - 1}")
        ny, nx, n = self.shape[1:]
        inside = None if self.inside is None else self.inside[z]
        if self.kind == "surface":
            out = np.broadcast_to(self.white, (ny, nx, n)).copy()
            lo, hi = np.searchsorted(self.vox, [z * ny * nx, (z + 1) * ny * nx])
            out.reshape(-1, n)[self.vox[lo:hi] - z * ny * nx] = self.vox_mix[lo:hi]
        else:
            out = np.zeros((ny, nx, n), np.float32)
            flat = self._filled(z)
            if len(flat):
                out.reshape(-1, n)[flat] = self.mix_t[self.nearest_texels(z, flat)]
        fixed = None
        if self.fixed is not None:
            fixed = self.fixed.plane(z) if hasattr(self.fixed, "plane") else np.asarray(self.fixed[z], np.float32)
        return _finish(inside, fixed, out)

    def _filled(self, z: int) -> np.ndarray:
        """Extrusion: the flat (y, x) indices (ascending) of layer z's voxels that it fills: its fill voxels (every
        voxel without an inside mask) among ``only``'s."""
        ny, nx = self.shape[1:3]
        fill = None if self.fill is None else self.fill[z].ravel()
        if self.only is None:
            return np.arange(ny * nx) if fill is None else np.flatnonzero(fill)
        sel = _layer_part(self.only, z, ny * nx)
        return sel if fill is None else sel[fill[sel]]

    def nearest_texels(self, z: int, flat: np.ndarray) -> np.ndarray:
        """Extrusion: the nearest scene texel (int64 (K,)) of the voxels ``flat`` (flat (y, x) indices, ascending)
        of layer z, which must be all the layer's filled voxels (``_filled``) when they were found by the distance
        transform."""
        if self.near is not None:
            return self.near[self.offsets[z] : self.offsets[z + 1]].astype(np.int64)
        yx = np.stack(np.unravel_index(flat, self.shape[1:3]), 1)
        pos = (np.column_stack([yx[:, ::-1], np.full(len(flat), z)]) + 0.5) * self.vmm
        return self.tree.query(pos, workers=-1)[1]

    def array(self) -> np.ndarray:
        """The whole (z, y, x, N) float32 mixture (small volumes, tests)."""
        return np.stack([self[z] for z in range(self.shape[0])]) if self.shape[0] else np.zeros(self.shape, np.float32)


def _layer_part(index: np.ndarray, z: int, plane: int) -> np.ndarray:
    """The flat (y, x) indices of layer z's entries of sorted flat (z, y, x) indices ``index``."""
    lo, hi = np.searchsorted(index, [z * plane, (z + 1) * plane])
    return index[lo:hi] - z * plane


def _nearest_centred(texels: Texels, fill: np.ndarray, vmm: np.ndarray, only: np.ndarray | None = None):
    """For texels at voxel centres (meshes): the nearest texel of every ``fill`` voxel (z, y, x bool; with ``only``,
    sorted flat (z, y, x) int64 indices, of those among them), by the exact
    Euclidean distance transform of the grid with voxel size ``vmm`` (x, y, z mm) to the texels' voxels, one z plane
    at a time (``_core.feature_plane``: scipy.ndimage.distance_transform_edt's answers, ties included, without its
    12 bytes per grid voxel). Returns (int32 (K,) texel index per such voxel in C order, int64 (Z + 1,) offset of
    each layer's first). Equidistant texels are resolved by the transform, which may pick another than a tree search
    would."""
    shape = fill.shape
    nz, ny, nx = shape
    flat_t = np.ravel_multi_index(tuple(texels.voxel.T), shape)
    order = np.argsort(flat_t)
    # the texels' voxels by column, then z: the z pass's nearest feature of each column is found by a search
    v = texels.voxel.astype(np.int64)
    col_z = np.unique((v[:, 1] * nx + v[:, 2]) * nz + v[:, 0])
    cols = np.arange(ny * nx, dtype=np.int64)

    def filled(z: int) -> np.ndarray:  # flat (y, x) indices of the layer's voxels asked for, ascending
        f = fill[z].ravel()
        if only is None:
            return np.flatnonzero(f)
        sel = _layer_part(only, z, ny * nx)
        return sel[f[sel]]

    if only is None:
        counts = np.array([np.count_nonzero(fill[z]) for z in range(nz)], np.int64)  # a plane at a time
    else:
        counts = np.array([len(filled(z)) for z in range(nz)], np.int64)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    near = np.empty(int(offsets[-1]), np.int32)
    sampling = tuple(float(s) for s in vmm[::-1])
    ft = np.empty((3, ny, nx), np.int32)
    for z in range(nz):  # layer by layer: nothing grid-sized
        if not counts[z]:
            continue
        _core.feature_plane(z, _column_sites(col_z, cols, z, nz).reshape(ny, nx), sampling, ft)
        k = filled(z)
        hit = np.ravel_multi_index((ft[0].ravel()[k], ft[1].ravel()[k], ft[2].ravel()[k]), shape)
        near[offsets[z] : offsets[z + 1]] = order[np.searchsorted(flat_t, hit, sorter=order)]
    return near, offsets


def _column_sites(col_z: np.ndarray, cols: np.ndarray, z: int, nz: int) -> np.ndarray:
    """int32 (columns,): the z of each column's feature nearest to plane z, the lower one of two as near (the
    distance transform's pass along z), -1 where a column has none. ``col_z``: sorted column * nz + z of the
    features; ``cols``: every column's index."""
    q = cols * nz + z
    i = np.searchsorted(col_z, q)
    nxt = col_z[np.minimum(i, len(col_z) - 1)]
    has_next = (i < len(col_z)) & (nxt // nz == cols)
    prev = col_z[np.maximum(i - 1, 0)]
    has_prev = (i > 0) & (prev // nz == cols)
    nxt_z, prev_z = nxt - cols * nz, prev - cols * nz
    take_prev = has_prev & (~has_next | (z - prev_z <= nxt_z - z))
    return np.where(take_prev, prev_z, np.where(has_next, nxt_z, -1)).astype(np.int32)


def _finish(inside, fixed, out: np.ndarray) -> np.ndarray:
    """Apply a layer's fixed ink shares (y, x, N) (or None) and zero its outside (``inside`` (y, x) or None)."""
    if fixed is not None and np.any(fixed):
        fixed = np.asarray(fixed, np.float32)
        out = fixed + np.clip(1.0 - fixed.sum(-1, keepdims=True), 0.0, 1.0) * out
    if inside is not None:
        out[~inside] = 0.0
    return np.ascontiguousarray(out, np.float32)


def surface_baseline(volume: Volume, texels: Texels, target_rgb, fixed_share=None, table=None, **kw) -> np.ndarray:
    """Mixture (z, y, x, N) float32: each scene texel's mapped mixture in its voxel, white elsewhere inside.

    volume: the run's volume (grid, inks, g, ior; mixture or labels: its medium is not used); texels and their
    target_rgb (I, 3) linear; fixed_share (z, y, x, N) or None: the run's constraints (``SceneRecord.fixed_share``),
    kept by the baseline. table: default ``colour_table`` of the volume's inks. ``refine`` (default True): the
    table's blend of its 8 nearest entries, else the nearest; ``progress``: the table build's progress bar.
    """
    return BaselineLayers("surface", volume, texels, target_rgb, _dense_fixed(fixed_share), table, **kw).array()


def extrusion_baseline(volume: Volume, texels: Texels, target_rgb, fixed_share=None, table=None, **kw) -> np.ndarray:
    """Mixture (z, y, x, N) float32: every inside voxel takes the mapped mixture of its nearest scene texel
    (distance in mm from the voxel centre to the texel's face centre). Arguments as ``surface_baseline``."""
    return BaselineLayers("extrusion", volume, texels, target_rgb, _dense_fixed(fixed_share), table, **kw).array()


def _dense_fixed(fixed_share):
    """A fixed-share argument as ``BaselineLayers`` takes it: None, a ``FixedShares`` or a float32 array."""
    if fixed_share is None or hasattr(fixed_share, "plane"):
        return fixed_share
    return np.asarray(fixed_share, np.float32)


BASELINES = {"surface": surface_baseline, "extrusion": extrusion_baseline}  # kind -> full-array function


def baseline_layers(kind: str, volume: Volume, texels: Texels, target_rgb, fixed_share=None, **kw) -> BaselineLayers:
    """Baseline ``kind``'s mixture one z layer at a time (``BaselineLayers``); arguments as ``baseline_mixture``."""
    return BaselineLayers(kind, volume, texels, target_rgb, _dense_fixed(fixed_share), **kw)


def baseline_mixture(kind: str, volume: Volume, texels: Texels, target_rgb, fixed_share=None, **kw) -> np.ndarray:
    """The (z, y, x, N) mixture of baseline ``kind`` ("surface" or "extrusion")."""
    if kind not in BASELINES:
        raise ValueError(f"unknown baseline '{kind}'; use one of {tuple(BASELINES)}")
    return BASELINES[kind](volume, texels, target_rgb, fixed_share, **kw)
