"""The quantization methods: one ink per printer voxel, a printer layer at a time (``printing.quantize``).

Each method is one class implementing ``Dither``, and ``DITHERS`` maps its name (``Quantization.method``) to it;
adding a method is one class and one entry there. A dither is made once per quantization (its random state, its
carried error) and asked for the printer layers in increasing z. Each layer comes as its cumulative mixture
``cum`` (N, Y, X) float32, ``c_k = rho_0 + ... + rho_k`` over the inks in band order, whose last entry is the inside
weight (``printing.grid``: the upsampling that made it).

- ``blue-noise`` (default, ``BlueNoise``) and ``random`` (``RandomDraws``) share one inverse-CDF rule with a
  threshold ``t`` in [0, 1) per printer voxel (``Thresholds``): the voxel gets ink ``k`` with
  ``c_{k-1} <= t < c_k``. Uniform random numbers make it an exact draw from the mixture (the paper's method, white
  noise); a blue-noise array makes it ordered dithering.
- ``blue-noise-columns`` (``BlueNoiseColumns``): the same rule with a 2D blue-noise mask whose thresholds shift
  along z by the golden ratio, so every column of printer voxels holds an evenly spread sequence of thresholds.
- ``error-diffusion`` (``ErrorDiffusion``): deterministic 3D vector error diffusion (``inkopt_core::diffuse``).
- ``count-diffusion`` (``CountDiffusion``): each optimisation voxel's whole ink counts by vector error diffusion
  between optimisation voxels (``inkopt_core::kernels::counts``), placed in its printer voxels by blue noise's
  thresholds; nearest upsampling only.

The blue-noise dithers sum the inks in the order ``Quantization.ink_order`` says (``INK_ORDERS``; ``band_order``),
lightest first by default (``dither.lightness_order`` says why); the other methods in index order.
"""

from __future__ import annotations

from typing import ClassVar, Protocol

import numpy as np

from ..errors import ParameterError
from ..model import EMPTY, Quantization
from .dither import COLUMN_MASK_SHAPE, GOLDEN, lightness_order, load_blue_noise
from .grid import PrinterGrid


class Dither(Protocol):
    """One quantization method. ``Dither(q, grid, n_inks, order)`` starts a quantization with the settings ``q`` on
    the printer grid ``grid`` of ``n_inks`` inks whose bands follow ``order`` ((N,) ink indices, or None: index
    order; ``band_order``); ``layer`` then gives each printer layer's labels, asked for in increasing k."""

    #: one line of what it does (``inkopt quantize --help``)
    help: ClassVar[str]
    #: whether its bands follow ``Quantization.ink_order`` (else index order, and its record says "index")
    ordered: ClassVar[bool]
    #: whether it needs nearest upsampling (``check_quantization`` refuses another for it)
    nearest_only: ClassVar[bool]

    def __init__(self, q: Quantization, grid: PrinterGrid, n_inks: int, order: np.ndarray | None) -> None: ...

    def layer(self, k: int, cum: np.ndarray, weight: np.ndarray | None) -> np.ndarray:
        """Printer layer k's labels, uint8 (Y, X) (ink index; ``EMPTY`` outside, ``grid.inside(k)``), from its
        cumulative mixture ``cum`` (N, Y, X) float32 in band order; ``weight`` (Y, X): the interpolated inside
        weight that the rows sum to (linear upsampling), None where they are normalised (nearest)."""
        ...


class Thresholds:
    """Inverse-CDF dithering: each printer voxel's threshold ``t`` in [0, 1) picks the ink whose band
    [c_{k-1}, c_k) of the cumulative mixture holds it, so every ink takes a share of the thresholds equal to its
    weight. A subclass says where the thresholds come from (``thresholds``); ``self.rng`` is
    ``numpy.random.default_rng(q.seed)``."""

    help: ClassVar[str] = ""
    ordered: ClassVar[bool] = False
    nearest_only: ClassVar[bool] = False

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


class ErrorDiffusion:
    """Deterministic 3D vector error diffusion (``inkopt_core::diffuse``, in Rust). Printer voxels are visited layer
    by layer (z up), rows in y, each row serpentine in x (direction alternating with ``y + z``); each takes the ink
    with the largest component of its corrected mixture (mixture + carried error, i.e. the nearest one-hot vector)
    and passes the residual (corrected mixture - one-hot) to unvisited neighbours: 7/8 in its layer with
    Floyd–Steinberg's proportions (49, 21, 35, 7)/128, 1/8 to the next layer (8/128 straight down, 2/128 to each of
    that voxel's four xy neighbours; the weights and the measurements that chose them are in
    crates/core/src/kernels/diffuse.rs). Weights are renormalised over neighbours inside the object; outside voxels
    neither take nor pass error. The ink counts of any window differ from its summed mixture only by the residuals
    crossing its boundary (each bounded: within [-1/2, 1/2] for two inks). The seed is unused. Memory: the carried
    error of this and the next printer layer, 2 × Y × X × N float32."""

    help = "deterministic 3D vector error diffusion"
    ordered = False
    nearest_only = False

    def __init__(self, q: Quantization, grid: PrinterGrid, n_inks: int, order: np.ndarray | None) -> None:
        self.grid = grid
        _, Y, X = grid.shape
        self.error = np.zeros((2, Y, X, n_inks), np.float32)

    def layer(self, k: int, cum: np.ndarray, weight: np.ndarray | None) -> np.ndarray:
        """Error-diffuses printer layer k in Rust; ``cum``'s last entry is the inside weight its mixture is
        divided by (``weight`` is the same under linear upsampling, and ignored)."""
        from .. import _core

        w = cum[-1]
        mix = np.diff(cum, axis=0, prepend=np.zeros((1,) + w.shape, np.float32))
        mix /= np.where(w > 0, w, 1.0).astype(np.float32)
        lab = np.empty(self.grid.shape[1:], np.uint8)
        inside_k, inside_next = self.grid.inside(k), self.grid.inside(k + 1)
        _core.diffuse_layer(
            np.ascontiguousarray(mix, np.float32),
            inside_k.view(np.uint8),
            inside_next.view(np.uint8),
            self.error,
            k,
            lab,
        )
        return lab


class CountDiffusion:
    """Whole ink counts per optimisation voxel chosen by vector error diffusion between optimisation voxels, placed
    in each voxel's block of printer voxels by the blue-noise array (``BlueNoise``'s thresholds and bands).

    Why: under nearest upsampling an optimisation voxel encloses a block of ``b`` printer voxels (2 x 1 x 3 or 4 at
    600 x 300 DPI x 27 µm over 85 µm voxels), so any dither gives it its shares in steps of 1/b; blue noise rounds
    each block on its own, and where the mixture changes from voxel to voxel the neighbours' rounding errors do not
    cancel. Here the counts ``c`` of a block are the nearest whole vector to ``b * share + carried error`` with sum
    ``b``, and the residual goes to the unvisited optimisation voxels (``inkopt_core::kernels::counts``: in-layer
    Floyd–Steinberg, the fraction ``down`` to the next optimisation layer), so the counts of any window of
    optimisation voxels differ from its summed mixture only by the residuals crossing its boundary. The error flows
    only between voxels of one depth shell under the surface (``shells``: the surface's voxels, the next shell, and
    so on, the last holding the rest, by 6-connected erosions of the inside mask), so the surface, which a texel
    sees, does not take the errors of the hidden voxels below it.

    Placement: the block's printer voxels sorted by their blue-noise thresholds take the bands in order (the first
    ``c_0`` voxels band 0, the lightest ink by default, and so on): where the diffused counts are the ones blue noise
    would give the block, the labels are blue noise's; elsewhere the voxels nearest a band's edge change ink.

    Follows the dither protocol: the counts of optimisation layer z are diffused when its first printer layer is
    asked for (from that layer's cumulative mixture, taken at one printer voxel per block, so ``--compensate`` and
    the bands' order apply as for blue noise) and the labels of its printer layers kept until asked for; memory
    holds one optimisation layer's printer layers (labels and thresholds) and two (y, x, N) f64 error planes.
    Deterministic for a seed (the blue-noise offset; the diffusion is sequential). Linear upsampling has no blocks
    of one mixture and is refused."""

    help = "ink counts per optimisation voxel by error diffusion between them, placed by blue noise"
    ordered = True
    nearest_only = True
    #: the fraction of each optimisation voxel's residual carried to the next optimisation layer (the rest stays in
    #: its layer) and the depth shells the error stays in (1: one class; docs/quality.md, "Counts kept per
    #: optimisation voxel")
    down = 0.125
    shells = 1

    def __init__(self, q: Quantization, grid: PrinterGrid, n_inks: int, order: np.ndarray | None) -> None:
        if q.upsample != "nearest":
            raise ParameterError(f"method '{q.method}' needs upsample 'nearest' (its blocks), got '{q.upsample}'")
        self.grid, self.n_inks = grid, n_inks
        self.blue = BlueNoise(q, grid, n_inks, order)
        self.iz, iy, ix = grid.enclosing
        nz, ny, nx = grid.source_shape
        self.per_z = np.bincount(self.iz, minlength=nz)
        # one printer row / column per optimisation row / column (its first), and the blocks' lateral sizes
        self.first_y = np.minimum(np.searchsorted(iy, np.arange(ny)), len(iy) - 1)
        self.first_x = np.minimum(np.searchsorted(ix, np.arange(nx)), len(ix) - 1)
        self.block_yx = np.outer(np.bincount(iy, minlength=ny), np.bincount(ix, minlength=nx)).astype(np.uint32)
        self.block_id = (iy[:, None] * nx + ix[None, :]).astype(np.int64)  # (Y, X): the block of each column
        self.error = np.zeros((2, ny, nx, n_inks), np.float64)
        self.counts = np.zeros((ny, nx, n_inks), np.uint32)
        self.next_z, self.labels = 0, {}
        self.classes = None if grid.inside_mask is None else depth_shells(grid.inside_mask, self.shells)
        self.max_residual = 0.0  # the largest |residual component| so far (the window bound's factor)

    def layer(self, k: int, cum: np.ndarray, weight: np.ndarray | None) -> np.ndarray:
        z = int(self.iz[k])
        while self.next_z <= z:  # optimisation layers without printer layers pass their carried error on
            self._diffuse(self.next_z, cum if self.next_z == z else None)
            self.next_z += 1
        return self.labels.pop(k)

    def _inside(self, z: int) -> np.ndarray:
        nz, ny, nx = self.grid.source_shape
        if z >= nz:
            return np.zeros((ny, nx), np.uint8)
        return np.ones((ny, nx), np.uint8) if self.classes is None else np.ascontiguousarray(self.classes[z])

    def _diffuse(self, z: int, cum: np.ndarray | None) -> None:
        """Diffuses optimisation layer z's counts (``cum``: its first printer layer's, None: no printer layer) and
        places them (``_place``)."""
        from .. import _core

        if cum is None:
            share = np.zeros((self.n_inks,) + self.block_yx.shape)
        else:
            at = cum[:, self.first_y[:, None], self.first_x[None, :]].astype(np.float64)
            share = np.diff(at, axis=0, prepend=0.0)
        block = np.ascontiguousarray(self.block_yx * np.uint32(self.per_z[z]))
        worst = _core.diffuse_counts_layer(
            np.ascontiguousarray(share),
            block,
            self._inside(z),
            self._inside(z + 1),
            self.error,
            z,
            self.down,
            self.counts,
        )
        self.max_residual = max(self.max_residual, worst)
        if cum is not None:
            self._place(z)

    def _place(self, z: int) -> None:
        """The labels of optimisation layer z's printer layers: in every block, the voxels in increasing threshold
        take ``counts`` bands in order (band order, mapped to inks by ``BlueNoise.band_ink``); outside EMPTY."""
        ks = np.flatnonzero(self.iz == z)
        t = np.stack([self.blue.thresholds(int(k)) for k in ks])  # (K, Y, X) in [0, 1)
        key = (self.block_id[None] + t.astype(np.float64)).ravel()
        sort = np.argsort(key, kind="stable")
        bid = np.broadcast_to(self.block_id, t.shape).ravel()[sort]
        start = np.searchsorted(bid, bid, side="left")  # the first sorted position of each voxel's block
        rank = np.arange(len(bid)) - start
        edges = np.cumsum(self.counts.reshape(-1, self.n_inks), axis=1)[bid]  # (M, N): the bands' ends
        band = np.empty(len(bid), np.uint8)
        band[sort] = np.sum(rank[:, None] >= edges[:, :-1], axis=1)
        lab = band.reshape(t.shape)
        if self.blue.band_ink is not None:
            lab = self.blue.band_ink[lab]
        for j, k in enumerate(ks):
            if self.grid.masked:
                lab[j][~self.grid.inside(int(k))] = EMPTY
            self.labels[int(k)] = lab[j]


def depth_shells(inside: np.ndarray, shells: int) -> np.ndarray:
    """uint8 (z, y, x): 0 outside, else the voxel's depth shell under the surface, 1 (has an outside 6-neighbour or
    lies on the grid's edge) to ``shells`` (the rest), by repeated 6-connected erosion of ``inside`` (bool)."""
    from scipy.ndimage import binary_erosion

    out = np.zeros(inside.shape, np.uint8)
    cur = np.asarray(inside, bool)
    for s in range(1, shells):
        eroded = binary_erosion(cur, border_value=0)
        out[cur & ~eroded] = s
        cur = eroded
    out[cur] = shells
    return out


#: the quantization methods by name (``Quantization.method``, ``inkopt quantize --method``)
DITHERS: dict[str, type[Dither]] = {
    "blue-noise": BlueNoise,
    "blue-noise-columns": BlueNoiseColumns,
    "random": RandomDraws,
    "error-diffusion": ErrorDiffusion,
    "count-diffusion": CountDiffusion,
}
METHODS = tuple(DITHERS)


def dither_class(method: str) -> type[Dither]:
    """The dither called ``method``; a one-line ParameterError for an unknown one."""
    try:
        return DITHERS[method]
    except KeyError:
        raise ParameterError(f"unknown quantization `method` '{method}'; use one of {list(DITHERS)}") from None


def _lightness(inks, g: float, ior: float) -> np.ndarray:
    if inks is None:
        raise ValueError("ink_order 'lightness' needs the mixture's ink table; give one or use 'index'")
    return lightness_order(inks, g, ior)


def _tint_first(inks, g: float, ior: float) -> np.ndarray:
    """Lightest first, but the second lightest ink (the paper's inks: yellow) before the lightest (white): the
    light tint then takes the thresholds' prefix, a blue-noise pattern of its own, where in a mixture with darker
    inks it would take a middle band; the two light inks together still precede the dark ones."""
    order = _lightness(inks, g, ior)
    return np.concatenate([order[1:2], order[:1], order[2:]])


#: the inks' orders in an ordered dither's bands by name (``Quantization.ink_order``): (inks, g, ior) -> (N,) ink
#: indices, or None for index order
INK_ORDERS = {"lightness": _lightness, "index": lambda inks, g, ior: None, "tint-first": _tint_first}


def band_order(q: Quantization, inks, g: float, ior: float) -> np.ndarray | None:
    """The inks' order in the cumulative mixture that the settings ``q`` say for ``inks`` (an ``InkTable``, or None
    for index order only) with the medium's ``g`` and ``ior``: ``q.ink_order``'s for an ordered dither (blue
    noise; lightest first by default), else None (index order). Every quantization takes it from here, so ours and
    the evaluation's baselines are dithered alike, a labels file made in index order included."""
    if not dither_class(q.method).ordered:
        return None
    return INK_ORDERS[q.ink_order](inks, g, ior)
