"""What a run will cost before it starts: time, peak memory and disk, from the scene's counts and a short measured
calibration (``estimate_run``), for the line ``inkopt slab`` / ``optimize`` log before a long job and for
``--dry-run``, which prints only that line.

Time: an iteration is a forward render (``forward_spp``) and a gradient pass (``spp``) over every texel, plus the
step over the free voxels. The calibration throws a first pass away (its one-off set-up), times both passes of the run's
own renderer on one texel (the part that does not grow with the texels, ``a``: the gradient's per-voxel buffer and its
conversion, the set-up of a pass; they grow with the free voxels) and then on texel subsets (16 runs
of neighbouring texels, ``texel_runs``), grown until the passes take ``MIN_TEXEL_SECONDS`` and ``FIXED_MULTIPLE`` x
``a`` more than on one texel (or the subset is every texel), so that the part that grows with the texels (``b`` per
texel) stands clear of ``a``'s jitter; a stall only adds time, so every timing that decides is the smaller of two. An
iteration takes ``a + b * texels`` plus the step's per-voxel work, timed on up to 65 536 free voxels and scaled to all
of them (the step's smoothing is not included). The final evaluation (adaptive spp) is not in the estimate: the line
says so. A run whose seconds per iteration are known before it starts (a coarse-to-fine job's fine stage with a time
budget: the coarse stage's, scaled, ``coarse.fine_iteration_seconds``) takes them instead of the calibration
(``Estimate.scaled`` True); it builds the renderer only.

Memory: this process's peak resident memory after the calibration, which has built the renderer, the optimiser's
state and a gradient pass's per-voxel arrays, plus the per-texel arrays of full passes (``rgb``, variances, the
adjoint and the running average: ~64 bytes per texel); without a calibration, the peak once the renderer is built,
which leaves a gradient pass's per-voxel arrays out (the calibrated estimate was already 0.06-0.22 GiB below the
peaks the mesh suite's 20 mm fine stages measured; report.json's ``peak_rss_gb`` is the run's own).

Disk: volume.npz at most 4 bytes per ink per inside voxel (compressed, often less), the checkpoint (uncompressed:
variables and the two optimiser moments, 12 bytes per ink per free voxel; the running average and its variance, 24
bytes per texel; ~80 bytes of history per iteration) and scene.npz (~40 bytes per texel: voxel, face, normal,
target); ``inkopt quantize`` adds what ``quantized_bytes`` says: for a mesh, its layered labels file (the dithered
band; a few bytes per layer of the empty outside and the homogeneous core) and quantized.npz (the printer surface
voxels' normals), fitted per texel and per grid voxel; for a slab, whose every voxel may be dithered, at most a byte
per printer voxel (600 x 300 DPI, 27 µm layers: ~6.3 per optimisation voxel of the object's box).
"""

from __future__ import annotations

import resource
import time
from dataclasses import asdict, dataclass

import numpy as np

from .units import format_duration

CALIBRATION_TEXELS = 256
#: the calibration's texel subsets are this many runs of consecutive texels (``texel_runs``)
SAMPLE_RUNS = 16
#: the calibration's texel subset grows until its passes take this much longer than on one texel (seconds)
MIN_TEXEL_SECONDS = 0.3
#: ... and this many times the one-texel passes: their jitter (the per-voxel buffers' allocation) is then a quarter
#: of the texels' part at most (docs/experiments.md, "The run estimate's calibration")
FIXED_MULTIPLE = 4.0
#: an estimate longer than this gets its line in the log before the run starts (seconds)
ANNOUNCE_SECONDS = 180.0
#: printer voxels per optimisation voxel at the default 600 x 300 DPI and 27 µm layers on the 300 DPI grid
PRINTER_PER_OPT_VOXEL = 2.0 * 1.0 * (25.4 / 300 / 0.027)
#: bytes ``inkopt quantize`` writes for a mesh per scene texel and per grid voxel: fitted to Spot 40 and 100 mm with a
#: 1 mm band (16.9 and 167 MB), within 4 % of Spot 20 mm (a band or every voxel free) and 60 mm
#: (docs/performance.md, "The last mile")
QUANTIZED_BYTES_PER_TEXEL, QUANTIZED_BYTES_PER_GRID_VOXEL = 26.3, 0.11


def quantized_bytes(texels: int, grid_voxels: int, mesh: bool) -> int:
    """What ``inkopt quantize`` writes (module docstring): the fit above for a mesh, a byte per printer voxel of the
    grid for a slab."""
    if mesh:
        return int(QUANTIZED_BYTES_PER_TEXEL * texels + QUANTIZED_BYTES_PER_GRID_VOXEL * grid_voxels)
    return int(PRINTER_PER_OPT_VOXEL * grid_voxels)


@dataclass
class Estimate:
    """A run's expected cost: ``iterations`` left at ``seconds_per_iteration`` (``seconds``; without the final
    evaluation; the most: a run stops earlier when done or by its time budget), ``peak_gib`` (GiB),
    ``disk_bytes`` in the run directory and ``quantized_bytes`` added by ``inkopt quantize``;
    ``calibration_seconds`` (what measuring it cost); ``scaled``: the seconds per iteration were given (scaled from
    a coarse stage's), not measured."""

    iterations: int
    seconds_per_iteration: float
    seconds: float
    peak_gib: float
    disk_bytes: int
    quantized_bytes: int
    calibration_seconds: float
    scaled: bool = False

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> Estimate:
        return cls(**{k: d[k] for k in cls.__dataclass_fields__ if k in d})  # ``scaled``: absent before it was kept

    def line(self, time_budget: float | None = None) -> str:
        """The log line; with the run's ``time_budget`` (seconds) shorter than the estimate, it says so."""
        each = self.seconds_per_iteration
        each = f"{each:.2g}" if each < 10 else f"{each:.0f}"  # 2.2 s, 17 s, 237 s
        budget = ""
        if time_budget is not None and self.seconds > time_budget:
            budget = f"; the time budget ({format_duration(time_budget)}) ends the run sooner"
        return (
            f"estimate: up to {self.iterations} iterations x {each} s = "
            f"{format_duration(self.seconds)} (+ the final evaluation), peak memory ~{self.peak_gib:.1f} GiB, disk "
            f"~{_size(self.disk_bytes)} (+ {_size(self.quantized_bytes)} after inkopt quantize); "
            + ("scaled from the coarse stage's iterations" if self.scaled else "measured")
            + f" in {self.calibration_seconds:.1f} s{budget}"
        )


def _size(n: float) -> str:
    return f"{n / 1e9:.2f} GB" if n >= 1e8 else f"{n / 1e6:.1f} MB"


def _peak_gib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def _step_seconds(run, rows: int = 1 << 16) -> float:
    """The step's per-voxel work (dE/dsigma -> dE/dx and the optimiser's update) timed on up to ``rows`` free
    voxels with a throwaway optimiser, scaled to all of them (the smoothing of the step is not included)."""
    from .model import mix_grad
    from .optim.optimizers import make_optimizer

    f = len(run.x)
    n = min(f, rows)
    if n == 0:
        return 0.0
    zeros = np.zeros((n, 3), np.float32)
    opt = make_optimizer(run.cfg.optimizer, run.cfg.step_size, (n, run.x.shape[1]), run.threads)
    t = time.perf_counter()
    g_x = run.param.backward(run.x[:n], mix_grad(zeros, zeros, run.base.inks), natural=run.opt.natural, lo=0)
    opt.step(run.x[:n], g_x)
    return (time.perf_counter() - t) * f / n


def texel_passes_seconds(passes, n_tex: int) -> float:
    """Seconds of the passes over all ``n_tex`` texels, from ``passes(n)`` (the measured seconds of the passes over n
    texels, ``texel_runs``). A first pass is thrown away (its one-off set-up: thread pool, buffers built on first use);
    ``a`` is the smaller of two one-texel passes; ``b`` per texel comes from a subset grown from ``CALIBRATION_TEXELS``
    (by the slope so far, at least doubling, at most 16x a round) until its passes take ``MIN_TEXEL_SECONDS`` and
    ``FIXED_MULTIPLE`` x ``a`` more than one texel's. A stall only ever adds time: each size that passes that test is
    timed twice and the smaller time kept (module docstring)."""
    passes(1)
    fixed = min(passes(1), passes(1))
    enough = max(MIN_TEXEL_SECONDS, FIXED_MULTIPLE * fixed)
    n = min(n_tex, CALIBRATION_TEXELS)
    while True:
        t = passes(n)
        if n >= n_tex:  # every texel measured
            return t
        if t - fixed >= enough:
            t = min(t, passes(n))
            if t - fixed >= enough:
                return fixed + (t - fixed) / n * n_tex
        grown = t - fixed
        want = int(np.ceil(1.3 * enough * n / max(grown, 1e-3)))
        n = min(n_tex, max(2 * n, min(want, 16 * n)))


def texel_runs(n_tex: int, n: int, rng: np.random.Generator, runs: int = SAMPLE_RUNS) -> np.ndarray:
    """(n,) int64 sorted texel indices: ``runs`` runs of consecutive texels (fewer when n < 64 ``runs``: runs of at
    least 64), one at a random place in each of as many equal stretches of the texel order. Consecutive texels are
    neighbours on the surface, as in a full pass, where a path finds the media its neighbours' paths brought into
    the caches; texels drawn one by one from the whole surface find them cold and take longer (docs/experiments.md,
    "The run estimate's calibration")."""
    n = min(n, n_tex)
    runs = max(1, min(runs, n // 64))
    edges = np.linspace(0, n_tex, runs + 1).astype(np.int64)
    stretch = np.diff(edges)
    lengths = stretch * n // n_tex  # < stretch when n < n_tex: room for one more in each run
    lengths[: n - lengths.sum()] += 1
    starts = edges[:-1] + (rng.random(runs) * (edges[1:] - edges[:-1] - lengths + 1)).astype(np.int64)
    return np.concatenate([np.arange(s, s + m) for s, m in zip(starts, lengths)])


def estimate_run(
    run, inside_voxels: int, box_voxels: int, seed: int = 0, seconds_per_iteration: float | None = None, mesh=False
) -> Estimate:
    """The cost of the iterations ``run`` (an ``optim.Optimization``, at its current iteration) has left, measured
    on its own renderer (module docstring). ``inside_voxels``: the object's voxels; ``box_voxels``: its grid's;
    ``mesh``: a mesh's (what ``inkopt quantize`` writes follows its surface);
    ``seconds_per_iteration``: known already (e.g. scaled from a coarse stage's): taken, not measured (the renderer
    is built, for the peak memory)."""
    t0 = time.perf_counter()
    cfg, tex = run.cfg, run.texels
    n_tex = len(tex)
    rng = np.random.default_rng(seed)
    renderer = run.renderer()
    if seconds_per_iteration is not None:
        took = time.perf_counter() - t0
        return _estimate(run, (inside_voxels, box_voxels, mesh), float(seconds_per_iteration), took, True)

    def passes(n: int) -> float:  # seconds of a forward render and a gradient pass over n texels
        sub = tex.subset(texel_runs(n_tex, n, rng))
        adjoint = rng.standard_normal((n, run.loss.channels)).astype(np.float32)  # bands: spectral
        t = time.perf_counter()
        if cfg.forward_spp > 0:
            renderer.render(sub, cfg.forward_spp, seed, cfg.include_specular)
        renderer.gradient(
            sub, adjoint, cfg.spp, seed + 1, cfg.include_specular, cfg.grad_method, grad_index=run.param.free_index
        )
        return time.perf_counter() - t

    per_iteration = texel_passes_seconds(passes, n_tex) + _step_seconds(run)
    return _estimate(run, (inside_voxels, box_voxels, mesh), per_iteration, time.perf_counter() - t0, False)


def _estimate(run, counts: tuple, per_iteration: float, took: float, scaled: bool) -> Estimate:
    """The ``Estimate`` of ``run``'s iterations left at ``per_iteration`` seconds each, its peak memory from this
    process's so far, its disk from the counts (module docstring; ``counts``: inside and grid voxels, whether a
    mesh); ``took``: seconds spent finding ``per_iteration``."""
    (inside_voxels, box_voxels, mesh), cfg, n_tex = counts, run.cfg, len(run.texels)
    left = max(cfg.iterations - run.iteration, 0)
    n_inks = run.x.shape[1]
    disk = 4 * n_inks * inside_voxels + (12 * n_inks * len(run.x) + 24 * n_tex + 80 * cfg.iterations) + 40 * n_tex
    return Estimate(
        iterations=left,
        seconds_per_iteration=per_iteration,
        seconds=per_iteration * left,
        peak_gib=_peak_gib() + 64 * n_tex / 2**30,
        disk_bytes=int(disk),
        quantized_bytes=quantized_bytes(n_tex, box_voxels, mesh),
        calibration_seconds=took,
        scaled=scaled,
    )
