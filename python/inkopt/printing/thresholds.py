"""The threshold dithers (``dithers.Dither``'s protocol): each printer voxel's threshold ``t`` in [0, 1) picks the
ink whose band of the cumulative mixture holds it (``Thresholds``); blue noise (``BlueNoise``), the columns' golden
shifts of a 2D mask (``BlueNoiseColumns``) and independent draws (``RandomDraws``) say where the thresholds come
from. Registered by name in ``printing.dithers``."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from ..model import EMPTY, Quantization
from .dither import COLUMN_MASK_SHAPE, GOLDEN, load_blue_noise
from .grid import PrinterGrid


class Thresholds:
    """Inverse-CDF dithering: each printer voxel's threshold ``t`` in [0, 1) picks the ink whose band
    [c_{k-1}, c_k) of the cumulative mixture holds it, so every ink takes a share of the thresholds equal to its
    weight. A subclass says where the thresholds come from (``thresholds``); ``self.rng`` is
    ``numpy.random.default_rng(q.seed)``."""

    help: ClassVar[str] = ""
    ordered: ClassVar[bool] = False
    nearest_only: ClassVar[bool] = False
    constant_as: ClassVar[str | None] = None

    def __init__(self, q: Quantization, grid: PrinterGrid, n_inks: int, order: np.ndarray | None) -> None:
        self.grid, self.n_inks = grid, n_inks
        self.rng = np.random.default_rng(q.seed)
        # the bands' map from band to ink label (None: band k is ink k)
        self.band_ink = None if order is None else np.asarray(order, np.int64).reshape(-1).astype(np.uint8)

    def thresholds(self, k: int) -> np.ndarray:
        """Printer layer k's thresholds, float32 (Y, X) in [0, 1)."""
        raise NotImplementedError

    def layer(self, k: int, cum: np.ndarray, weight: np.ndarray | None) -> np.ndarray:
        t = self.thresholds(k)
        if weight is not None:
            t = t * weight  # normalise by the interpolated inside weight (t * w >= c_n  <=>  t >= c_n / w)
        lab = np.zeros(self.grid.shape[1:], np.uint8)
        for n in range(self.n_inks - 1):
            lab += t >= cum[n]
        if self.band_ink is not None:
            lab = self.band_ink[lab]
        if self.grid.masked:
            lab[~self.grid.inside(k)] = EMPTY
        return lab


class BlueNoise(Thresholds):
    """Ordered dithering: the thresholds are a 3D blue-noise array (void-and-cluster, ``dither.load_blue_noise``)
    tiled periodically over the printer grid at a toroidal offset drawn from the seed. Because the thresholds of
    neighbouring voxels are spread evenly, the local ink fractions match the mixture much more closely than
    independent draws (the error is pushed to high spatial frequencies, which the scattering medium low-passes)."""

    help = "ordered dithering"
    ordered = True

    def __init__(self, q: Quantization, grid: PrinterGrid, n_inks: int, order: np.ndarray | None) -> None:
        super().__init__(q, grid, n_inks, order)
        self.tile = load_blue_noise()
        _, Y, X = grid.shape
        tz, ty, tx = self.tile.shape
        self.oz, oy, ox = (int(v) for v in self.rng.integers(0, self.tile.shape))
        self.ty_idx = ((np.arange(Y) + oy) % ty)[:, None]
        self.tx_idx = ((np.arange(X) + ox) % tx)[None, :]

    def thresholds(self, k: int) -> np.ndarray:
        return self.tile[(k + self.oz) % self.tile.shape[0]][self.ty_idx, self.tx_idx]


class BlueNoiseColumns(Thresholds):
    """Ordered dithering whose every column of printer voxels is an even sequence in depth: the thresholds are
    ``t(x, y, z) = frac(B(x, y) + (z + oz) * GOLDEN)``, with ``B`` a 2D blue-noise mask (void-and-cluster,
    ``dither.COLUMN_MASK_SHAPE``) tiled over (y, x) at a toroidal offset drawn from the seed, and ``GOLDEN`` the
    golden ratio's conjugate (the "spatiotemporal blue noise" of animation, with depth as time).

    Why: a texel's colour is the light that came back through its column of printer voxels, weighted by depth.
    Along a column the thresholds are a Kronecker sequence, the most evenly spread sequence of its kind: any k
    consecutive layers hold each ink's share of them to within about one voxel, so a column's depth-weighted ink
    counts stay close to its mixture. Each layer is the mask shifted in value, so it takes one band of the mask's
    ranks per ink: still spread evenly in (y, x), though a band that is not a prefix of the ranks is less blue than
    one that is. Consecutive layers' thresholds differ by 0.382 or 0.618, so an ink under 38 % never takes two
    voxels on top of each other."""

    help = "ordered dithering, every column's layers an even sequence (golden-ratio shifts of a 2D blue-noise mask)"
    ordered = True

    def __init__(self, q: Quantization, grid: PrinterGrid, n_inks: int, order: np.ndarray | None) -> None:
        super().__init__(q, grid, n_inks, order)
        mask = load_blue_noise(COLUMN_MASK_SHAPE)
        _, Y, X = grid.shape
        ty, tx = mask.shape
        self.oz, oy, ox = (int(v) for v in self.rng.integers(0, (2**20, ty, tx)))
        self.mask = mask[((np.arange(Y) + oy) % ty)[:, None], ((np.arange(X) + ox) % tx)[None, :]]

    def thresholds(self, k: int) -> np.ndarray:
        shift = np.float32(((k + self.oz) * GOLDEN) % 1.0)  # in float64: k * GOLDEN keeps its fraction
        t = self.mask + shift
        t[t >= 1.0] -= 1.0
        return t


class RandomDraws(Thresholds):
    """The paper's method: each printer voxel draws its ink independently with the (upsampled) mixture as the
    probability distribution, one layer after the other (so the result does not depend on any chunking). Adds
    white noise."""

    help = "the paper's independent draws"

    def thresholds(self, k: int) -> np.ndarray:
        return self.rng.random(self.grid.shape[1:], dtype=np.float32)
