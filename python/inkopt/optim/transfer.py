"""Coarse to fine: a result on one grid (e.g. a run at 150 DPI) as the start of a run of the same object on
another grid (300 DPI).

The mixture is moved in millimetres by ``model.resample.MixtureResampler`` ("linear": trilinear over the source's
inside voxels; a voxel the source does not hold takes the nearest inside source voxel's mixture) to the free voxels
of the destination scene, and mapped to their free part exactly as a start from a volume file is
(``param.free_part``: the destination's fixed shares, the white core and translucency constraints, stay what its
scene fixes).

A coarse stage that started from a baseline B (a print-shop start, e.g. the extrusion baseline, on each grid: B_c
on the coarse one, B_f on the fine one) is moved by the correction scheme of multigrid instead: the fine start is
B_f + U(C - B_c), its whole mixture rows then mapped to the free part as above (clipped at 0, renormalised to sum 1,
the fixed shares kept). U, the same resampler, is linear in the mixture (its weights depend on the inside masks
only, the same for C and B_c), so U(C - B_c) = U(C) - U(B_c), each resampled on its own (each renormalised to sum
1 as the plain transfer's rows are; not side by side, which would copy both coarse grids into one (z, y, x, 2N)
array: 4.7 GB at Spot 100 mm's 150-DPI grid). The fine start keeps the baseline's detail finer
than the coarse grid (B_f - U(B_c)) and takes the coarse stage's change at the scales that grid resolves. It is
done in shares, not in the optimiser's logits: a change of logits is a ratio of shares, and a baseline's shares
reach 0 (an ink its colour does not use), where a ratio is unbounded (a coarse voxel taking an ink from 1e-6 to 0.1
would multiply that ink a hundred-thousand-fold in every fine voxel that has some of it); a change of shares is
bounded by 1 and U reproduces a constant, so from white (B the same row everywhere) the correction is zero and the
transfer is the plain one. :class:`Baseline` carries B; without it the plain transfer runs.

:func:`write_transferred_volume` writes the result as a mixture volume file on the destination's grid, which a
run takes as its start with ``OptimizeConfig(init=PATH)``; :func:`write_transferred_rows` writes only the
destination's free voxels' rows (``optim.startrows``: 8 + 4N bytes per free voxel, what a coarse-to-fine job
writes, ``coarse.run_coarse_to_fine``) and :func:`write_start_volume` turns such a file into the whole grid's
volume; :func:`transferred_free_mixture` gives the free part (F, N) directly. :func:`coarse_start` is the whole
first stage: optimise the coarse scene (no evaluation, no checkpoints) and write its result as the start of the
fine scene's run (a :class:`CoarseStart`).

Memory: the source (a mixture volume, or held by its band, ``model.banded.BandMixture``: a run's result read by
:func:`coarse_result`; with a baseline, B_c too), the destination's free index (``Parameterization``), and per
chunk of free voxels the resampling temporaries; never a (z, y, x, N) array of the destination grid (the volume
file is written in z slabs of ``SLAB_VOXELS`` voxels, about 80 MB each). The run that starts from the file reads it
in blocks (``param.file_free_mixture``), keeping only the free voxels' free part (F, N).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..model import FixedShares, Volume
from ..model.banded import BandMixture
from ..model.mixturefile import MixtureSource
from ..model.resample import CHUNK, MixtureResampler
from .config import OptimizeConfig
from .loop import Optimization
from .param import Parameterization, free_part
from .startrows import save_start_rows, start_rows_blocks

#: destination voxels per written slab of layers (about 80 MB of float32 mixture at 5 inks)
SLAB_VOXELS = 1 << 22


def _source(source: Volume | BandMixture | str | Path) -> Volume | BandMixture:
    if isinstance(source, BandMixture):
        return source
    vol = source if isinstance(source, Volume) else Volume.load(source)
    vol.require_mixture("a coarse-to-fine start")
    return vol


def coarse_result(path: str | Path) -> Volume | BandMixture:
    """A run's result volume file ``path`` as a transfer's source: held by its band when it has an inside mask
    (``MixtureSource.band_volume``: read a layer at a time, 8 + 4N bytes per voxel not in its core), else whole
    (a slab's)."""
    with MixtureSource(path, "a coarse-to-fine start") as src:
        if src.inside is not None:
            return src.band_volume()
    return _source(path)


def _geometry(src: Volume | BandMixture) -> Volume:
    """The volume holding ``src``'s grid, inside mask and inks."""
    return src.volume if isinstance(src, BandMixture) else src


def _check(src: Volume | BandMixture, base: Volume) -> None:
    inks = _geometry(src).inks
    if base.inks is None or inks.names != base.inks.names:
        have = list(inks.names)
        want = None if base.inks is None else list(base.inks.names)
        raise ValueError(f"the source mixture's inks {have} differ from the destination's {want}")


@dataclass(frozen=True)
class Baseline:
    """The start B of a coarse stage that began from a baseline, for the correction transfer (module docstring):
    ``coarse``, its mixture on the coarse grid (the grid and inside mask of the coarse result), a mixture volume or
    a ``BandMixture`` (``model.banded``: held by its band, the same values); ``fine``, its
    mixture on the destination grid one z layer at a time: ``fine[z]`` (Y, X, N) float32 and ``fine.shape``
    (Z, Y, X, N) (``evaluation.baselines.BaselineLayers``, or a whole array)."""

    coarse: Volume | BandMixture
    fine: object


class _LayerRows:
    """The rows (K, N) float32 of a layer source (``Baseline.fine``) at flat grid indices, given in increasing order
    over the calls: each z layer is made once (the last one is kept for the next call)."""

    def __init__(self, layers, shape, n: int):
        if tuple(layers.shape) != (*shape, n):
            raise ValueError(f"the fine baseline has shape {tuple(layers.shape)}, expected {(*shape, n)}")
        self.layers, self.plane, self.n, self.z, self.layer = layers, shape[1] * shape[2], n, -1, None

    def __call__(self, index: np.ndarray) -> np.ndarray:
        out = np.empty((len(index), self.n), np.float32)
        z = index // self.plane
        cuts = [0, *(np.flatnonzero(np.diff(z)) + 1), len(index)]
        for lo, hi in zip(cuts[:-1], cuts[1:], strict=False):
            if hi > lo:
                if z[lo] != self.z:
                    self.z, self.layer = int(z[lo]), np.asarray(self.layers[int(z[lo])]).reshape(-1, self.n)
                out[lo:hi] = self.layer[index[lo:hi] - self.z * self.plane]
        return out


class _Mover:
    """The whole mixture rows of the destination's free voxels: U(C) (the plain transfer), or with a baseline
    B_f + U(C) - U(B_c) (float64; the correction transfer), U(C) and U(B_c) resampled apart."""

    def __init__(self, src: Volume | BandMixture, base: Volume, method: str, baseline: Baseline | None):
        self.base, self.n, self.fine_rows, self.up_b = base, len(base.inks), None, None
        self.up = MixtureResampler(src, method)
        if baseline is None:
            return
        bc = _source(baseline.coarse)
        _check(bc, base)
        geo_b, geo_c = _geometry(bc), _geometry(src)
        if geo_b.shape != geo_c.shape or not np.array_equal(geo_b.inside_mask(), geo_c.inside_mask()):
            raise ValueError("the coarse baseline's grid or inside mask differs from the coarse result's")
        self.up_b = MixtureResampler(bc, method)
        self.fine_rows = _LayerRows(baseline.fine, base.shape, self.n)

    def rows(self, index: np.ndarray, chunk: int) -> np.ndarray:
        grid = (self.base.shape, self.base.voxel_mm, self.base.origin_mm, chunk)
        up_c = self.up.on_grid(index, *grid)
        if self.fine_rows is None:
            return up_c
        up_c, up_b = up_c.astype(np.float64), self.up_b.on_grid(index, *grid).astype(np.float64)
        change = up_c / up_c.sum(axis=1, keepdims=True) - up_b / up_b.sum(axis=1, keepdims=True)
        return self.fine_rows(index) + change


def destination(base: Volume, fixed_share: FixedShares | None) -> Parameterization:
    """The free voxels of a run of the scene of ``base`` (the destination's volume) whose fixed shares are
    ``fixed_share`` (None: none): its ``Parameterization`` (their ``free_index`` is the run's, whatever its kind)."""
    fs = FixedShares.none(base.shape, len(base.inks)) if fixed_share is None else fixed_share
    return Parameterization("softmax", fs)


def _free_slab(mover: _Mover, param: Parameterization, a: int, b: int, chunk: int) -> np.ndarray:
    """The free part p (b - a, N) float64 of the free voxels a:b (``free_index`` order)."""
    rows = mover.rows(param.free_index[a:b], chunk)
    fixed = None if param.fixed_f is None else param.fixed_f[a:b]
    return free_part(rows, fixed, param.share_f[a:b])


def transferred_free_mixture(
    source: Volume | str | Path,
    base: Volume,
    fixed_share: FixedShares | None = None,
    method: str = "linear",
    chunk: int = CHUNK,
    baseline: Baseline | None = None,
) -> np.ndarray:
    """The free part (F, N) float32 (rows summing to 1, ``Parameterization.free_index`` order) of the mixture of
    ``source`` (a mixture volume or its file) moved onto the grid of ``base`` (the destination scene's volume:
    shape, ``voxel_mm``, ``origin_mm``, inks) whose fixed shares are ``fixed_share`` (None: none); with
    ``baseline`` (the source's start B, a :class:`Baseline`) by the correction transfer B_f + U(C - B_c)."""
    src = _source(source)
    _check(src, base)
    param = destination(base, fixed_share)
    mover = _Mover(src, base, method, baseline)
    out = np.empty((param.n_free, len(base.inks)), np.float32)
    for a in range(0, param.n_free, chunk):
        b = min(param.n_free, a + chunk)
        out[a:b] = _free_slab(mover, param, a, b, chunk)
    return out


def write_transferred_volume(
    source: Volume | str | Path,
    base: Volume,
    fixed_share: FixedShares | None,
    path: str | Path,
    method: str = "linear",
    chunk: int = CHUNK,
    slab_voxels: int = SLAB_VOXELS,
    baseline: Baseline | None = None,
    compressed: bool = True,
) -> Path:
    """Write to ``path`` (atomically) a mixture volume file on the grid of ``base`` (its geometry: inside mask,
    normals, origin, boundary) holding the fixed shares ``fixed_share`` (None: none) plus, at the free voxels, the
    free part of ``source``'s mixture moved onto that grid (:func:`transferred_free_mixture`; with ``baseline``
    by the correction transfer), ``slab_voxels`` destination voxels at a time; ``compressed`` False: the file is
    stored without zlib (4 bytes per ink per grid voxel; a coarse-to-fine job's own start, written and read once:
    zlib took a third of the box's 20 mm transfer, ``coarse.run_coarse_to_fine``). A run of the destination scene
    started from it (``OptimizeConfig(init=path)``) starts from exactly that free part (up to the
    parameterisation's clipping at 1e-6)."""
    src = _source(source)
    _check(src, base)
    param = destination(base, fixed_share)
    mover = _Mover(src, base, method, baseline)
    whole = _whole_rows(mover, param, chunk)
    base.save_with_mixture(path, param.grid_slabs(whole, slab_voxels, chunk), base.inks, compressed=compressed)
    return Path(path)


def write_start_volume(
    start: str | Path, base: Volume, fixed_share: FixedShares | None, path: str | Path, slab_voxels: int = SLAB_VOXELS
) -> Path:
    """Write to ``path`` (atomically) the start-rows file ``start`` (``optim.startrows``, of a run of the scene of
    ``base`` whose fixed shares are ``fixed_share``) as a mixture volume file of the whole grid of ``base``: the
    fixed shares, the file's rows at its free voxels (what :func:`write_transferred_volume` writes for the same
    transfer, bit for bit), e.g. to render or print a coarse-to-fine job's start. Holds the file's rows (F, N)."""
    param = destination(base, fixed_share)
    rows = np.empty((param.n_free, len(base.inks)), np.float32)
    for lo, part in start_rows_blocks(start, base.inks, base.shape, param.free_index):
        rows[lo : lo + len(part)] = part
    base.save_with_mixture(path, param.grid_slabs(lambda a, b: rows[a:b], slab_voxels), base.inks)
    return Path(path)


def _whole_rows(mover: _Mover, param: Parameterization, chunk: int):
    """rows(a, b): the whole mixtures (b - a, N) float64 (fixed shares plus the free part moved) of the free voxels
    a:b, at most ``chunk`` of them."""

    def rows(a: int, b: int) -> np.ndarray:
        whole = param.share_f[a:b, None] * _free_slab(mover, param, a, b, chunk)
        return whole if param.fixed_f is None else whole + param.fixed_f[a:b]

    return rows


def write_transferred_rows(
    source: Volume | BandMixture | str | Path,
    base: Volume,
    param: Parameterization,
    path: str | Path,
    method: str = "linear",
    chunk: int = CHUNK,
    baseline: Baseline | None = None,
) -> Path:
    """Write to ``path`` (atomically) a start-rows file (``optim.startrows``) of ``param``'s free voxels (a
    ``Parameterization`` of the fixed shares of ``base``, the destination scene's volume): their whole mixtures,
    the fixed shares plus the free part of ``source``'s mixture moved onto the grid of ``base``
    (:func:`transferred_free_mixture`; with ``baseline`` by the correction transfer), ``chunk`` voxels at a time:
    the rows :func:`write_transferred_volume` writes at those voxels, bit for bit, in 8 + 4N bytes per free voxel
    instead of 4N per grid voxel. A run of the destination scene started from it (``OptimizeConfig(init=path)``)
    starts from exactly that free part (up to the parameterisation's clipping at 1e-6)."""
    src = _source(source)
    _check(src, base)
    if tuple(param.shape) != tuple(base.shape):
        raise ValueError(f"the free voxels are of a grid of {param.shape}, the destination's is {base.shape}")
    whole = _whole_rows(_Mover(src, base, method, baseline), param, chunk)
    rows = (whole(a, min(param.n_free, a + chunk)) for a in range(0, param.n_free, chunk))
    return save_start_rows(path, base.shape, base.inks, param.free_index, rows)


@dataclass
class CoarseStart:
    """What :func:`coarse_start` did: the start volume file ``path``, the coarse run's ``iterations``, its wall
    seconds (``setup_seconds``: parameterisation, loss, smoother; ``seconds``: the iterations), the transfer's
    (``transfer_seconds``: resampling and writing the file) and its training mean ΔE76 per iteration."""

    path: str
    iterations: int
    setup_seconds: float
    seconds: float
    transfer_seconds: float
    delta_e76: list = field(default_factory=list)

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> CoarseStart:
        return cls(**d)


def coarse_start(
    coarse,
    fine,
    cfg: OptimizeConfig,
    path: str | Path,
    *,
    threads: int | None = None,
    lighting=None,
    method: str = "linear",
    log=None,
    coarse_path: str | Path | None = None,
) -> CoarseStart:
    """Optimise the scene ``coarse`` (the same object as ``fine`` on a coarser grid, e.g. its spec at half the DPI)
    for ``cfg.iterations`` from ``cfg.init``, then write its result moved onto ``fine``'s grid (free voxels, fixed
    shares) to ``path`` (:func:`write_transferred_volume`): the start of ``fine``'s run, ``OptimizeConfig(init=path)``.
    ``log``: progress lines of the coarse iterations; ``coarse_path``: also save the coarse result there (a mixture
    volume file on the coarse grid; not counted in ``transfer_seconds``)."""
    t0 = time.perf_counter()
    run = Optimization(coarse, cfg.for_scene(coarse.kind), threads=threads, lighting=lighting)
    setup_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    run.run(log=log, log_every_s=60.0)
    run_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    iterations, history = run.iteration, [float(v) for v in run.history.delta_e76]
    result = run.volume()  # the coarse grid's mixture (an eighth of the fine grid's voxels at half the DPI)
    del run  # the coarse run's renderer, loss and smoother, before the fine grid's slabs are made
    write_transferred_volume(result, fine.volume, fine.fixed_share, path, method)
    transfer_s = time.perf_counter() - t0
    if coarse_path is not None:
        result.save(coarse_path)
    return CoarseStart(str(path), iterations, setup_s, run_s, transfer_s, history)
