"""The optimisation variables: for every *free* voxel an unconstrained vector x (N inks), mapped to a mixture by
``sigmoid`` (the paper: sigmoid, then per-voxel normalisation) or ``softmax``, and the run's starting point.

Constraints are fixed ink shares: a voxel's mixture is ``fixed_share + (1 - sum(fixed_share)) * p(x)``; a voxel
whose fixed share sums to 1 is not a variable at all (a white core below a shell, masks), and a share below 1 fixes
part of the mixture (e.g. 80 % transparent ink in a translucent region, the rest optimised).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..errors import ParameterError
from ..model import FixedShares, InkTable
from ..model.mixturefile import MixtureSource
from ..threads import check_threads
from .config import PARAMS

BAD_SHARES = "fixed ink shares must be non-negative and sum to at most 1 per voxel"


class Parameterization:
    """Maps variables x (F, N) of the free voxels to the full mixture (z, y, x, N), and gradients back.

    fixed_share: the (z, y, x, N) ink shares the optimiser may not change (:class:`~inkopt.model.FixedShares`, kept
    by reference; no grid-sized float array is made from it). ``threads``: threads of the softmax and its backward
    map (default all cores; results do not depend on it).
    """

    def __init__(self, kind: str, fixed_share: FixedShares, threads: int | None = None):
        if kind not in PARAMS:
            raise ValueError(f"unknown parameterisation '{kind}'")
        self.kind, self.threads = kind, check_threads(threads)
        fs = fixed_share
        if (
            np.any(fs.held < 0)
            or np.any(fs.rows < 0)
            or np.any(fs.rows.sum(-1) > 1 + 1e-5)
            or (fs.held.sum() > 1 + 1e-5 and not fs.mask.all())
        ):
            raise ValueError(BAD_SHARES)
        self.fixed_share, self.n_inks = fs, fs.shape[-1]
        held_free = np.clip(1.0 - fs.held.sum(), 0.0, 1.0) > 1e-6  # the held row leaves room: variables too
        room = np.clip(1.0 - fs.rows.sum(-1), 0.0, 1.0) > 1e-6  # indexed voxels whose rows leave room
        # the free (or, with room in the held row, all) voxels not indexed, and the indexed ones with room
        base = np.arange(fs.mask.size, dtype=np.int64) if held_free else fs.mask.nonzero()
        #: flat (z, y, x) indices of the free voxels (F,) int64, increasing (the renderer's gradient slots are in
        #: this order)
        self.free_index = np.union1d(base[~np.isin(base, fs.index)], fs.index[room]) if len(fs.index) else base
        del base
        #: the free voxels' free share (F,) float32 and fixed shares (F, N) (None: all zero), made in pieces; without
        #: fixed shares every free share is 1, held as a read-only broadcast view of one value (nothing per voxel)
        self.share_f = np.empty(len(self.free_index), np.float32)
        any_fixed = False
        for lo, hi in self.chunks():
            rows = fs.at(self.free_index[lo:hi])
            self.share_f[lo:hi] = np.clip(1.0 - rows.sum(-1), 0.0, 1.0)
            any_fixed = any_fixed or bool(rows.any())
        self.fixed_f = fs.at(self.free_index) if any_fixed else None
        if not any_fixed:
            self.share_f = np.broadcast_to(np.float32(1.0), self.share_f.shape)  # the same values: 1 - 0

    def share_index(self, index: np.ndarray | None) -> None:
        """Hold ``index`` ((F,) int64, e.g. a band's, ``model.media.Band``) as ``free_index`` when it lists the same
        voxels: one array for both (8 bytes per free voxel) where a band is only the free voxels."""
        if index is not None and np.array_equal(index, self.free_index):
            self.free_index = index

    @property
    def shape(self) -> tuple:
        """(z, y, x) of the grid."""
        return tuple(self.fixed_share.shape[:3])

    @property
    def n_free(self) -> int:
        return len(self.free_index)

    def held_index(self, base) -> np.ndarray:
        """Flat indices ((K,) int64) of the inside voxels of ``base`` (a ``Volume`` with an inside mask) that are not
        variables and whose fixed shares a renderer of it is given once: with a band (``Volume.band``) only the
        band's, since its core holds the core's mixture already; else every one."""
        if base.band is not None:
            return _sorted_difference(base.band.index, self.free_index)
        held = base.inside.dense()
        held.reshape(-1)[self.free_index] = False
        return np.flatnonzero(held)

    def chunks(self, rows: int = 1 << 20):
        """Row ranges (lo, hi) covering the F free voxels, ``rows`` at a time: the per-voxel arithmetic of a big
        object in pieces, so that its temporaries are a few MB instead of several (F, N) arrays. Every operation
        is per row, so the result does not depend on the chunking, bit for bit."""
        return [(lo, min(lo + rows, self.n_free)) for lo in range(0, self.n_free, rows)]

    def _p(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Free-part mixture p (F, N) and an auxiliary array for the backward pass."""
        if self.kind == "softmax":  # in the Rust core: parallel and one pass, without numpy's (F, N) temporaries
            from .. import _core

            p = _core.softmax_rows(np.ascontiguousarray(x, np.float32), self.threads)
            return p, p
        s = 1.0 / (1.0 + np.exp(-x))
        return s / s.sum(axis=1, keepdims=True), s

    def free_rows(self, x: np.ndarray, lo: int = 0) -> np.ndarray:
        """The free voxels' whole mixtures (F, N) float32 (fixed + free part), in ``free_index`` order: what
        :meth:`mixture` holds at those voxels, bit for bit. ``x`` may be the rows lo:lo+len(x) only."""
        hi = lo + len(x)
        p, _ = self._p(x)
        rows = self.share_f[lo:hi, None] * p
        return rows if self.fixed_f is None else self.fixed_f[lo:hi] + rows

    def mixture(self, x: np.ndarray) -> np.ndarray:
        """The whole grid's mixture (z, y, x, N) float32 of variables x (F, N)."""
        rho = self.fixed_share.dense().reshape(-1, self.n_inks)
        for lo, hi in self.chunks():  # in pieces: no (F, N) temporaries beside the grid-sized result
            rho[self.free_index[lo:hi]] = self.free_rows(x[lo:hi], lo)
        return rho.reshape(self.shape + (self.n_inks,))

    def mixture_slabs(self, x: np.ndarray, voxels: int = 1 << 22):
        """The whole grid's mixture of variables x (F, N) as (k, y, x, N) float32 slabs of about ``voxels`` voxels
        in z order (an iterator; each slab equals the same layers of :meth:`mixture`, bit for bit), so that a big
        object's result can be written without the grid-sized array."""
        return self.grid_slabs(lambda a, b: self.free_rows(x[a:b], a), voxels)

    def grid_slabs(self, rows, voxels: int = 1 << 22, chunk: int = 1 << 20):
        """The whole grid's mixture as (k, y, x, N) float32 slabs of about ``voxels`` voxels in z order (an
        iterator): the fixed shares, and at the free voxels a:b (``free_index`` order) the whole mixtures
        ``rows(a, b)`` ((b - a, N), at most ``chunk`` of them)."""
        nz, ny, nx = self.shape
        plane = ny * nx
        step = max(1, voxels // max(plane, 1))
        fs = self.fixed_share
        for z0 in range(0, nz, step):
            z1 = min(nz, z0 + step)
            rho = fs.at(np.arange(z0 * plane, z1 * plane, dtype=np.int64))
            lo, hi = np.searchsorted(self.free_index, [z0 * plane, z1 * plane])
            for a in range(lo, hi, chunk):
                b = min(hi, a + chunk)
                rho[self.free_index[a:b] - z0 * plane] = rows(a, b)
            yield rho.reshape(z1 - z0, ny, nx, self.n_inks)

    def backward(self, x: np.ndarray, grad_rho: np.ndarray, natural: bool = False, lo: int = 0) -> np.ndarray:
        """dE/dx (F, N) from dE/drho, given per free voxel (F, N) or for the whole grid (z, y, x, N).
        ``natural``: the mirror-descent direction on the simplex instead (softmax only): g - <g, p>, the
        exponentiated-gradient step in logit space. With ``lo``: x and grad_rho are the free voxels' rows
        lo:lo+len(x) only (see :meth:`chunks`)."""
        g = grad_rho.reshape(-1, self.n_inks)
        if len(g) != len(x):
            g = g[self.free_index]
        share = self.share_f[lo : lo + len(x)]
        if self.kind == "softmax":  # p and the centring fused in the Rust core (``inkopt_core::simplex``)
            from .. import _core

            return _core.softmax_backward(
                np.ascontiguousarray(x, np.float32),
                np.ascontiguousarray(g, np.float32),
                np.ascontiguousarray(share, np.float32),
                bool(natural),
                self.threads,
            )
        if natural:
            raise ValueError("the natural (exponentiated-gradient) direction needs the softmax parameterisation")
        g = g * share[:, None]
        p, s = self._p(x)
        centred = g - np.sum(g * p, axis=1, keepdims=True)
        return (centred * s * (1.0 - s) / s.sum(axis=1, keepdims=True)).astype(np.float32)

    def variables_for(self, p: np.ndarray, reuse: bool = False) -> np.ndarray:
        """Variables x (F, N) float32 whose free-part mixture is p (F, N) (entries clipped to [1e-6, 1]); row by
        row, in blocks (float64 temporaries of a block only). ``reuse``: p is the caller's to give up, and x is
        written over it when it is a writable float32 array of its own (each block is read before it is written),
        so that a baseline's start holds one (F, N) array, not two."""
        own = reuse and p.dtype == np.float32 and p.flags.writeable and p.flags.owndata and p.flags.c_contiguous
        x = p if own else np.empty(np.shape(p), np.float32)
        for lo in range(0, len(x), 1 << 20):
            q = np.clip(np.asarray(p[lo : lo + (1 << 20)], np.float64), 1e-6, 1.0)
            q /= q.sum(axis=1, keepdims=True)
            x[lo : lo + (1 << 20)] = np.log(q) if self.kind == "softmax" else np.log(q / (1.0 - q + 1e-12))
        return x  # sigmoid: sigmoid(x) = p, and sum(p) = 1


BASELINE_INITS = ("surface", "extrusion")


def initial_free_mixture(
    inks: InkTable, param: Parameterization, init: str, seed: int, baseline: Callable | None = None
) -> np.ndarray:
    """The free part's starting mixture (F, N): 97 % white + the rest split over the other inks (paper), a seeded
    random mixture, a print-shop baseline ("surface" or "extrusion"; ``baseline(kind)``, given by the caller,
    returns its (z, y, x, N) mixture as an array or layer by layer: ``layers_free_mixture``), or the mixture of
    an earlier result file on the same grid (its free part: ``free_part``, so a run's own result starts a run of
    the same scene where it ended, fixed shares and all)."""
    n, f = len(inks), param.n_free
    if init == "white":
        if "white" not in inks.names:
            raise ParameterError("`init` white needs a 'white' ink in the ink set; use `init` random")
        row = np.full(n, 0.03 / max(n - 1, 1), np.float64)
        row[inks.index("white")] = 0.97 if n > 1 else 1.0
        return np.broadcast_to(row, (f, n))  # one row for every voxel: a read-only view, no (F, N) array
    if init == "random":
        return np.random.default_rng(seed).dirichlet(np.ones(n), size=f)
    if init in BASELINE_INITS:
        if baseline is None:
            raise ParameterError(f"`init` {init} needs the run's texels and targets")
        return layers_free_mixture(baseline(init), n, param)
    return file_free_mixture(init, inks, param)


def layers_free_mixture(source, n: int, param: Parameterization) -> np.ndarray:
    """The free part (F, N) float32 of a mixture given one z layer at a time: ``source[z]`` (Y, X, N) and
    ``source.shape`` (Z, Y, X, N) (a print-shop baseline's ``BaselineLayers``, or a whole array), so that a big
    object's start holds one layer of the baseline beside the result, not its (Z, Y, X, N) mixture."""
    if tuple(source.shape) != (*param.shape, n):
        raise ValueError(f"a start of shape {tuple(source.shape)}, expected {(*param.shape, n)}")
    plane = param.shape[1] * param.shape[2]
    out = np.empty((param.n_free, n), np.float32)
    ends = np.searchsorted(param.free_index, np.arange(1, param.shape[0] + 1) * plane)
    lo = 0
    for z, hi in enumerate(ends):
        if hi > lo:
            rows = np.asarray(source[z]).reshape(-1, n)[param.free_index[lo:hi] - z * plane]
            fixed = None if param.fixed_f is None else param.fixed_f[lo:hi]
            out[lo:hi] = free_part(rows, fixed, param.share_f[lo:hi])
        lo = hi
    return out


#: mixture voxels per block read from a start volume file (about 20 MB of float32 at 5 inks)
BLOCK_VOXELS = 1 << 20


def file_free_mixture(path, inks: InkTable, param: Parameterization, voxels: int = BLOCK_VOXELS) -> np.ndarray:
    """The free part (F, N) float32 of the start file ``path`` (``--init FILE``) at ``param``'s free voxels:
    ``free_part`` of its rows. A mixture volume file (any of the grid ``param.shape`` with ``inks``, e.g. a run's
    volume.npz) is read ``voxels`` grid voxels at a time (``MixtureSource.blocks``), bit for bit what ``free_part``
    of the whole ``Volume.load(path).mixture`` gives; a start-rows file of exactly the run's free voxels
    (``optim.startrows``, a coarse-to-fine job's start) ``voxels`` rows at a time. Only a block of the file's
    mixture is in memory beside the result."""
    from .startrows import is_start_rows, start_rows_blocks

    n = len(inks)
    if is_start_rows(path):  # the free voxels' rows only (a coarse-to-fine job's start)
        out = np.empty((param.n_free, n), np.float32)
        for lo, rows in start_rows_blocks(path, inks, param.shape, param.free_index, voxels):
            hi = lo + len(rows)
            fixed = None if param.fixed_f is None else param.fixed_f[lo:hi]
            out[lo:hi] = free_part(rows, fixed, param.share_f[lo:hi])
        return out
    with MixtureSource(path, f"`init` {path}") as src:
        if src.inks.names != inks.names:
            raise ParameterError(f"`init` {path}: needs a mixture volume with inks {list(inks.names)}")
        if tuple(src.shape[:3]) != param.shape:
            raise ParameterError(
                f"`init` {path}: volume shape {tuple(src.shape[:3])} differs from {param.shape} (a result on "
                "another grid: optim.transfer.write_transferred_volume moves it onto this one)"
            )
        out = np.empty((param.n_free, n), np.float32)
        ends = np.searchsorted(param.free_index, np.arange(0, int(np.prod(param.shape)), voxels)[1:])
        lo = 0
        for (v0, rows), hi in zip(src.blocks(voxels), [*ends, param.n_free], strict=True):
            fixed = None if param.fixed_f is None else param.fixed_f[lo:hi]
            out[lo:hi] = free_part(rows[param.free_index[lo:hi] - v0], fixed, param.share_f[lo:hi])
            lo = hi
    return out


def free_part(rows: np.ndarray, fixed: np.ndarray | None, share: np.ndarray) -> np.ndarray:
    """The free part p (K, N) float64 of whole mixtures ``rows`` (K, N) at free voxels with fixed shares ``fixed``
    (K, N) (None: none) and free share ``share`` (K,): what ``Parameterization`` maps to ``fixed + share * p``.
    ``(rows - fixed) / share`` clipped at 0 and normalised to sum 1; a row with nothing left is uniform."""
    rho = np.asarray(rows, np.float64)
    p = np.clip(rho - (0.0 if fixed is None else fixed), 0.0, None) / np.asarray(share)[:, None]
    total = p.sum(1, keepdims=True)
    return np.where(total > 0, p / np.where(total > 0, total, 1.0), 1.0 / rho.shape[1])


def _sorted_difference(a: np.ndarray, b: np.ndarray, chunk: int = 1 << 20) -> np.ndarray:
    """The entries of ``a`` not in ``b``, both (K,) int64 strictly increasing, in ``a``'s order: what
    ``np.setdiff1d(a, b, assume_unique=True)`` gives, found ``chunk`` entries of ``a`` at a time by binary search
    in ``b``; sorting both joined, as ``setdiff1d`` does, holds ~50 B per entry (2.4 GB for a band of 47 M)."""
    if a is b or len(b) == 0:
        return a[:0].copy() if a is b else np.asarray(a, np.int64).copy()
    keep = []
    for lo in range(0, len(a), chunk):
        part = a[lo : lo + chunk]
        at = np.minimum(np.searchsorted(b, part), len(b) - 1)
        keep.append(part[b[at] != part])
    return np.concatenate(keep) if keep else a[:0].copy()
