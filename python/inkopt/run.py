"""The run driver: one optimisation run of any scene, from start (or resume) to report (docs/run-dir.md).

``run_optimisation(scene, out_dir, cfg)``: a fresh run (not a resume) first removes every output of an earlier run in
``out_dir`` (``RunDir.remove_earlier_run``); write scene.npz, estimate the cost (``inkopt.estimate``), measure the
start's figures once (kept in the checkpoints, so a resume does not render the start again), optimise with
checkpoints (``resume`` continues exactly), save volume.npz (and remove the outputs derived from an earlier one), then
the result's figures. Figures are renders with seeds from ``2**62 + cfg.seed`` (never used by the optimisation) at
``eval_spp`` samples per texel if given, else adaptively (``evaluation.noise.adaptive_render``: enough that the Monte
Carlo noise adds at most ~0.5 to the mean ΔE76 and SSIM's and the mottle's noise correction is accurate, at most
``eval_max_spp`` (4096) and within ``eval_time_budget``, or within ``FINAL_FIGURES_SHARE`` of the run's time when
neither that nor a run time budget is given; the start's figures are one pilot pass), compared with the target by
``evaluation.metrics.prediction_metrics``; then the scene's pictures, loss.png and report.json
(``evaluation.results.Report``). The scene comes from user inputs through a spec (``scenes.spec``:
``SlabSpec(...).build(inks)``, ``MeshSpec(...).build(inks)``).
"""

from __future__ import annotations

import ctypes
import gc
import resource
import time
from pathlib import Path

import numpy as np

from .distributed import renderer_factory
from .estimate import ANNOUNCE_SECONDS, Estimate, estimate_run
from .evaluation.baselines import baseline_layers
from .evaluation.metrics import delta_e76_map, prediction_metrics
from .evaluation.noise import EVAL_SEED_OFFSET, MAX_SPP, PILOT_SPP, Sampling, adaptive_render
from .evaluation.results import Report
from .io import file_digest
from .lighting import Lighting, load_lighting
from .optim import EXTRUSION_START_MM, Optimization, OptimizeConfig
from .pictures import loss_figure
from .rundir import Predictions, RunDir
from .scenes import Scene

#: Shares of a run's time budget (``OptimizeConfig.time_budget``) given to the start's figures, the result's
#: figures, and kept for writing the result (volume, pictures, predictions, report): the iterations get the rest,
#: the step decay planned to end in time (``optim.stopping``). Not measured optima: the figures are informative
#: and noise-corrected at any spp (their noise is reported), the quality is the iterations'.
BUDGET_START_FIGURES, BUDGET_FINAL_FIGURES, BUDGET_WRITING = 0.03, 0.08, 0.04
#: Without a budget, the result's figures add samples beyond the pilot only while they take at most this share of
#: the run's time so far: on a mesh the noise-free figures of a run cost as much as its iterations (Spot 20 mm:
#: ~550 spp, ~6 min, twice). The noise left is corrected for and reported; `inkopt evaluate` measures the
#: printed result against the baselines without noise.
FINAL_FIGURES_SHARE = 0.25


def figure_budgets(cfg: OptimizeConfig, eval_time_budget: float | None) -> tuple:
    """(start's, result's) time budget of the adaptive figures in seconds, or None: the user's
    ``eval_time_budget``, within the shares of the run's time budget if it has one."""
    if cfg.time_budget is None:
        return eval_time_budget, eval_time_budget
    cap = float("inf") if eval_time_budget is None else eval_time_budget
    return min(cap, BUDGET_START_FIGURES * cfg.time_budget), min(cap, BUDGET_FINAL_FIGURES * cfg.time_budget)


def peak_rss_gb() -> float:
    """Peak resident memory of this process so far, GiB (Linux reports ru_maxrss in KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def release_freed_memory() -> None:
    """Give the memory freed so far back to the operating system where the C library can (glibc's
    ``malloc_trim``; elsewhere nothing): a finished stage's many small blocks, freed in many threads' heaps,
    otherwise stay in the process under the next stage's peak (a 40 mm coarse stage and transfer left ~0.6 GiB,
    docs/performance.md)."""
    gc.collect()
    try:
        trim = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError, TypeError):  # not glibc (macOS, Windows, musl builds without it)
        return
    trim(0)


def run_optimisation(
    scene: Scene,
    out_dir,
    cfg: OptimizeConfig,
    *,
    resume: bool = False,
    eval_spp: int | None = None,
    threads: int | None = None,
    progress: bool = False,
    lighting: Lighting | str | None = None,
    ray: str | None = None,
    log=print,
    log_every_s: float = 30.0,
    dry_run: bool = False,
    eval_max_spp: int = MAX_SPP,
    eval_time_budget: float | None = None,
    started: float | None = None,
    on_step=None,
) -> Report | Estimate:
    """Optimise ``scene`` into run directory ``out_dir`` under the display ``lighting`` (default uniform; the
    final figures are rendered under it too); returns the report (also report.json). ``ray``: "auto" or a Ray
    cluster's address: every render is split into texel shards on Ray workers (``inkopt.distributed``; the
    results are bit-identical), ``threads`` then being each worker's. Without ``progress`` (no terminal), ``log``
    gets a progress line at least every ``log_every_s`` seconds of the iterations. Before the iterations the run's
    cost is estimated (``inkopt.estimate``) and logged when it exceeds ``estimate.ANNOUNCE_SECONDS``; with
    ``dry_run`` only the estimate is made and returned, and nothing is written. ``eval_max_spp`` and
    ``eval_time_budget`` (seconds) cap each adaptive figure's samples. ``started``: when the job began
    (``time.perf_counter()``, e.g. before the scene was built; default: now), the time ``cfg.time_budget`` and the
    run's wall time count from. ``on_step(optimization)``: called after every iteration (``Optimization.run``)."""
    with renderer_factory(ray, threads) as make_renderer:
        return _optimise(
            scene,
            out_dir,
            cfg,
            resume,
            eval_spp,
            threads,
            progress,
            load_lighting(lighting),
            log,
            make_renderer,
            log_every_s,
            dry_run,
            eval_max_spp,
            eval_time_budget,
            started,
            on_step,
        )


def _optimise(
    scene,
    out_dir,
    cfg,
    resume,
    eval_spp,
    threads,
    progress,
    lighting,
    log,
    make_renderer,
    log_every_s,
    dry_run,
    eval_max_spp,
    eval_time_budget,
    started,
    on_step,
) -> Report | Estimate:
    t_start = time.perf_counter() if started is None else started
    log(scene.describe())
    for note in scene.warnings:  # e.g. a mesh's small holes
        log(f"warning: {note}")

    def baseline(kind: str):  # a print-shop start (cfg.init "surface" or "extrusion"), one z layer at a time
        return baseline_layers(kind, scene.volume, scene.texels, scene.target_rgb, scene.fixed_share, progress=progress)

    run = Optimization(
        scene.volume,
        scene.texels,
        scene.target_rgb,
        cfg,
        fixed_share=scene.fixed_share,
        threads=threads,
        baseline=baseline,
        lighting=lighting,
        renderer_factory=make_renderer,
        kind=scene.kind,
    )
    shape = scene.volume.shape
    box = int(np.prod(shape))
    inside = box if scene.volume.inside is None else int(scene.volume.inside.sum())
    if dry_run:  # read the checkpoint a resume would continue from, write nothing
        checkpoint = RunDir(out_dir).checkpoint_path if Path(out_dir).is_dir() else None
        if resume and checkpoint is not None and checkpoint.is_file():
            run.load_checkpoint(checkpoint)
        return estimate_run(run, inside, box, cfg.seed)
    rd = RunDir.create(out_dir)
    if not (resume and run.resume(rd.checkpoint_path, log)):
        gone = rd.remove_earlier_run()  # a fresh run: nothing of an earlier run may pair with the new result
        if gone:
            log(f"removed the outputs of an earlier run in {rd}: {', '.join(gone)}")
    rd.save_scene(scene.record())
    estimate = estimate_run(run, inside, box, cfg.seed)
    if estimate.seconds > ANNOUNCE_SECONDS:
        log(estimate.line(cfg.time_budget))
    run.invocation_start = t_start  # the whole run's time counts this invocation's set-up too

    # Figures with seeds unused by the optimisation, adaptive spp unless given (at most ``eval_max_spp`` and
    # ``eval_time_budget`` seconds per result). The run's own renderer, set to a mixture (only the free voxels
    # change: no grid-sized volume), renders exactly what a renderer built from that volume would.
    spp = int(eval_spp) if eval_spp else None  # None: adaptive
    seed = EVAL_SEED_OFFSET + cfg.seed

    start_budget, final_budget = figure_budgets(cfg, eval_time_budget)

    def figures_of(x=None, budget=final_budget, max_spp=eval_max_spp, pilot_in_budget=True, keep_renderer=True):
        renderer = run.renderer(x)

        def render(n: int, s: int):
            r = renderer.render(scene.texels, n, s, cfg.include_specular, progress)
            return r.rgb, r.var_mean, n

        res = adaptive_render(
            render,
            run.loss.target_lab,
            Sampling(seed=seed, spp=spp, max_spp=max_spp, time_budget=budget, pilot_in_budget=pilot_in_budget),
            log=log,
        )
        if not keep_renderer:  # its media are not needed beside the loss's window operators that the figures build
            del renderer
            run.release_renderer()
        return res, prediction_metrics(run.loss, res.rgb, res.var)

    def final_figures():
        """The result's figures: the user's samples or budget, the run's budget share, or (neither) samples up to
        ``FINAL_FIGURES_SHARE`` of the run's time so far after a whole pilot."""
        if spp is not None or final_budget is not None:
            return figures_of(keep_renderer=False)
        return figures_of(budget=FINAL_FIGURES_SHARE * run.wall_seconds(), pilot_in_budget=False, keep_renderer=False)

    def keep_start(res0, init) -> None:
        run.start_figures = {
            "delta_e76_mean": init.delta_e76_mean,
            "ssim": init.ssim,
            "delta_e76_mean_corrected": init.delta_e76_mean_corrected,
            "eval_spp": res0.spp,
        }

    if run.start_figures is None and run.iteration == 0:  # measured once, before the first step, and then kept in
        # the start's figures: one pilot (noise-corrected; `inkopt evaluate` measures the baselines noise-free)
        keep_start(*figures_of(budget=start_budget, max_spp=min(eval_max_spp, PILOT_SPP)))
    reserve = 0.0 if cfg.time_budget is None else (final_budget or 0.0) + BUDGET_WRITING * cfg.time_budget
    run.run(rd.checkpoint_path, progress=progress, log=log, log_every_s=log_every_s, reserve=reserve, on_step=on_step)
    run.release_renderer()  # not beside the writing of the result, nor beside the finishing smoothing
    run.finish()  # the result: the last iterate smoothed (cfg.finish_smooth); the checkpoint keeps the iterate
    rd.save_volume_slabs(run.base, run.mixture_slabs(), run.base.inks)  # a slab of layers at a time
    gone = rd.remove_stale()  # quantized volume, slices, evaluation made from an earlier volume.npz
    if gone:
        log(f"removed outputs made from the earlier volume.npz: {', '.join(gone)}")

    res, metrics = final_figures()
    if run.start_figures is None:  # a checkpoint written before the start's figures were kept in it
        start_x = run.initial_variables()
        keep_start(*figures_of(start_x, start_budget, min(eval_max_spp, PILOT_SPP), keep_renderer=False))
    start = run.start_figures
    de = delta_e76_map(run.loss, res.rgb)
    scene.write_pictures(rd, res.rgb, de)
    rd.save_predictions(
        Predictions(
            {"continuous": res.rgb},
            "optimisation",
            {"continuous": res.spp},
            file_digest(rd.volume_path),
            lighting.describe(),
        )
    )
    loss_figure(rd.loss_picture_path, run.history.loss, run.history.delta_e76)
    h = run.history
    n = max(len(h.seconds), 1)
    report = Report(
        metrics=metrics,
        initial_delta_e76_mean=start["delta_e76_mean"],
        initial_ssim=start["ssim"],
        initial_delta_e76_mean_corrected=start["delta_e76_mean_corrected"],
        delta_e76_max=float(de.max()),
        iterations=run.iteration,
        spp=cfg.spp,
        eval_spp=res.spp,
        spp_adaptive=spp is None,
        eval_spp_passes=res.passes,
        initial_eval_spp=start["eval_spp"],
        # this invocation's wall time (set-up, the iterations it ran, the evaluation); a resumed run's earlier
        # iterations are in the history, so seconds_iterations covers all of them
        seconds=time.perf_counter() - t_start,
        seconds_total=run.wall_seconds(),
        estimate=estimate.to_json(),
        stop=run.schedule.describe(run.cfg),
        seconds_iterations=float(np.sum(h.seconds)),
        seconds_per_iteration=float(np.sum(h.seconds) / n),
        time_split={k: float(np.sum(getattr(h, k)) / n) for k in ("render_s", "gradient_s", "loss_s", "step_s")},
        scene=scene.report_fields(),
        inks=list(scene.volume.inks.names),
        gamma=list(cfg.gamma),
        lr=run.cfg.step_size,
        optimizer=cfg.optimizer,
        param=cfg.param,
        init=run.cfg.init,
        seed=cfg.seed,
        decay=cfg.decay,
        smooth=run.cfg.smooth,
        finish_smooth=run.cfg.finish_smooth,
        adjoint_ema=run.cfg.adjoint_ema,
        gradient=cfg.grad_method,
        threads=threads,
        peak_rss_gb=peak_rss_gb(),
        lighting=lighting.describe(),
    )
    rd.write_report(report.to_json())
    return report


#: share of a time budget the coarse stage of a coarse-to-fine run may take; the fine stage has the rest
COARSE_BUDGET_SHARE = 0.6
#: a run with a time budget goes coarse to fine by default, the coarse grid at this fraction of the run's DPI: at
#: equal budgets it ended lower than the plain run on the reference slab (3 min: 29.01 against 29.36 ΔE76) and on
#: Spot 20 mm (8 min: 9.99 against 15.36) (bench/results/time_to_quality.json)
DEADLINE_COARSE_FACTOR = 0.5


def deadline_plan(spec, cfg: OptimizeConfig, log=print) -> tuple[float, OptimizeConfig]:
    """How a run with a time budget and no ``--coarse-dpi`` goes: (coarse-stage DPI, 0 for none; the settings).
    A mesh at least ``EXTRUSION_START_MM`` thick whose settings name no start (``cfg.init`` None) starts from the
    extrusion baseline at its own DPI; every other run goes coarse to fine at ``DEADLINE_COARSE_FACTOR`` of its
    DPI with its own start."""
    from dataclasses import replace

    if spec.kind == "mesh" and cfg.init is None:
        thick = spec.mean_thickness_mm()
        if thick >= EXTRUSION_START_MM:
            log(
                f"deadline: the mesh is {thick:.2f} mm thick (volume / area, at least {EXTRUSION_START_MM:g}): "
                f"starting from the extrusion baseline at {spec.dpi:g} DPI, no coarse stage"
            )
            return 0.0, replace(cfg, init="extrusion")
    return DEADLINE_COARSE_FACTOR * spec.dpi, cfg


def run_coarse_to_fine(spec, inks, out_dir, cfg: OptimizeConfig, coarse_dpi: float, *, resume=False, log=print, **kw):
    """Coarse to fine: optimise ``spec``'s object first on a grid of ``coarse_dpi`` (a run of its own in
    ``OUT/coarse/`` with ``cfg``'s settings: it stops when done, or within ``COARSE_BUDGET_SHARE`` of
    ``cfg.time_budget``), move its result onto the grid of ``spec`` (``optim.transfer.write_transferred_volume``:
    ``OUT/coarse/fine_start.npz``, fixed shares kept) and optimise from there (``cfg`` with that start, and a warm
    start's step unless ``cfg.lr`` is set). A half-DPI iteration costs about a sixth of a full one on Spot
    (docs/performance.md). ``resume`` continues whichever stage was under way; the time budget and the run's wall
    time count from the job's start (``kw["started"]``). ``kw``: ``run_optimisation``'s other arguments
    (``on_step`` is called in the fine stage only). Returns the
    fine run's report (``--dry-run``: its estimate, from a white start; nothing is written)."""
    from dataclasses import replace

    from .optim.transfer import write_transferred_volume

    if not 0 < coarse_dpi < spec.dpi:
        raise ValueError(f"--coarse-dpi must lie between 0 and the run's DPI ({spec.dpi:g}), got {coarse_dpi:g}")
    kw.setdefault("started", time.perf_counter())
    if kw.get("dry_run"):
        return run_optimisation(spec.build(inks), out_dir, cfg, resume=resume, log=log, **kw)
    rd = RunDir.create(out_dir)
    coarse_dir, start = rd.path / "coarse", rd.path / "coarse" / "fine_start.npz"
    fine_begun = resume and rd.checkpoint_path.is_file() and start.is_file()
    if not fine_begun:
        coarse = replace(spec, dpi=coarse_dpi).build(inks)
        budget = None if cfg.time_budget is None else COARSE_BUDGET_SHARE * cfg.time_budget
        log(f"coarse stage at {coarse_dpi:g} DPI into {coarse_dir}")
        # the caller's per-step hook sees the fine stage only (another grid here); the coarse result's figures are
        # one pilot pass (informative: the fine stage's are the run's)
        ckw = {**kw, "on_step": None, "eval_spp": kw.get("eval_spp") or PILOT_SPP}
        run_optimisation(
            coarse, coarse_dir, replace(cfg, time_budget=budget), resume=resume, log=lambda m: log(f"  {m}"), **ckw
        )
        del coarse
        release_freed_memory()
    fine = spec.build(inks)
    if not fine_begun:
        t = time.perf_counter()
        write_transferred_volume(RunDir(coarse_dir).load_volume(), fine.volume, fine.fixed_share, start)
        log(f"coarse result moved onto the {spec.dpi:g}-DPI grid in {time.perf_counter() - t:.0f} s: {start}")
        release_freed_memory()  # the fine stage's peak is the job's: nothing of the stages before it under it
    return run_optimisation(fine, out_dir, replace(cfg, init=str(start)), resume=resume, log=log, **kw)
