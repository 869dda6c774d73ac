"""A mixture held in proportion to its band: ``BandMixture``, a volume with a ``Band`` (geometry, inside mask, inks,
the core's mixture) and the band's mixture rows, taken from any source of (y, x, N) layers (a volume file read
lazily, a print-shop baseline made a layer at a time) by ``band_of_layers``. The band is every inside voxel whose
mixture is not the core's, so the pair holds exactly the mixture the layers give, in 8 B of index and 4N B of
mixture per band voxel instead of 4N B per grid voxel.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .media import Band, InsideLabels, VolumeError
from .volume import Volume


class BandMixture(NamedTuple):
    """``volume``: a ``Volume`` with a ``Band`` (its medium a placeholder that holds nothing per voxel); ``rows``:
    (K, N) float32, the mixture of the band's voxels in ``volume.band.index`` order. Every other inside voxel holds
    ``volume.band.core``."""

    volume: Volume
    rows: np.ndarray

    def at(self, index: np.ndarray) -> np.ndarray:
        """(K, N) float32: the mixture of the inside voxels ``index`` ((K,) int64 flat (z, y, x) indices, any
        order): the band's row where the voxel is in the band, else the core's (the values a dense mixture holds
        there, bit for bit)."""
        band = self.volume.band
        index = np.asarray(index, np.int64)
        out = np.empty((len(index), len(band.core)), np.float32)
        out[:] = band.core
        if len(band.index) and len(index):
            at = np.minimum(np.searchsorted(band.index, index), len(band.index) - 1)
            hit = np.flatnonzero(band.index[at] == index)
            out[hit] = self.rows[at[hit]]
        return out


def most_common_row(layers, inside) -> np.ndarray:
    """(N,) float32: the mixture most inside voxels of the middle layer that has some hold (a run's fixed core
    below its shell); ``layers[z]`` (y, x, N), ``inside[z]`` (y, x) bool (a dense mask or a ``PackedMask``)."""
    held = [z for z in range(layers.shape[0]) if np.any(inside[z])]
    if not held:
        raise VolumeError("the volume has no inside voxel")
    z = held[len(held) // 2]
    lay = np.asarray(layers[z], np.float32).reshape(-1, layers.shape[3])[np.asarray(inside[z]).reshape(-1)]
    rows, counts = np.unique(lay, axis=0, return_counts=True)
    return rows[int(np.argmax(counts))]


def band_of_layers(layers, inside, core: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(index (K,) int64, rows (K, N) float32): the inside voxels of ``layers`` (``[z]`` (y, x, N) in increasing
    z, ``shape`` (z, y, x, N)) whose mixture is not ``core`` ((N,) float32) and their mixtures, read a layer at a
    time; ``inside[z]``: layer z's inside mask (y, x) bool."""
    nz, ny, nx, n = (int(s) for s in layers.shape)
    core = np.asarray(core, np.float32).reshape(n)
    index, rows = [np.empty(0, np.int64)], [np.empty((0, n), np.float32)]
    for z in range(nz):
        lay = np.ascontiguousarray(layers[z], np.float32).reshape(-1, n)
        differ = np.any(lay.view(np.uint32) != core.view(np.uint32), axis=1)  # bits: -0.0 is not the core's 0.0
        k = np.flatnonzero(np.asarray(inside[z]).reshape(-1) & differ)
        index.append(k + z * ny * nx)
        rows.append(lay[k])
    return np.concatenate(index), np.concatenate(rows)


def band_mixture(geometry: Volume, layers, core: np.ndarray | None = None) -> BandMixture:
    """The mixture ``layers`` (``[z]`` (y, x, N), ``shape`` (z, y, x, N)) on the grid of ``geometry`` (a volume
    with an inside mask and an ink table; its medium is not read) as a ``BandMixture`` whose core is ``core``
    ((N,) float32; None: ``most_common_row``). Any core is exact: every inside voxel holding another mixture is in
    the band."""
    if geometry.inside is None or geometry.inks is None:
        raise VolumeError("a mixture held by its band needs a volume with an inside mask and an ink table")
    if tuple(layers.shape) != (*geometry.shape, len(geometry.inks)):
        raise VolumeError(f"layers of shape {tuple(layers.shape)} on a grid of {geometry.shape}")
    inside = geometry.inside
    core = most_common_row(layers, inside) if core is None else np.asarray(core, np.float32)
    index, rows = band_of_layers(layers, inside, core)
    medium = InsideLabels(inside, 0, geometry.inks)  # a placeholder: nothing per voxel
    return BandMixture(geometry.with_medium(medium, band=Band(index, core)), rows)
