"""A spatial preconditioner for the optimiser's step: a few explicit diffusion steps over the free voxels'
6-neighbour grid ("large steps" for voxel fields, cf. Nicolet et al. 2021, who precondition mesh gradients by
(I + λL)⁻¹), weighted so that it acts only where the target is flat.

Why: the loss sees a voxel's mixture only through light that has scattered over several voxels, so its curvature
is small at voxel-scale spatial frequencies, while a few-spp gradient puts as much noise there as anywhere. Plain
steps therefore let the mixture random-walk at those frequencies: the mottle (in flat regions the
prediction carries ~1 (ΔL*)² of texel-scale power that the target has no trace of: Spot 20 mm without smoothing,
experiments/results/shell_mm.json, ``none+smooth0`` and ``1+smooth0``). Diffusing the step damps each
spatial frequency by its heat-kernel factor: the noise injected at voxel scale shrinks by that factor, while the
low frequencies (the colour of a region) move at the full step.

What is diffused is the step the optimiser chose (new x - x), not the gradient: diffusing the gradient also
lowers the exponentiated-gradient step scale (the 99th percentile of |g|, which the voxel-scale noise sets), i.e.
makes every step larger, and it cost the zebra chart SSIM (docs/experiments.md, "Step smoothing").

Guided by the target: the diffusion between two voxels is weighted by exp(-|guide_r - guide_q|² / edge²), the
guide being each voxel's nearest texel's target CIELAB and its depth below that texel (``DEPTH_DE`` ΔE76 per
voxel), so steps are smoothed within a region of one colour, mostly side by side under the surface, but not across
the target's edges, where the optimum changes sharply (unguided, the zebra chart lost SSIM: docs/experiments.md),
and only a little from one depth to the next.

Steps: ``d <- d + a * sum_nb w (d_nb - d)`` with a = 1/8, repeated an even number of times ``k = 2 ceil(sigma² /
(4 a))``, so the kernel's variance along each axis is 2 a k >= sigma² (voxel units). One step's eigenvalues lie in
[-1/2, 1] (weights <= 1, 6 neighbours); an even number of them makes the preconditioner symmetric with
eigenvalues in [0, 1]: it never reverses or lengthens any spatial mode of the step. Voxels that are not free
(fixed shares, outside the object) are not neighbours: no flux crosses to them (Neumann boundary), and the sum
of the step over a connected free region is kept.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .. import heap
from ..threads import check_threads

ALPHA = 0.125


def diffusion_steps(sigma: float) -> int:
    """Number of explicit steps (even) whose kernel has a standard deviation of at least ``sigma`` voxels."""
    return 0 if sigma <= 0 else 2 * math.ceil(sigma * sigma / (4 * ALPHA))


#: ΔE76 that one voxel of difference in depth (distance to the nearest texel) counts as in the guide: with the
#: default edge of 4 ΔE76, neighbours one voxel apart in depth exchange a little per pass (weight e^-1.56 = 0.21),
#: those side by side under a face fully. Not more: on a mesh, grid neighbours side by side under a sloped surface
#: differ by up to ~0.7 voxel in their distance to the nearest (surface-voxel) texel; with 30 ΔE76 per voxel only
#: a third of the smoothed set's neighbour pairs on Spot 20 mm keep a weight above 0.1 and the smoothing hardly
#: acts on curved surfaces. Measured 30 against 5 (experiments/results/convergence_*.json entries ``smooth1.5*``,
#: shell_mm.json ``none+smooth1.5_depth*``): the demo slab equal, the astronaut photograph and Spot better.
DEPTH_DE = 5.0


#: Voxels farther than this from every texel (voxels; 0.85 mm at 300 DPI) are not smoothed: light that reaches
#: them and comes back out is a small part of what a texel shows, so their steps carry little of the mottle, and
#: the nearest-texel search for the deep interior of a big object (most of its voxels, each far from every texel)
#: would cost minutes (Spot 40 mm: 15.7 M free voxels).
MAX_DEPTH = 10.0


def nearest_texels(
    shape,
    index: np.ndarray,
    pos_vox: np.ndarray,
    max_dist: float = np.inf,
    chunk: int = 1 << 21,
    threads: int | None = None,
):
    """For voxels ``index`` (F,) (increasing linear indices into the grid ``shape`` (z, y, x)): the nearest
    texel (F,) int64 and the distance to it (F,) float32, in voxels; for voxels with no texel within
    ``max_dist``, -1 and inf. ``pos_vox`` (I, 3) texel positions (x, y, z) in voxel units (``Texels.pos_vox``).
    Works in chunks of voxels (``nearest_texel_chunks``), on ``threads`` threads (default all cores)."""
    index = np.asarray(index)
    k = np.empty(len(index), np.int64)
    dist = np.empty(len(index), np.float32)
    for lo, k_c, d_c in nearest_texel_chunks(shape, index, pos_vox, max_dist, chunk, threads):
        k[lo : lo + len(k_c)], dist[lo : lo + len(k_c)] = k_c, d_c
    return k, dist


def nearest_texel_chunks(
    shape, index: np.ndarray, pos_vox: np.ndarray, max_dist: float = np.inf, chunk: int = 1 << 21, threads=None
):
    """``nearest_texels`` a chunk of ``chunk`` voxels at a time: yields (lo, nearest (K,) int64, distance (K,)
    float32) of the voxels index[lo:lo + K], so a caller that keeps only some of them holds no (F,) arrays."""
    tree = cKDTree(np.asarray(pos_vox, np.float64))
    index = np.asarray(index)
    for s in range(0, len(index), chunk):
        z, y, x = np.unravel_index(index[s : s + chunk], shape)
        dist, k = tree.query(
            np.stack([x, y, z], axis=1) + 0.5, workers=check_threads(threads) or -1, distance_upper_bound=max_dist
        )
        k[k == tree.n] = -1
        yield s, k.astype(np.int64, copy=False), dist.astype(np.float32)


@dataclass(frozen=True)
class SmoothGuide:
    """The smoothing's guide: row r's vector is ``table[key[r]]`` followed by ``extra[r]`` if given.

    table (T, D) float32; key (K,) uint32 (None: row r's entry is r, T = K); extra (K,) float32 or None. Voxels
    under one texel share its entry of the table (its target CIELAB), so the loop's guide holds 8 bytes per voxel
    (a key and a depth), not 16.
    """

    table: np.ndarray
    key: np.ndarray | None = None
    extra: np.ndarray | None = None

    @classmethod
    def of_rows(cls, values: np.ndarray) -> SmoothGuide:
        """A vector per row: ``values`` (K, D)."""
        return cls(np.ascontiguousarray(values, np.float32))

    def __post_init__(self):
        object.__setattr__(self, "table", np.ascontiguousarray(self.table, np.float32))
        if self.table.ndim != 2 or self.table.shape[1] == 0:
            raise ValueError(f"the guide's table must be (entries, dims), got {self.table.shape}")
        for name, dtype in (("key", np.uint32), ("extra", np.float32)):
            v = getattr(self, name)
            if v is not None:
                object.__setattr__(self, name, np.ascontiguousarray(v, dtype))
        if self.key is not None and len(self.key) and int(self.key.max()) >= len(self.table):
            raise ValueError(f"the guide's keys reach past its table of {len(self.table)} entries")
        if self.key is not None and self.extra is not None and len(self.key) != len(self.extra):
            raise ValueError(f"the guide has {len(self.key)} keys and {len(self.extra)} extra values")

    def __len__(self) -> int:
        """K, the number of rows it guides."""
        return len(self.key if self.key is not None else self.table)

    def dense(self) -> np.ndarray:
        """(K, D [+ 1]) float32: every row's vector (for small sets and tests)."""
        rows = self.table if self.key is None else self.table[self.key]
        return rows if self.extra is None else np.concatenate([rows, self.extra[:, None]], axis=1)


def texel_guide(
    target_lab: np.ndarray, nearest: np.ndarray, dist: np.ndarray, depth_de: float = DEPTH_DE
) -> SmoothGuide:
    """The guide of voxels whose nearest texel is ``nearest`` (K,) at ``dist`` (K,) voxels (from
    :func:`nearest_texels`): that texel's CIELAB target (``target_lab`` (I, 3), shared as the table) and the
    distance times ``depth_de``."""
    dist = np.asarray(dist, np.float32)
    return SmoothGuide(np.asarray(target_lab, np.float32), np.asarray(nearest, np.uint32), dist * depth_de)


def flat_texel_guide(shape, free_index: np.ndarray, pos_vox: np.ndarray, loss, threads=None):
    """The guided smoothing's set and guide: the free voxels (``free_index`` (F,), increasing linear indices into
    the grid ``shape``) whose nearest texel (``pos_vox`` (I, 3)) is within ``MAX_DEPTH`` voxels and flat
    (``loss.flat`` (I,) bool), as row numbers (K,) uint32, and their :func:`texel_guide` (``loss.target_lab``).
    Found a chunk of voxels at a time, keeping only those rows: no (F,) arrays beside the smoother's own."""
    parts = []
    for lo, near, dist in nearest_texel_chunks(shape, free_index, pos_vox, MAX_DEPTH, threads=threads):
        keep = np.flatnonzero((near >= 0) & loss.flat[near])
        parts.append(((keep + lo).astype(np.uint32), near[keep].astype(np.uint32), dist[keep]))
    empty = (np.empty(0, np.uint32), np.empty(0, np.uint32), np.empty(0, np.float32))
    rows, near, dist = (np.concatenate(a) for a in zip(*(parts or [empty]), strict=True))
    del parts
    return rows, texel_guide(loss.target_lab, near, dist)


class GradientSmoother:
    """Diffuses per-free-voxel arrays (F, N) over a set of the free voxels' 6-neighbourhood (the loop in the Rust
    core, ``inkopt_core::kernels::smooth``: parallel, thread-count independent; during a call, a column at a time,
    two working copies of the column (8 bytes per voxel of the set) and each voxel's neighbours and weights (29
    bytes); kept for the run: the set's rows and the guide's key and depth, 4 + 8 bytes per voxel of the set).

    shape (z, y, x) of the grid; index (F,) int64: the free voxels' increasing linear indices
    (``Parameterization.free_index``; kept by reference); ``rows``: which of them are smoothed (e.g. those under
    flat texels), increasing row numbers (kept as uint32), or None for all; the others are left as they are and
    exchange nothing with the set (no flux crosses its boundary). ``sigma``: kernel width in voxels (> 0);
    ``guide`` (a :class:`SmoothGuide`, or a (len(rows), D) float32 array: a vector per row) and ``edge``:
    neighbours are weighted by exp(-|guide_r - guide_q|² / edge²) (e.g. the voxels' target CIELAB and depth from
    :func:`texel_guide` and an edge in ΔE76); None: unweighted. ``threads``: default all
    cores (results do not depend on it).
    """

    def __init__(
        self,
        shape,
        index: np.ndarray,
        sigma: float,
        guide: SmoothGuide | np.ndarray | None = None,
        edge: float = 0.0,
        rows: np.ndarray | None = None,
        threads: int | None = None,
    ):
        if not sigma > 0:
            raise ValueError(f"smoothing width must be positive, got {sigma}")
        if guide is not None and not edge > 0:
            raise ValueError(f"the guide's edge must be positive, got {edge}")
        self.steps = diffusion_steps(sigma)
        self.shape = tuple(int(v) for v in shape)
        self.rows = None if rows is None else _row_numbers(rows)
        index = np.asarray(index, np.int64)
        self.free_index = index  # the set's voxel indices are gathered from it at each call, not kept (8 B a voxel)
        n = len(index) if self.rows is None else len(self.rows)
        if guide is not None and not isinstance(guide, SmoothGuide):
            guide = SmoothGuide.of_rows(guide)
        self.guide = guide
        if self.guide is not None and len(self.guide) != n:
            raise ValueError(f"the guide has {len(self.guide)} rows for a set of {n} voxels")
        self.edge, self.threads = float(edge), check_threads(threads)

    @property
    def index(self) -> np.ndarray:
        """(K,) int64: the linear indices of the set's voxels (a new array when the set is not every free voxel)."""
        return self.free_index if self.rows is None else np.ascontiguousarray(self.free_index[self.rows])

    def __call__(self, g: np.ndarray) -> np.ndarray:
        """The diffused copy of g (F, N) float32 (g itself is not changed; rows outside the set are copied)."""
        return self.apply(np.array(g, np.float32))

    def apply(self, g: np.ndarray) -> np.ndarray:
        """Diffuse g (F, N) float32 (C-contiguous) in place (rows outside the set unchanged) and return it.

        The kernel reads the set's rows of g through ``rows`` and diffuses a slab of z-planes at a time (with the
        planes the steps reach on either side) and one column at a time (each column's and each slab's diffusion is
        the whole set's, bit for bit), so a call holds a slab's neighbours and weights (29 bytes per voxel) and its
        column's two working copies (8 bytes), no copy of g or of the set's voxel indices."""
        from .. import _core

        if g.dtype != np.float32 or not g.flags.c_contiguous:
            raise ValueError("the smoothed array must be C-contiguous float32")
        # the heap's free memory (what the step's earlier temporaries left there) given back first, so that the
        # kernel's working arrays are not placed beside it: Spot 40 mm with a 1 mm shell, 17 B per free voxel
        # resident above the step's start after the update without it (bench/results/step_memory_spot.json,
        # entries 40mm_shell1_mem_before and _mem_after)
        heap.trim()
        gd = self.guide
        _core.smooth_rows(
            self.shape,
            self.free_index,
            g,
            self.steps,
            ALPHA,
            None if gd is None else gd.table,
            self.edge or 1.0,
            self.threads,
            self.rows,
            None if gd is None else gd.key,
            None if gd is None else gd.extra,
        )
        return g


def _row_numbers(rows) -> np.ndarray:
    """(K,) uint32 row numbers (4 bytes per smoothed voxel; the kernel refuses sets of 2³² - 1 rows or more)."""
    rows = np.asarray(rows)
    if len(rows) and (rows.min() < 0 or rows.max() >= np.iinfo(np.uint32).max):
        raise ValueError("the smoothed rows must be row numbers below 2**32 - 1")
    return np.ascontiguousarray(rows, np.uint32)
