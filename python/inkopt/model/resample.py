"""A mixture moved from one grid of an object to another grid of the same object (e.g. a coarse run's result onto
the optimisation grid of a finer one), in millimetres.

Both grids place voxel (z, y, x)'s centre at ``origin_mm + ((x, y, z) + 0.5) * voxel_mm`` (``origin_mm`` None: 0,
as slabs have it). :class:`MixtureResampler` holds the source volume's mixture and inside mask and gives the
mixture at any points (mm) or at chosen voxels of another grid, a chunk of points at a time:

- ``"linear"``: trilinear interpolation between the 8 source voxel centres around a point, over the source's
  inside voxels only (the weights of outside or off-grid corners are dropped and the rest renormalised), so the
  colour of a surface layer is not mixed with the empty voxels outside the object;
- ``"nearest"``: the source voxel that holds the point, if it is inside.

A point with no inside source voxel there (a thin feature or the boundary shell that the coarser grid does not
hold) takes the mixture of the nearest inside source voxel centre (Euclidean distance in mm). That voxel is found
among the source's boundary voxels (inside, with a 6-neighbour outside or off the grid): for cubic voxels the
nearest inside voxel of a point that none of its 8 surrounding centres holds is always one of them, since a step
towards the point along its largest offset is shorter.

Memory: the source mixture as given (it is not copied; a ``BandMixture`` holds its band's rows only), its inside
mask (a byte per source voxel), its boundary voxels' positions (a KD-tree, built on the first point that needs it),
and per chunk of ``chunk`` points a few (chunk, N) float64 arrays; no array the size of the destination grid.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from .banded import BandMixture
from .volume import Volume, VolumeError

METHODS = ("linear", "nearest")
#: points per chunk: the temporaries of one chunk are a few (chunk, N) float64 arrays (~10 MB at 5 inks)
CHUNK = 1 << 18


def voxel_centres_mm(index: np.ndarray, shape, voxel_mm, origin_mm=None) -> np.ndarray:
    """(K, 3) float64 (x, y, z) mm: the centres of the voxels ``index`` ((K,) flat (z, y, x) indices) of a grid of
    ``shape`` (z, y, x), ``voxel_mm`` (x, y, z) and low corner ``origin_mm`` (x, y, z; None: 0)."""
    zyx = np.stack(np.unravel_index(np.asarray(index, np.int64), tuple(shape)), axis=1)
    origin = np.zeros(3) if origin_mm is None else np.asarray(origin_mm, np.float64).reshape(3)
    return origin + (zyx[:, ::-1] + 0.5) * np.asarray(voxel_mm, np.float64).reshape(3)


class MixtureResampler:
    """The mixture of ``source`` at other points, by ``method`` ("linear" or "nearest", module docstring). ``source``:
    a mixture ``Volume`` ((z, y, x, N) float32, its inside mask, ``voxel_mm``, ``origin_mm``), or a
    ``BandMixture`` (``model.banded``: the same mixture held by its band; the same results, bit for bit)."""

    def __init__(self, source: Volume | BandMixture, method: str = "linear"):
        if method not in METHODS:
            raise ValueError(f"unknown resampling method '{method}'; use one of {list(METHODS)}")
        if isinstance(source, BandMixture):
            geometry, self.n_inks, self._mixture_at = source.volume, source.rows.shape[1], source.at
        else:
            geometry, flat = source, source.require_mixture("resampling a mixture").mixture
            self.n_inks = flat.shape[-1]
            flat = flat.reshape(-1, self.n_inks)
            self._mixture_at = flat.__getitem__
        self.inside = geometry.inside_mask()
        if not self.inside.any():
            raise VolumeError("the source volume has no inside voxel to take a mixture from")
        self.method, self.shape = method, self.inside.shape
        self.voxel_mm = np.asarray(geometry.voxel_mm, np.float64)
        self.origin_mm = np.zeros(3) if geometry.origin_mm is None else np.asarray(geometry.origin_mm, np.float64)
        self._tree = self._tree_index = None

    def at(self, points_mm: np.ndarray, chunk: int = CHUNK) -> np.ndarray:
        """(K, N) float32, rows summing to 1: the mixture at ``points_mm`` ((K, 3) (x, y, z) mm), ``chunk`` points
        at a time."""
        points_mm = np.asarray(points_mm, np.float64).reshape(-1, 3)
        out = np.empty((len(points_mm), self.n_inks), np.float32)
        for lo in range(0, len(points_mm), chunk):
            out[lo : lo + chunk] = self._rows(points_mm[lo : lo + chunk])
        return out

    def on_grid(self, index: np.ndarray, shape, voxel_mm, origin_mm=None, chunk: int = CHUNK) -> np.ndarray:
        """(K, N) float32: the mixture at the centres of the voxels ``index`` ((K,) flat (z, y, x) indices) of the
        grid ``shape``, ``voxel_mm``, ``origin_mm`` (``voxel_centres_mm``), ``chunk`` voxels at a time."""
        index = np.asarray(index, np.int64).reshape(-1)
        out = np.empty((len(index), self.n_inks), np.float32)
        for lo in range(0, len(index), chunk):
            out[lo : lo + chunk] = self._rows(voxel_centres_mm(index[lo : lo + chunk], shape, voxel_mm, origin_mm))
        return out

    def _rows(self, p: np.ndarray) -> np.ndarray:
        u = ((p - self.origin_mm) / self.voxel_mm - 0.5)[:, ::-1]  # continuous source index (z, y, x)
        acc = np.zeros((len(p), self.n_inks), np.float64)
        wsum = np.zeros(len(p), np.float64)
        if self.method == "linear":
            i0 = np.floor(u).astype(np.int64)
            f = u - i0
            corners = [(dz, dy, dx) for dz in (0, 1) for dy in (0, 1) for dx in (0, 1)]
        else:
            i0, f, corners = np.floor(u + 0.5).astype(np.int64), None, [(0, 0, 0)]
        for off in corners:
            idx = i0 + np.asarray(off)
            ok = np.all((idx >= 0) & (idx < np.asarray(self.shape)), axis=1)
            lin = np.ravel_multi_index(tuple(np.where(ok[:, None], idx, 0).T), self.shape)
            ok &= self.inside.reshape(-1)[lin]
            w = ok.astype(np.float64)
            if f is not None:
                w *= np.prod(np.where(np.asarray(off) == 1, f, 1.0 - f), axis=1)
            hit = np.flatnonzero(w > 0)
            acc[hit] += w[hit, None] * self._mixture_at(lin[hit])
            wsum += w
        # no inside source voxel around: the nearest one's mixture (a tiny total weight counts as none)
        lost = np.flatnonzero(wsum < 1e-6)
        if len(lost):
            acc[lost] = self._mixture_at(self._nearest_inside(p[lost]))
            wsum[lost] = 1.0
        acc /= wsum[:, None]
        acc /= np.maximum(acc.sum(axis=1, keepdims=True), 1e-30)  # rows sum to 1 (the source's, up to rounding)
        return acc.astype(np.float32)

    def _nearest_inside(self, p: np.ndarray) -> np.ndarray:
        """(K,) flat source indices of the inside voxel centres nearest to ``p`` ((K, 3) mm), among the boundary
        voxels (module docstring)."""
        if self._tree is None:
            from scipy.spatial import cKDTree

            six = ndimage.generate_binary_structure(3, 1)
            edge = self.inside & ~ndimage.binary_erosion(self.inside, six, border_value=0)
            self._tree_index = np.flatnonzero(edge)
            self._tree = cKDTree(voxel_centres_mm(self._tree_index, self.shape, self.voxel_mm, self.origin_mm))
        _, k = self._tree.query(p)
        return self._tree_index[k]
