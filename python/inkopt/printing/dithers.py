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
  thresholds; nearest upsampling only. ``count-adaptive`` (``AdaptiveCounts``): the same where the mixture changes
  from voxel to voxel, blue noise's own labels where it is smooth.

The threshold dithers live in ``printing.thresholds``, the counts' dithers in ``printing.counts``.

The blue-noise dithers sum the inks in the order ``Quantization.ink_order`` says (``INK_ORDERS``; ``band_order``),
lightest first by default (``dither.lightness_order`` says why); the other methods in index order.
"""

from __future__ import annotations

from typing import ClassVar, Protocol

import numpy as np

from ..errors import ParameterError
from ..model import Quantization
from .counts import AdaptiveCounts, CountDiffusion
from .dither import lightness_order
from .grid import PrinterGrid
from .thresholds import BlueNoise, BlueNoiseColumns, RandomDraws


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
    #: the method whose labels it gives on a constant mixture, where it has one (None: its own); a compensation
    #: measured on flat patches is shared with that method (``compensate.compensation_key``)
    constant_as: ClassVar[str | None]

    def __init__(self, q: Quantization, grid: PrinterGrid, n_inks: int, order: np.ndarray | None) -> None: ...

    def layer(self, k: int, cum: np.ndarray, weight: np.ndarray | None) -> np.ndarray:
        """Printer layer k's labels, uint8 (Y, X) (ink index; ``EMPTY`` outside, ``grid.inside(k)``), from its
        cumulative mixture ``cum`` (N, Y, X) float32 in band order; ``weight`` (Y, X): the interpolated inside
        weight that the rows sum to (linear upsampling), None where they are normalised (nearest)."""
        ...


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
    constant_as = None

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


#: the quantization methods by name (``Quantization.method``, ``inkopt quantize --method``)
DITHERS: dict[str, type[Dither]] = {
    "blue-noise": BlueNoise,
    "blue-noise-columns": BlueNoiseColumns,
    "random": RandomDraws,
    "error-diffusion": ErrorDiffusion,
    "count-diffusion": CountDiffusion,
    "count-adaptive": AdaptiveCounts,
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
