"""The mixture a quantization reads, one optimisation layer at a time (``printing.quantize``).

``MixtureLayers`` is what ``quantize`` quantizes: a mixture on the optimisation grid (an array, or a layer source
such as ``model.mixturefile.MixtureSource``) with its voxel size, inside mask and ink table. ``CumulativeLayers``
turns its layers into what a dither compares (``printing.dithers``): the normalised cumulative mixture in band order,
upsampled to the printer grid (``printing.grid``). Memory: only the xy-upsampled cumulative mixture of one or two
optimisation layers (N × Y × X float32) exists at a time, never the full upsampled float volume.

Conventions (docs/conventions.md): arrays (z, y, x[, ink]); ``voxel_mm`` is (x, y, z).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model import DEFAULT_G, EMPTY, InkTable, Volume
from ..model.mask import PackedMask


@dataclass(frozen=True, eq=False)
class MixtureLayers:
    """A mixture on the optimisation grid as quantization reads it, one (y, x, N) layer at a time.

    mixture   float (z, y, x, N), non-negative (another dtype is cast to float32), read whole and checked at once;
              or a layer source: ``shape`` (z, y, x, N) and ``[z]`` giving one (y, x, N) layer, asked for in
              increasing z and checked as it is read (``model.mixturefile.MixtureSource``, the evaluation's
              ``BaselineLayers``). Rows are normalised to sum 1; rows inside must have a positive sum
    voxel_mm  (x, y, z) mm of the optimisation grid
    inside    bool (z, y, x), a ``PackedMask`` (read a plane at a time) or None (every voxel inside); printer
              voxels of an outside voxel get ``EMPTY``
    inks      the ``InkTable`` of the N inks, or None (then only index order: ``Quantization.ink_order`` "index")
    g, ior    the medium's, for the inks' order (``dithers.band_order``)
    """

    mixture: object
    voxel_mm: object
    inside: np.ndarray | PackedMask | None = None
    inks: InkTable | None = None
    g: float = DEFAULT_G
    ior: float = 1.5
    total: np.ndarray | None = field(default=None, init=False, repr=False)  # an array's row sums (float64)

    def __post_init__(self):
        if not self.is_source:
            m = np.asarray(self.mixture)
            object.__setattr__(self, "mixture", m if np.issubdtype(m.dtype, np.floating) else m.astype(np.float32))
        shape = self.shape
        if len(shape) != 4 or shape[3] < 1:
            raise ValueError(f"mixture must have shape (z, y, x, N), got {shape}")
        if shape[3] >= EMPTY:
            raise ValueError(f"at most {EMPTY - 1} inks fit uint8 labels, got {shape[3]}")
        if self.inside is not None:
            inside = self.inside if isinstance(self.inside, PackedMask) else np.asarray(self.inside, bool)
            if tuple(inside.shape) != tuple(shape[:3]):
                raise ValueError(f"inside mask shape {inside.shape} differs from mixture shape {tuple(shape[:3])}")
            object.__setattr__(self, "inside", inside)
        if self.inks is not None and len(self.inks) != shape[3]:
            raise ValueError(f"mixture of {shape[3]} inks, but the ink table has {len(self.inks)}")
        object.__setattr__(self, "voxel_mm", np.asarray(self.voxel_mm, np.float64).reshape(-1))
        if not self.is_source:
            inside = None if self.inside is None else np.asarray(self.inside)  # an array's grid: dense bytes
            object.__setattr__(self, "total", _checked_total(self.mixture, inside))

    @classmethod
    def of(cls, volume) -> MixtureLayers:
        """``volume`` as quantization reads it: a mixture ``Volume``, a layer source with ``voxel_mm``, ``inside``,
        ``inks``, ``g`` and ``ior`` (``model.mixturefile.MixtureSource``), or already ``MixtureLayers``."""
        if isinstance(volume, MixtureLayers):
            return volume
        mixture = volume.require_mixture("quantization").mixture if isinstance(volume, Volume) else volume
        return cls(mixture, volume.voxel_mm, volume.inside, volume.inks, volume.g, volume.ior)

    @property
    def is_source(self) -> bool:
        """Whether the mixture is a layer source (else an array)."""
        return not isinstance(self.mixture, np.ndarray) and hasattr(self.mixture, "shape")

    @property
    def shape(self) -> tuple[int, ...]:
        """(z, y, x, N)."""
        return tuple(int(s) for s in self.mixture.shape)

    def layer(self, z: int) -> tuple[np.ndarray, np.ndarray]:
        """Layer z's mixture (y, x, N) and its row sums (y, x) float64, checked."""
        if self.total is not None:
            return self.mixture[z], self.total[z]
        lay = np.asarray(self.mixture[z])
        return lay, _checked_total(lay, None if self.inside is None else self.inside[z])


def _checked_total(m, inside) -> np.ndarray:
    """Row sums (float64) of a mixture array (..., N), checked: finite, non-negative, positive inside."""
    if not np.all(np.isfinite(m)) or m.min() < 0:
        raise ValueError("mixture must be finite and non-negative")
    total = m.sum(axis=-1, dtype=np.float64)
    if np.any((total <= 0) if inside is None else (inside & (total <= 0))):
        raise ValueError("mixture rows inside the object must have a positive sum")
    return total


class CumulativeLayers:
    """The printer layers' cumulative mixtures of ``source`` for a dither: each optimisation layer's rows
    normalised (1 inside, 0 outside), their inks in band ``order`` ((N,) ink indices, None: index order), summed
    cumulatively and upsampled in x and y by ``upsampler`` (``printing.grid.UPSAMPLERS``); the two optimisation
    layers asked for last are kept, since printer layers come in increasing z. ``compensation``: None, or a
    ``printing.compensate.ShareCompensation`` applied to the normalised rows before they are ordered."""

    def __init__(self, source: MixtureLayers, upsampler, order: np.ndarray | None, compensation=None):
        self.source, self.upsampler, self.compensation = source, upsampler, compensation
        self.order = None if order is None else np.asarray(order, np.int64).reshape(-1)
        self.cache: dict[int, np.ndarray] = {}

    def optimisation_layer(self, z: int) -> np.ndarray:
        """xy-upsampled cumulative mixture of optimisation layer z, float32 (N, Y, X); entry N-1 = inside weight."""
        if z in self.cache:
            return self.cache[z]
        lay, t = self.source.layer(z)
        lay = lay.astype(np.float64)
        inside = self.source.inside
        w = np.ones(lay.shape[:2]) if inside is None else inside[z].astype(np.float64)
        lay = lay * (w / np.where(t > 0, t, 1.0))[..., None]  # rows sum to 1 inside, 0 outside
        if self.compensation is not None:
            lay = self.compensation.apply(lay)
        if self.order is not None:
            lay = lay[..., self.order]
        cum = np.cumsum(lay, axis=2).astype(np.float32).transpose(2, 0, 1)  # (N, ny, nx)
        if len(self.cache) >= 2:
            self.cache.pop(next(iter(self.cache)))
        self.cache[z] = np.ascontiguousarray(self.upsampler.xy(cum), dtype=np.float32)
        return self.cache[z]

    def printer_layer(self, k: int) -> tuple[np.ndarray, np.ndarray | None]:
        """Printer layer k's ``(cum, weight)`` (``Dither.layer``'s arguments)."""
        return self.upsampler.layer(k, self.optimisation_layer)
