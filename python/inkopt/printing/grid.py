"""The printer grid of a quantization and its maps to the optimisation grid (``printing.quantize``).

The optimiser works on a coarse grid (300 DPI, ~85 µm voxels); the printer deposits one ink per voxel on a finer,
anisotropic grid covering the same box (``printer_grid``: 600 × 300 DPI in x × y and 27 µm layers by default).
Every printer voxel belongs to the optimisation voxel that encloses its centre (``PrinterGrid.enclosing``): the
inside mask and the shading normals go to the printer grid so (printer voxels outside get label ``EMPTY``). The
mixture goes there by an upsampling, one class per kind (``UPSAMPLERS``: name -> class, ``Quantization.upsample``):

- ``nearest`` (default, as the paper): every printer voxel takes the mixture of its enclosing voxel (``Nearest``).
- ``linear``: the mixture interpolated trilinearly between optimisation voxel centres, over the inside voxels only
  (their rows are normalised, the outside ones zero, so empty space never bleeds in): ``Linear``.

Conventions (docs/conventions.md): arrays (z, y, x[, ink]); ``voxel_mm`` and ``dpi`` are (x, y, z).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..errors import ParameterError
from ..model import Quantization, SurfaceNormals
from ..model.mask import PackedMask
from ..units import MM_PER_INCH, PRINTER_DPI, PRINTER_LAYER_UM

DEFAULT_DPI = PRINTER_DPI
DEFAULT_LAYER_UM = PRINTER_LAYER_UM


def printer_grid(shape_opt, voxel_mm_opt, dpi=(600, 300, None), layer_um: float = DEFAULT_LAYER_UM):
    """Printer voxel grid covering the same box as an optimisation grid.

    shape_opt (z, y, x) voxels; voxel_mm_opt (x, y, z) mm; ``dpi`` (x, y) or (x, y, z) dots per inch, the z
    entry None (default) meaning "use ``layer_um``" (layer thickness in µm, 27 by default, 14 for high quality).
    Each printer dimension is ``round(extent_mm / printer_voxel_mm)`` (at least 1), so the printed extent differs
    from the optimised one by at most half a printer voxel.
    Returns ``(shape_p (Z, Y, X) tuple of int, voxel_mm_p (3,) float64 (x, y, z) mm)``.
    """
    shape_opt = tuple(int(s) for s in shape_opt)
    vo = np.asarray(voxel_mm_opt, np.float64).reshape(-1)
    if len(shape_opt) != 3 or min(shape_opt) < 1:
        raise ValueError(f"shape_opt must be 3 positive sizes (z, y, x), got {shape_opt}")
    if vo.shape != (3,) or not np.all(np.isfinite(vo)) or np.any(vo <= 0):
        raise ValueError(f"voxel_mm must be 3 positive finite sizes (x, y, z) in mm, got {vo}")
    dpi = tuple(dpi)
    if len(dpi) not in (2, 3):
        raise ParameterError(f"`dpi` must be (x, y) or (x, y, z), got {dpi}")
    if len(dpi) == 3 and dpi[2] is not None:
        vz = MM_PER_INCH / float(dpi[2])
    else:
        vz = float(layer_um) / 1000.0
    vp = np.array([MM_PER_INCH / float(dpi[0]), MM_PER_INCH / float(dpi[1]), vz], np.float64)
    if not np.all(np.isfinite(vp)) or np.any(vp <= 0):
        raise ParameterError(f"`dpi` and `layer_um` must be positive, got dpi={dpi} layer_um={layer_um}")
    extent = np.array(shape_opt[::-1], np.float64) * vo  # (x, y, z) mm
    n = np.maximum(1, np.rint(extent / vp)).astype(int)
    return (int(n[2]), int(n[1]), int(n[0])), vp


def _enclosing(n_p: int, vp: float, n_o: int, vo: float) -> np.ndarray:
    """Index (int64) of the optimisation voxel that encloses each printer voxel centre along one axis."""
    return np.clip(np.floor((np.arange(n_p) + 0.5) * (vp / vo)).astype(np.int64), 0, n_o - 1)


def _linear(n_p: int, vp: float, n_o: int, vo: float):
    """(i0, i1, w1) of linear interpolation between optimisation voxel centres at printer voxel centres."""
    s = np.clip((np.arange(n_p) + 0.5) * (vp / vo) - 0.5, 0.0, n_o - 1.0)
    i0 = np.minimum(np.floor(s).astype(np.int64), n_o - 1)
    i1 = np.minimum(i0 + 1, n_o - 1)
    return i0, i1, (s - i0).astype(np.float32)


@dataclass(frozen=True, eq=False)
class PrinterGrid:
    """A printer grid over an optimisation grid: ``shape`` (Z, Y, X) printer voxels of ``voxel_mm`` (x, y, z) mm
    over ``source_shape`` (z, y, x) voxels of ``source_voxel_mm`` (x, y, z) mm, and the optimisation grid's
    ``inside`` mask (bool (z, y, x) or a ``PackedMask``, read a plane at a time; None: every voxel inside)."""

    shape: tuple[int, int, int]
    voxel_mm: np.ndarray
    source_shape: tuple[int, int, int]
    source_voxel_mm: np.ndarray
    inside_mask: np.ndarray | PackedMask | None = None

    @classmethod
    def of(cls, source_shape, source_voxel_mm, q: Quantization, inside=None) -> PrinterGrid:
        """The printer grid that the settings ``q`` (``dpi``, ``layer_um``) give over an optimisation grid."""
        dpi = DEFAULT_DPI if q.dpi is None else q.dpi
        layer_um = DEFAULT_LAYER_UM if q.layer_um is None else q.layer_um
        shape, vp = printer_grid(source_shape, source_voxel_mm, dpi=tuple(dpi), layer_um=layer_um)
        vo = np.asarray(source_voxel_mm, np.float64).reshape(-1)
        return cls(shape, vp, tuple(int(s) for s in source_shape), vo, inside)

    def _axes(self, along):
        """``along(n_p, vp, n_o, vo)`` for the z, y and x axes."""
        vp, vo = self.voxel_mm[::-1], self.source_voxel_mm[::-1]  # (z, y, x)
        return tuple(along(self.shape[a], vp[a], self.source_shape[a], vo[a]) for a in range(3))

    @cached_property
    def enclosing(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(iz, iy, ix) int64: per axis, the optimisation voxel that encloses each printer voxel's centre."""
        return self._axes(_enclosing)

    @cached_property
    def linear(self):
        """((i0, i1, w1) of z, of y, of x): linear interpolation between optimisation voxel centres (``_linear``)."""
        return self._axes(_linear)

    @property
    def masked(self) -> bool:
        """Whether the optimisation grid has an inside mask (else every printer voxel is inside)."""
        return self.inside_mask is not None

    def inside(self, k: int) -> np.ndarray:
        """Printer layer k's inside mask (that of the enclosing voxels), bool (Y, X); all False past the last."""
        Z, Y, X = self.shape
        if k >= Z:
            return np.zeros((Y, X), bool)
        if self.inside_mask is None:
            return np.ones((Y, X), bool)
        iz, iy, ix = self.enclosing
        return self.inside_mask[iz[k]][iy[:, None], ix[None, :]]


# ----------------------------------------------------------------------------------------- upsampling
class Nearest:
    """Every printer voxel takes the mixture of the optimisation voxel that encloses its centre; the cumulative
    mixture's last entry is then the normalised rows' sum (1 inside, 0 outside), no weight to divide by."""

    def __init__(self, grid: PrinterGrid):
        self.iz, self.iy, self.ix = grid.enclosing

    def xy(self, cum: np.ndarray) -> np.ndarray:
        """An optimisation layer's (N, y, x) float32 on the printer grid's (N, Y, X)."""
        return cum[:, self.iy][:, :, self.ix]

    def layer(self, k: int, layer_cum):
        """``(cum, weight)`` of printer layer k from ``layer_cum(z)`` (the xy-upsampled optimisation layer z):
        that of its enclosing layer, and no weight (None)."""
        return layer_cum(int(self.iz[k])), None


class Linear:
    """The mixture interpolated trilinearly between optimisation voxel centres (rows normalised inside and zero
    outside, so the interpolated rows sum to the interpolated inside weight, the cumulative mixture's last entry)."""

    def __init__(self, grid: PrinterGrid):
        self.z, self.y, self.x = grid.linear

    def xy(self, cum: np.ndarray) -> np.ndarray:
        """An optimisation layer's (N, y, x) float32 interpolated to the printer grid's (N, Y, X)."""
        (y0, y1, wy), (x0, x1, wx) = self.y, self.x
        cum = cum[:, y0] * (1 - wy)[None, :, None] + cum[:, y1] * wy[None, :, None]
        return cum[:, :, x0] * (1 - wx) + cum[:, :, x1] * wx

    def layer(self, k: int, layer_cum):
        """``(cum, weight)`` of printer layer k from ``layer_cum(z)``: the two nearest optimisation layers
        interpolated, and the interpolated inside weight (its last entry) that the mixture is normalised by."""
        z0, z1, wz = (a[k] for a in self.z)
        cum = layer_cum(int(z0)) * (1 - wz) + layer_cum(int(z1)) * wz
        return cum, cum[-1]


#: the upsamplings by name (``Quantization.upsample``)
UPSAMPLERS = {"nearest": Nearest, "linear": Linear}


def upsampler_class(name: str):
    """The upsampling called ``name``; a one-line ParameterError for an unknown one."""
    try:
        return UPSAMPLERS[name]
    except KeyError:
        raise ParameterError(f"unknown `upsample` '{name}'; use one of {list(UPSAMPLERS)}") from None


def upsample_normals(normals: SurfaceNormals, grid: PrinterGrid) -> SurfaceNormals:
    """Shading normals on the printer grid, nearest from ``normals`` on its optimisation grid: every printer voxel
    inside a voxel with a normal gets it (a few printer voxels per surface voxel; 20 bytes each). Built one printer
    layer at a time."""
    (Z, Y, X), (iz, iy, ix) = grid.shape, grid.enclosing
    index, vectors, last = [], [], None
    for k in range(Z):
        if iz[k] != last:  # printer layers in one optimisation layer share its upsampled normals (iz is sorted)
            up = normals.layer(iz[k])[iy][:, ix].reshape(-1, 3)
            has = np.flatnonzero(np.any(up != 0, axis=1))
            vec, last = up[has], iz[k]
        index.append(k * Y * X + has)
        vectors.append(vec)
    return SurfaceNormals(grid.shape, np.concatenate(index), np.concatenate(vectors))
