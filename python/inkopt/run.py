"""The run driver: one optimisation run of any scene, from start (or resume) to report (docs/run-dir.md).

``run_optimisation(scene, out_dir, cfg, options)``: the settings ``cfg`` (``OptimizeConfig``) are resolved once for the
scene's kind; ``options`` (``RunOptions``) say how the run is carried out. A fresh run (not a resume) first removes
every output of an earlier run in ``out_dir`` (``RunDir.remove_earlier_run``); write scene.npz, estimate the cost
(``inkopt.estimate``), measure the start's figures and the extrusion baseline's once (kept in the checkpoints, so a
resume does not render them again), optimise with checkpoints (``options.resume`` continues exactly), choose the
result's finishing smoothing (``finish_smooth`` auto: where the run's paired render says it lowers the loss,
``evaluation.finish``), save volume.npz (and remove the outputs derived from an earlier one), then the result's figures
(``runfigures.RunFigures``; their first pass the finishing choice's render), checked against the baseline's
(``evaluation.guard``: a warning if worse beyond their noise). Figures: renders with seeds from ``2**62 + cfg.seed``
(never used by the optimisation) at ``options.eval_spp`` samples per texel if given, else adaptively
(``evaluation.noise.adaptive_render``: enough that the Monte Carlo noise adds at most ~0.5 to the mean ΔE76 and SSIM's
and the mottle's noise correction is accurate, at most ``eval_max_spp`` (4096) and within ``eval_time_budget``, or
within ``runfigures.FINAL_FIGURES_SHARE`` of the run's time when neither that nor a run time budget is given; the
start's and the baseline's figures are one pilot pass each), compared with the target by
``evaluation.metrics.prediction_metrics``, on every texel or on a texel sample (``runfigures``: a large object's,
and then every texel is rendered for the pictures within the time the sample leaves); then the scene's pictures,
loss.png and report.json
(``evaluation.results.Report``). The scene comes from user inputs through a spec (``scenes.spec``:
``scenes.build_scene(SlabSpec(...), inks)``, ``scenes.build_scene(MeshSpec(...), inks)``).
"""

from __future__ import annotations

import gc
import resource
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from . import heap
from .distributed import renderer_factory
from .errors import ParameterError
from .estimate import ANNOUNCE_SECONDS, Estimate, estimate_run
from .evaluation.baselines import baseline_layers
from .evaluation.finish import FinishChoice
from .evaluation.guard import BaselineCheck, check_baseline, keep_baseline_figures
from .evaluation.lights import light_figures
from .evaluation.metrics import delta_e76_map
from .evaluation.noise import MAX_SPP
from .evaluation.results import Report
from .evaluation.spectral import bands_of
from .io import file_digest
from .lighting import Lighting, load_lighting
from .model.spectral import write_spectral_ink_file
from .optim import Optimization, OptimizeConfig
from .optim.config import FINISH_AUTO
from .pictures import loss_figure
from .rundir import Predictions, RunDir
from .runfigures import BUDGET_WRITING, RunFigures
from .scenes import Scene
from .spectral.viewing import Viewing


def peak_rss_gb() -> float:
    """Peak resident memory of this process so far, GiB (Linux reports ru_maxrss in KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def release_freed_memory() -> None:
    """Give the memory freed so far back to the operating system where the C library can (glibc's
    ``malloc_trim``; elsewhere nothing): a finished stage's many small blocks, freed in many threads' heaps,
    otherwise stay in the process under the next stage's peak (a 40 mm coarse-to-fine job cut to 1 + 1 iterations
    peaked at 4.07 GiB without it, 3.72 GiB with it: bench/results/c2f_memory.json, entries ``spot40_c2f_after`` and
    ``spot40_c2f_after_trim``)."""
    gc.collect()
    heap.trim()


@dataclass(frozen=True)
class RunOptions:
    """How one run is carried out (what it optimises is ``OptimizeConfig``'s).

    ``resume``: continue from the run directory's checkpoint if there is one. ``eval_spp``: samples per texel of
    the figures, used exactly (None: adaptive, at most ``eval_max_spp`` and ``eval_time_budget`` seconds per
    figure). ``threads``: the renderer's (with ``ray``, each worker's). ``progress``: a progress bar (a terminal);
    without it ``log`` gets a progress line at least every ``log_every_s`` seconds of the iterations. ``lighting``:
    the display lighting (``inkopt.lighting``; default uniform), the final figures are rendered under it too.
    ``viewing``: spectral or RGB and the lights (``spectral.viewing.Viewing``; default the RGB path). A spectral
    run's headline figures are under its first light, report.json's ``viewing`` holds them under each light, its
    pictures and predictions.npz show it under the first light as sRGB (``Viewing.display``).
    ``ray``: "auto" or a Ray cluster's address: every render is split into texel shards on Ray workers
    (``inkopt.distributed``; bit-identical results). ``dry_run``: only estimate the run (nothing is written).
    ``started``: when the job began (``time.perf_counter()``, e.g. before the scene was built; default: when the
    run starts), the time ``cfg.time_budget`` and the run's wall time count from. ``on_step(optimization)``:
    called after every iteration (``Optimization.run``). ``baseline_guard``: measure the extrusion baseline's
    figures at the start and check the result against them (``evaluation.guard``). ``baselines``: print-shop
    baselines' mixtures already made for this scene (kind -> ``evaluation.baselines.baseline_layers``'s layers,
    e.g. by a coarse-to-fine transfer from a baseline), taken by the run's start and its guard instead of being made
    again, then released: the run empties a dict given before its iterations (the spider of the mesh suite at 20 mm: its
    fine stage ran 9 iterations in a 5-minute job instead of 6, docs/quality.md, "The correction transfer").
    ``after(setup_s)``: seconds the job needs after this run, from the run's seconds outside its iterations so far
    (its set-up); the run's time budget keeps them besides its own figures and writing (a coarse stage's: its fine
    stage's predicted cost, ``coarse.fine_stage_seconds``). ``seconds_per_iteration``: known before the run starts
    (a coarse-to-fine job's fine stage with a time budget: the coarse stage's, scaled,
    ``coarse.fine_iteration_seconds``): the run's estimate takes it instead of timing passes on its renderer
    (``estimate.estimate_run``). ``figure_texel_sample``: the start's, the baselines' and the result's figures of every
    texel (0) or of a texel sample of that many texels (None: a sample where a pilot predicts it twice as fast,
    ``runfigures``)."""

    resume: bool = False
    eval_spp: int | None = None
    eval_max_spp: int = MAX_SPP
    eval_time_budget: float | None = None
    threads: int | None = None
    progress: bool = False
    lighting: Lighting | str | None = None
    viewing: Viewing | None = None
    ray: str | None = None
    log: Callable[[str], None] = print
    log_every_s: float = 30.0
    dry_run: bool = False
    started: float | None = None
    on_step: Callable | None = None
    baseline_guard: bool = True
    baselines: dict | None = None
    after: Callable[[float], float] | None = None
    seconds_per_iteration: float | None = None
    figure_texel_sample: int | None = None

    def validate(self) -> None:
        """One-line errors naming the option, before any work."""
        if self.eval_spp is not None and self.eval_spp < 1:
            raise ParameterError(
                f"`eval_spp` must be at least 1 (leave it out for adaptive samples), got {self.eval_spp}"
            )
        if self.eval_max_spp < 1:
            raise ParameterError(f"`eval_max_spp` must be at least 1, got {self.eval_max_spp}")
        if self.eval_time_budget is not None and not self.eval_time_budget > 0:
            raise ParameterError(
                f"`eval_time_budget` must be a positive number of seconds, got {self.eval_time_budget}"
            )
        if not self.log_every_s >= 0:
            raise ParameterError(f"`log_every_s` must be a number of seconds >= 0, got {self.log_every_s}")
        per = self.seconds_per_iteration
        if per is not None and not 0 < per < float("inf"):
            raise ParameterError(f"`seconds_per_iteration` must be a positive number of seconds, got {per}")
        n = self.figure_texel_sample
        if n is not None and (n < 0 or n == 1):
            raise ParameterError(f"`figure_texel_sample` must be 0 (every texel) or at least 2 texels, got {n}")


@dataclass
class _Job:
    """One invocation of a run: the scene, its settings resolved for the scene's kind, the options, the display
    lighting, the optimisation and (unless a dry run) its run directory."""

    scene: Scene
    cfg: OptimizeConfig
    options: RunOptions
    lighting: Lighting
    run: Optimization
    rd: RunDir | None = None


def run_optimisation(scene: Scene, out_dir, cfg: OptimizeConfig, options: RunOptions = RunOptions()):
    """Optimise ``scene`` into run directory ``out_dir`` with settings ``cfg`` (resolved here for the scene's
    kind, once) as ``options`` say; returns the ``Report`` (also report.json), or with ``options.dry_run`` the
    ``Estimate`` (nothing written). Before the iterations the run's cost is estimated (``inkopt.estimate``) and
    logged when it exceeds ``estimate.ANNOUNCE_SECONDS``."""
    options.validate()
    cfg = cfg.for_scene(scene.kind)
    if options.started is None:
        options = replace(options, started=time.perf_counter())
    folder = RunDir.locked(out_dir, options.log, write=not options.dry_run)  # one job at a time writes into it
    with folder, renderer_factory(options.ray, options.threads) as make_renderer:
        job = _start(scene, cfg, options, make_renderer)
        if options.dry_run:
            return _dry_run(job, out_dir)
        estimate = _prepare(job, out_dir)
        figures = RunFigures(job)
        if job.run.start_figures is None and job.run.iteration == 0:
            # measured once, before the first step, then kept in the checkpoints: one pilot (noise-corrected;
            # `inkopt evaluate` measures the baselines noise-free)
            job.run.keep_start_figures(figures.start())
        if options.baseline_guard:  # the extrusion baseline's figures, measured once like the start's
            keep_baseline_figures(job.run, lambda x: figures.start(x, keep_renderer=True), options.log)
        if isinstance(options.baselines, dict):  # read by the start and the guard alone: not held further
            options.baselines.clear()
        job.run.release_unread_operators()  # the figures' window is not held through the first render
        release_freed_memory()  # nor the heap the figures freed: a step's large arrays are mapped, not taken from it
        finish = _iterate(job, figures)
        result = figures.final()
        if job.run.start_figures is None:  # a checkpoint written before the start's figures were kept in it
            job.run.keep_start_figures(figures.start(job.run.initial_variables()))
        check = check_baseline(job.run, result.metrics, options.log, result.error)  # warns when worse than it
        de = _write_result_files(job, result.pictures)
        report = _report(job, result, de, estimate, check, finish)
        job.rd.write_report(report.to_json())
        return report


def _start(scene: Scene, cfg: OptimizeConfig, options: RunOptions, make_renderer) -> _Job:
    """Log the scene and its warnings and set up its optimisation."""
    log = options.log
    log(scene.describe())
    if options.viewing is not None and options.viewing.spectral:
        d = options.viewing.describe()
        log(
            f"spectral: {d['bands']} bands, seen under {', '.join(d['illuminants'])} (loss: {d['combine']}); the "
            f"figures are under {d['illuminants'][0]}, report.json's viewing.by_light under each light"
        )
    for note in scene.warnings:  # e.g. a mesh's small holes
        log(f"warning: {note}")
    lighting = load_lighting(options.lighting)

    free = []  # the run's free voxels once its set-up has made them: the guard's baseline is read there alone

    def baseline(kind: str):  # a print-shop start (cfg.init "surface" or "extrusion"), one z layer at a time
        if options.baselines and kind in options.baselines:  # made already, for this scene
            return options.baselines[kind]
        only = free[0] if free else None  # a band's baseline for the band alone (4 B a voxel, not per inside voxel)
        return baseline_layers(
            kind, scene.volume, scene.texels, scene.target_rgb, scene.fixed_share, progress=options.progress, only=only
        )

    run = Optimization(
        scene,
        cfg,
        threads=options.threads,
        baseline=baseline,
        lighting=lighting,
        renderer_factory=make_renderer,
        viewing=options.viewing,
        started=options.started,  # the whole run's time counts this invocation's set-up too
    )
    free.append(run.param.free_index)
    return _Job(scene, cfg, options, lighting, run)


def _voxel_counts(job: _Job) -> tuple[int, int]:
    """(inside voxels, grid voxels) of the scene's volume."""
    vol = job.scene.volume
    box = int(np.prod(vol.shape))
    return (box if vol.inside is None else vol.inside.count), box


def _is_mesh(job: _Job) -> bool:
    """Whether the scene is a mesh's (its volume has shading normals)."""
    return job.scene.volume.normals is not None


def _dry_run(job: _Job, out_dir) -> Estimate:
    """The estimate of the iterations a run would do, from the checkpoint a resume would continue from; writes
    nothing."""
    checkpoint = RunDir(out_dir).checkpoint_path if Path(out_dir).is_dir() else None
    if job.options.resume and checkpoint is not None and checkpoint.is_file():
        job.run.load_checkpoint(checkpoint)
    return estimate_run(job.run, *_voxel_counts(job), job.cfg.seed, mesh=_is_mesh(job))


def _prepare(job: _Job, out_dir) -> Estimate:
    """The run directory: resumed from its checkpoint, or cleared of an earlier run's outputs; scene.npz written;
    the run's cost estimated (and logged when long)."""
    log, run = job.options.log, job.run
    job.rd = rd = RunDir.create(out_dir)
    if not (job.options.resume and run.resume(rd.checkpoint_path, log)):
        gone = rd.remove_earlier_run()  # a fresh run: nothing of an earlier run may pair with the new result
        if gone:
            log(f"removed the outputs of an earlier run in {rd}: {', '.join(gone)}")
    rd.save_scene(job.scene.record())
    estimate = estimate_run(run, *_voxel_counts(job), job.cfg.seed, job.options.seconds_per_iteration, _is_mesh(job))
    if estimate.seconds > ANNOUNCE_SECONDS:
        log(estimate.line(job.cfg.time_budget))
    return estimate


def _iterate(job: _Job, figures: RunFigures) -> FinishChoice | None:
    """The iterations (checkpointed), the result's finishing smoothing (``finish_smooth`` auto: where the run's paired
    render says it lowers the loss, ``RunFigures.choose_finish``) and volume.npz; outputs made from an earlier
    volume.npz are removed. A time budget keeps the result's figures' seconds (``RunFigures.final_reserve``), the
    finishing choice's (``RunFigures.choice_reserve``), the writing's share and ``options.after``'s seconds for
    after the iterations. Returns the finishing choice (None: ``cfg.finish_smooth`` passes, as set)."""
    run, opts, cfg, rd = job.run, job.options, job.cfg, job.rd
    auto = cfg.finish_smooth == FINISH_AUTO
    own = 0.0 if cfg.time_budget is None else (figures.final_reserve() or 0.0) + BUDGET_WRITING * cfg.time_budget

    def reserve(setup_s: float) -> float:  # read only with a time budget
        later = 0.0 if opts.after is None else opts.after(setup_s)  # a later stage's seconds
        return own + later + (figures.choice_reserve() if auto else 0.0)

    run.run(
        rd.checkpoint_path,
        progress=opts.progress,
        log=opts.log,
        log_every_s=opts.log_every_s,
        reserve=reserve,
        on_step=opts.on_step,
    )
    if run.viewing.plan is not None and run.history.seconds:  # a spectral run's band plan and its pilot's cost
        opts.log(run.viewing.plan.line(float(np.median(run.history.seconds))))
    choice = figures.choose_finish() if auto else None  # with the run's renderer, as a step smooths beside it
    if choice is not None:
        opts.log(choice.line())
    run.release_renderer()  # not beside the writing of the result, nor beside a set number of smoothing passes
    if not auto:
        run.finish()  # the result: the last iterate smoothed (cfg.finish_smooth); the checkpoint keeps the iterate
    rd.save_volume_slabs(run.base, run.mixture_slabs(), run.base.inks)  # a slab of layers at a time
    gone = rd.remove_stale()  # quantized volume, slices, evaluation made from an earlier volume.npz
    if gone:
        opts.log(f"removed outputs made from the earlier volume.npz: {', '.join(gone)}")
    return choice


def _write_result_files(job: _Job, res) -> np.ndarray:
    """The scene's pictures, predictions.npz and loss.png of the result's render ``res``; returns its per-texel
    ΔE76 (I,)."""
    run, rd = job.run, job.rd
    de = delta_e76_map(run.loss, res.rgb)
    shown = run.viewing.display(res.rgb)  # a spectral run: sRGB of the first light's colour (the RGB path: as is)
    job.scene.write_pictures(rd, shown, de)
    predictions = Predictions(
        {"continuous": shown},
        "optimisation",
        {"continuous": res.spp},
        file_digest(rd.volume_path),
        job.lighting.describe(),
        bands_of(run.viewing, res.rgb),
    )
    rd.save_predictions(predictions)
    if run.viewing.spectral:  # what `inkopt evaluate` renders the run's bands with
        write_spectral_ink_file(rd.spectral_inks_path, run.viewing.table)
    loss_figure(rd.loss_picture_path, run.history.loss, run.history.delta_e76)
    return de


def _report(job: _Job, result, de, estimate: Estimate, check: BaselineCheck | None, finish=None) -> Report:
    """report.json's contents: the result's figures (``runfigures.ResultFigures``; per-texel ΔE76 ``de`` of its
    pictures' render), the
    start's, the baseline's (``check``; None: not measured), the finishing choice (``finish``, a ``FinishChoice``;
    None: ``cfg.finish_smooth`` passes as set), the run's times and settings."""
    run, cfg, start = job.run, job.cfg, job.run.start_figures
    res, metrics = result.render, result.metrics
    h = run.history
    n = max(len(h.seconds), 1)
    return Report(
        metrics=metrics,
        initial_delta_e76_mean=start["delta_e76_mean"],
        initial_ssim=start["ssim"],
        initial_delta_e76_mean_corrected=start["delta_e76_mean_corrected"],
        delta_e76_max=float(de.max()),
        iterations=run.iteration,
        spp=cfg.spp,
        eval_spp=res.spp,
        spp_adaptive=job.options.eval_spp is None,
        eval_spp_passes=res.passes,
        initial_eval_spp=start["eval_spp"],
        initial_texel_sample=start.get("texel_sample"),
        texel_sample=result.sample,
        pictures_spp=result.pictures.spp,
        # this invocation's wall time (set-up, the iterations it ran, the evaluation); a resumed run's earlier
        # iterations are in the history, so seconds_iterations covers all of them
        seconds=time.perf_counter() - job.options.started,
        seconds_total=run.wall_seconds(),
        estimate=estimate.to_json(),
        stop=run.schedule.describe(cfg),
        seconds_iterations=float(np.sum(h.seconds)),
        seconds_per_iteration=float(np.sum(h.seconds) / n),
        time_split={k: float(np.sum(getattr(h, k)) / n) for k in ("render_s", "gradient_s", "loss_s", "step_s")},
        scene=job.scene.report_fields(),
        inks=list(job.scene.volume.inks.names),
        gamma=list(cfg.gamma),
        colour_term=cfg.colour_term,
        lr=cfg.step_size,
        **{k: getattr(cfg, k) for k in ("optimizer", "param", "init", "seed", "decay", "smooth")},
        finish_smooth=cfg.finish_smooth if finish is None else finish.passes,  # the passes in the result
        finish=None if finish is None else finish.to_json(),
        adjoint_ema=cfg.adjoint_ema,
        gradient=cfg.grad_method,
        threads=job.options.threads,
        peak_rss_gb=peak_rss_gb(),
        lighting=job.lighting.describe(),
        baseline=None if check is None else check.to_json(),
        beats_baseline=None if check is None else check.beats,
        viewing=_lights_report(run, result),
    )


def _lights_report(run: Optimization, result) -> dict | None:
    """report.json's ``viewing`` of a spectral run (None on the RGB path): ``Viewing.describe()``, the headline
    light, and the result's figures under each light (``ResultFigures``: on the texel sample with their standard
    errors where the result took one, else ``evaluation.lights.light_figures`` of every texel's render)."""
    if not run.viewing.spectral:
        return None
    names = tuple(light.name for light in run.viewing.seen_under())
    res = result.pictures
    figures = result.by_light or light_figures(run.loss, res.rgb, res.var, names)
    return {**run.viewing.describe(), "headline": names[0], **figures}
