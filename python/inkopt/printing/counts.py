"""The counts' dithers: each optimisation voxel's whole ink counts chosen by vector error diffusion between
optimisation voxels (``inkopt_core::kernels::counts``) and placed in its block of printer voxels by blue noise's
thresholds (``CountDiffusion``), and the same only where the mixture changes from voxel to voxel, blue noise's own
labels elsewhere (``AdaptiveCounts``). Both follow ``dithers.Dither``'s protocol and are registered there."""

from __future__ import annotations

import numpy as np

from ..errors import ParameterError
from ..model import EMPTY, Quantization
from .grid import PrinterGrid
from .thresholds import BlueNoise

#: the class of the counts kernel's voxels that take the ordered dither's own counts (``kernels::counts``)
DITHER_CLASS = 255


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
    holds one optimisation layer's printer layers (labels and thresholds, and each block's voxels in threshold order,
    ``kernels::blocks``) and two (y, x, N) f64 error planes.
    Deterministic for a seed (the blue-noise offset; the diffusion is sequential). Linear upsampling has no blocks
    of one mixture and is refused."""

    help = "ink counts per optimisation voxel by error diffusion between them, placed by blue noise"
    ordered = True
    nearest_only = True
    constant_as = None
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
        # the printer rows and columns of optimisation row / column y: ry[y]..ry[y + 1] (``kernels::blocks``); from
        # them one printer row / column per optimisation row / column (its first) and the blocks' lateral sizes
        self.ry = np.searchsorted(iy, np.arange(ny + 1)).astype(np.uint32)
        self.rx = np.searchsorted(ix, np.arange(nx + 1)).astype(np.uint32)
        self.first_y = np.minimum(self.ry[:-1], len(iy) - 1).astype(np.int64)
        self.first_x = np.minimum(self.rx[:-1], len(ix) - 1).astype(np.int64)
        self.block_yx = np.outer(np.diff(self.ry), np.diff(self.rx)).astype(np.uint32)
        self.error = np.zeros((2, ny, nx, n_inks), np.float64)
        self.counts = np.zeros((ny, nx, n_inks), np.uint32)
        self.next_z, self.labels = 0, {}
        # one class needs no erosion: each layer's classes are its inside plane, read when its turn comes
        several = grid.inside_mask is not None and self.shells > 1
        self.classes = depth_shells(grid.inside_mask, self.shells) if several else None
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
        if self.classes is not None:
            return np.ascontiguousarray(self.classes[z])
        if self.grid.inside_mask is None:
            return np.ones((ny, nx), np.uint8)
        return np.asarray(self.grid.inside_mask[z], np.uint8)

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
        ks = np.flatnonzero(self.iz == z)
        order, sorted_t = self._sorted(ks) if cum is not None else (None, None)
        classes = self._classes(z, share)
        worst = _core.diffuse_counts_layer(
            np.ascontiguousarray(share),
            block,
            classes,
            self._inside(z + 1),
            self.error,
            z,
            self.down,
            self.counts,
            sorted_t if np.any(classes == DITHER_CLASS) else None,
        )
        self.max_residual = max(self.max_residual, worst)
        if order is not None:
            self._place(ks, order)

    def _classes(self, z: int, share: np.ndarray) -> np.ndarray:
        """Optimisation layer z's classes (``_inside``); here every inside voxel diffuses."""
        return self._inside(z)

    def _sorted(self, ks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The printer layers ``ks`` of one optimisation layer: each block's voxels in increasing blue-noise
        threshold, (ny, nx, W) their flat (K, Y, X) indices and (ny, nx, W) f64 their thresholds
        (``kernels::blocks::sort_blocks``)."""
        from .. import _core

        t = np.ascontiguousarray(np.stack([self.blue.thresholds(int(k)) for k in ks]), np.float32)  # (K, Y, X)
        width = len(ks) * int(np.diff(self.ry).max()) * int(np.diff(self.rx).max())
        order = np.empty(self.block_yx.shape + (width,), np.uint32)
        sorted_t = np.empty(order.shape, np.float64)
        _core.sort_blocks(t, self.ry, self.rx, order, sorted_t)
        return order, sorted_t

    def _place(self, ks: np.ndarray, order: np.ndarray) -> None:
        """The labels of one optimisation layer's printer layers ``ks``: in every block, the voxels in increasing
        threshold take ``counts`` bands in order (band order, mapped to inks by ``BlueNoise.band_ink``); outside
        EMPTY."""
        from .. import _core

        lab = np.zeros((len(ks),) + self.grid.shape[1:], np.uint8)
        _core.place_blocks(order, self.counts, self.ry, self.rx, lab)
        if self.blue.band_ink is not None:
            lab = self.blue.band_ink[lab]
        for j, k in enumerate(ks):
            if self.grid.masked:
                lab[j][~self.grid.inside(int(k))] = EMPTY
            self.labels[int(k)] = lab[j]


class AdaptiveCounts(CountDiffusion):
    """Blue noise where the mixture is smooth, the counts' diffusion (``CountDiffusion``) where it changes from
    voxel to voxel: an optimisation voxel whose mixture differs from its inside neighbours' (four in its layer, one
    below) by less than ``smooth`` (the root mean square over them of the share vectors' Euclidean distance; 0 for
    a voxel without inside neighbours) takes blue noise's own labels and neither takes nor passes error
    (``inkopt_core::kernels::counts::DITHER_CLASS``); the others diffuse their counts among themselves, by depth
    shell, as ``CountDiffusion``'s do.

    Why: on the suite the counts' diffusion lowers the grain where the optimiser's mixture changes from voxel to
    voxel (the duck), but where it is smooth it decides at the optimisation voxel's scale which blocks get an ink's
    extra printer voxel and doubles the grain (the eyeball), where blue noise's 3D array does better
    (docs/quality.md, "Counts kept per optimisation voxel"). Error a diffusing voxel passes down to a voxel that
    turns out smooth in the next layer is dropped (the next layer's mixture is not read before its turn)."""

    help = "blue noise where the mixture is smooth, counts diffused where it changes from voxel to voxel"
    constant_as = "blue-noise"  # every voxel of a constant mixture takes blue noise's labels
    #: the RMS share distance to the neighbours below which a voxel takes blue noise's labels
    smooth = 0.05

    def __init__(self, q: Quantization, grid: PrinterGrid, n_inks: int, order: np.ndarray | None) -> None:
        super().__init__(q, grid, n_inks, order)
        self.below: np.ndarray | None = None  # the previous optimisation layer's (N, y, x) shares and inside mask
        self.below_inside: np.ndarray | None = None

    def _classes(self, z: int, share: np.ndarray) -> np.ndarray:
        from .. import _core

        classes = self._inside(z).copy()
        inside = (classes > 0).view(np.uint8)
        below = {} if self.below is None else {"below": self.below, "below_inside": self.below_inside}
        _core.mark_smooth(np.ascontiguousarray(share), classes, self.smooth, **below)
        if share.any():  # an optimisation layer without printer layers keeps the one below
            self.below, self.below_inside = np.ascontiguousarray(share), inside
        return classes


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
