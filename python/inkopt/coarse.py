"""Jobs of more than one run and the plan of a deadline: coarse to fine (``run_coarse_to_fine``: a coarse run of the
object, its result moved onto the fine grid as the fine run's start), ``deadline_plan``, how a run with a time
budget and no coarse grid given goes (coarse to fine at half its DPI; a mesh from the extrusion baseline),
``fine_stage_seconds``, the fine stage's predicted fixed cost that the coarse stage leaves room for, and
``default_time_budget``, the deadline of a run given neither a time budget nor a number of iterations."""

from __future__ import annotations

import time
from dataclasses import replace

from .errors import ParameterError
from .evaluation.baselines import baseline_layers
from .evaluation.noise import PILOT_SPP
from .model import Volume
from .model.banded import BandMixture, band_mixture
from .optim import OptimizeConfig
from .optim.param import BASELINE_INITS
from .run import RunOptions, release_freed_memory, run_optimisation
from .rundir import RunDir
from .scenes import build_scene
from .units import voxel_mm

#: share of a time budget the coarse stage of a coarse-to-fine run may take; the fine stage has the rest, and more
#: when its fixed costs are predicted to need it (``fine_stage_seconds``), down to ``COARSE_MIN_SHARE``
COARSE_BUDGET_SHARE = 0.6
#: the least share of the budget the coarse stage keeps however expensive its fine stage is predicted to be: a job
#: whose fine stage needs more than the rest overruns its budget (the coarse stage's line says so)
COARSE_MIN_SHARE = 0.2
#: the fine stage's fixed costs (the fine grid's baseline and the transfer, scene set-up and estimate, start and
#: baseline figures, the one iteration a run always does, the result's figures and writing), predicted as
#: ``FINE_FIXED_SECONDS + FINE_SETUP_FACTOR * s``, s the coarse run's seconds outside its iterations (scene, start,
#: estimate, start's figures: the same kinds of work on a grid of 1/8 the voxels and 1/4 the texels). The least
#: upper bound over the seven 20 mm short-budget jobs of the mesh suite whose coarse stage kept 80 s + 5.5 s for them
#: (variant fixed-80, commit a1905bd: their fine stages from the coarse stage's end to the job's end, the iterations
#: after the first taken out, 39-160 s) is 47.26 s + 5.143 s (bench/results/mesh_suite_phases.json, ``fit``),
#: rounded up. Those fine stages stored their start compressed and timed their estimate: today's are cheaper
#: (``run_coarse_to_fine``), so the bound holds them with room (docs/quality.md, "The deadline's fine stage"). The
#: coarse run's seconds per iteration add nothing to the bound: the spider's fine stage takes 101 s at 1.0 s per
#: coarse iteration, the duck's 101 s at 4.6 s.
FINE_FIXED_SECONDS, FINE_SETUP_FACTOR = 48.0, 5.2
#: a coarse-to-fine job with a time budget does not time its fine stage's iterations before they start (the estimate's
#: calibration: 1.4-12.3 s on the mesh suite's 20 mm fine grids): it scales the coarse stage's measured seconds per
#: iteration by (fine DPI / coarse DPI) ** ``FINE_ITERATION_EXPONENT``. The geometric mean of the fine / coarse ratio
#: over the mesh suite's 14 short-budget cells at 10 and 20 mm (commits a1905bd, 03bf2f7, 5b85789: 4.26-8.03 at half
#: the DPI) is 5.51 = 2 ** 2.46; the scaled estimate is then within -31 % / +29 % of the fine stage's measured seconds
#: per iteration, the calibration's own within -22 % / +45 % on the same cells (the estimate's accuracy on a loaded
#: machine is ±40 %, docs/experiments.md). Other DPI ratios: not measured.
FINE_ITERATION_EXPONENT = 2.46
#: a run with a time budget goes coarse to fine by default, the coarse grid at this fraction of the run's DPI: at
#: equal budgets it ended lower than the plain run on the reference slab (3 min: 29.01 against 29.36 ΔE76) and on
#: Spot 20 mm (8 min: 9.99 against 15.36) (bench/results/time_to_quality.json)
DEADLINE_COARSE_FACTOR = 0.5


#: A mesh run with a time budget whose settings name no start goes coarse to fine from this print-shop baseline: the
#: coarse stage starts from it at half the DPI, and the fine stage from the baseline on its own grid plus the coarse
#: stage's change moved up (the correction transfer, ``optim.transfer``). On the mesh suite at 20 mm with the short
#: budget (5 minutes; bench/results/mesh_suite.json, variant ``c2f-correction``; printed - extrusion, paired, ΔE76 /
#: SSIM) it beats the extrusion baseline by more than 0.5 ΔE76 with no SSIM loss beyond the noise on the spider (-3.52 /
#: -0.001), the coin (-1.99 / +0.012), the box (-0.84 / +0.001), the eyeball (-1.32 / +0.001), the orange (-0.71 /
#: +0.009) and the checker (-1.51 / -0.004 ± 0.003), and misses the margin on the duck (-0.40 / -0.001); the plan before
#: (the extrusion start on the full grid for meshes at least 2 mm thick by volume / area, else coarse to fine from
#: white) missed the margin on the box (-0.40), the duck (-0.21) and the orange (-0.35) and lost SSIM on the spider
#: (-0.073) and the eyeball (-0.009). Where both plans meet the margin, coarse to fine from white leads by ~0.5 ΔE76
#: (the coin -2.49; Spot 20 mm -2.42 against -1.97, bench/results/spot20_deadline_start.json) but loses SSIM on Spot
#: (-0.011 against +0.003). Not measured under this plan: 10 mm, Spot 40 mm, the longer budgets (docs/quality.md, "The
#: correction transfer").
DEADLINE_MESH_START = "extrusion"

#: a run given neither a time budget nor iterations gets the time of this many of its iterations (at its full grid,
#: from white) as its deadline. Deadline jobs of about that size reached within 1 ΔE76 of 300 iterations: Spot
#: 20 mm in 7 min 45 s, 40 iterations of its 11.6 s (bench/results/job.json, spot20_budget7m45s_warm025, against
#: bench/results/mesh_20mm.json), Spot 40 mm in 27 min, 27.6 of its 58.8 s (bench/results/time_to_quality.json,
#: spot40/extrusion_budget27m, against mesh_40mm.json); from white at the full grid the same target takes ~60
#: iterations and the curve's knee (50 more iterations gain < 0.2 ΔE76) lies near 180 (spot40/reference there;
#: docs/performance.md, "A time plan by default")
PLAN_ITERATIONS = 40
#: the shortest such deadline: the reference slab's 3 minutes reached within 1 ΔE76 of its 450-iteration result
#: (time_to_quality.json, reference/c2f150_budget3m_warm025), where 40 of its 0.85-s iterations are less than its
#: set-up and figures
PLAN_MIN_SECONDS = 180.0
#: the longest such deadline, so that a job with the defaults goes from mesh to printer package within 3 hours
#: (quantize and export took 4 min 45 s at Spot 100 mm, whose 40 iterations' time is 9 h 43 min). Spot 100 mm in
#: 90 minutes, coarse to fine from the extrusion baseline, printed 0.91 ± 0.08 ΔE76 below the extrusion baseline and
#: 11.8 below the surface baseline (docs/performance.md, "Spot 100 mm from mesh to GCVF in 90 minutes"); what the
#: longer plans of objects this large gain is not measured. Objects up to about 60 mm (40 iterations within the
#: cap) keep their 40 iterations' time
PLAN_MAX_SECONDS = 2.75 * 3600.0


def default_time_budget(seconds_per_iteration: float) -> float:
    """The deadline (seconds) of a run given neither a time budget nor iterations, from its estimated
    ``seconds_per_iteration`` at its full grid from white: ``PLAN_ITERATIONS`` of them, at least
    ``PLAN_MIN_SECONDS`` and at most ``PLAN_MAX_SECONDS``."""
    if not (seconds_per_iteration >= 0 and seconds_per_iteration < float("inf")):
        raise ParameterError(f"`seconds_per_iteration` must be a finite time, got {seconds_per_iteration}")
    return min(max(PLAN_ITERATIONS * seconds_per_iteration, PLAN_MIN_SECONDS), PLAN_MAX_SECONDS)


def fine_stage_seconds(setup_s: float) -> float:
    """The predicted fixed cost (seconds, wall clock) of a coarse-to-fine job's fine stage, from the coarse run's
    ``setup_s`` seconds outside its iterations (``FINE_FIXED_SECONDS``, ``FINE_SETUP_FACTOR``)."""
    return FINE_FIXED_SECONDS + FINE_SETUP_FACTOR * max(setup_s, 0.0)


def fine_iteration_seconds(coarse_seconds: float, coarse_dpi: float, dpi: float) -> float:
    """The expected seconds of a fine-stage iteration at ``dpi`` from the coarse stage's ``coarse_seconds`` per
    iteration at ``coarse_dpi`` (``FINE_ITERATION_EXPONENT``)."""
    return coarse_seconds * (dpi / coarse_dpi) ** FINE_ITERATION_EXPONENT


def coarse_reserve(time_budget: float, setup_s: float) -> float:
    """Seconds the coarse run keeps from its time budget (``COARSE_BUDGET_SHARE`` of the job's ``time_budget``,
    seconds) for the fine stage beyond the rest of the job's budget: its iterations end by the earlier of the share
    and the budget less the fine stage's predicted cost (``fine_stage_seconds(setup_s)``), but no earlier than
    ``COARSE_MIN_SHARE`` of the budget."""
    beyond = fine_stage_seconds(setup_s) - (1.0 - COARSE_BUDGET_SHARE) * time_budget
    return min(max(beyond, 0.0), (COARSE_BUDGET_SHARE - COARSE_MIN_SHARE) * time_budget)


def deadline_plan(spec, cfg: OptimizeConfig, log=print) -> tuple[float, OptimizeConfig]:
    """How a run with a time budget and no ``--coarse-dpi`` goes: (coarse-stage DPI, 0 for none; the settings).
    A slab thinner than one voxel of the coarse grid has no coarse stage; every other run goes coarse to fine at
    ``DEADLINE_COARSE_FACTOR`` of its DPI, a mesh whose settings name no start (``cfg.init`` None) from
    ``DEADLINE_MESH_START`` (moved onto the fine grid by the correction transfer), every other run from its own
    start."""
    coarse_dpi = DEADLINE_COARSE_FACTOR * spec.dpi
    if spec.kind == "mesh" and cfg.init is None:
        log(
            f"deadline: coarse to fine from the {DEADLINE_MESH_START} baseline ({coarse_dpi:g} DPI, then "
            f"{spec.dpi:g} DPI from the baseline plus the coarse stage's change)"
        )
        return coarse_dpi, replace(cfg, init=DEADLINE_MESH_START)
    if spec.kind == "slab" and min(spec.size_mm) < voxel_mm(coarse_dpi):  # the coarse grid cannot hold it
        log(f"deadline: the slab is thinner than one voxel at {coarse_dpi:g} DPI: no coarse stage")
        return 0.0, cfg
    return coarse_dpi, cfg


def run_coarse_to_fine(spec, inks, out_dir, cfg: OptimizeConfig, coarse_dpi: float, options: RunOptions | None = None):
    """Coarse to fine: optimise ``spec``'s object first on a grid of ``coarse_dpi`` (a run of its own in
    ``OUT/coarse/`` with ``cfg``'s settings: it stops when done, or within ``COARSE_BUDGET_SHARE`` of
    ``cfg.time_budget`` less what the fine stage is predicted to need beyond the rest, ``coarse_reserve``), move its
    result onto the grid of ``spec`` (``optim.transfer.write_transferred_rows``: ``OUT/coarse/fine_start.npz``, the
    fine run's free voxels' rows, fixed shares kept; the coarse result and its baseline held by their bands, the
    fine baseline made at the free voxels only) and optimise from there (``cfg`` with that start, and a warm start's
    step unless ``cfg.lr`` is set; with a time budget its estimate is the coarse stage's seconds per iteration
    scaled, ``fine_iteration_seconds``, not timed again). A half-DPI grid has a quarter of the texels: on Spot 20 mm
    an iteration took 5.9 CPU s at 150 DPI (bench/results/mesh_20mm_150dpi.json) against 22 at 300 DPI with newer
    code (bench/results/mesh_20mm.json). ``options.resume`` continues whichever stage was under way; the time budget
    and the run's wall time count from the job's start (``options.started``); ``options.on_step`` is called in the
    fine stage only. Returns the fine run's report (``dry_run``: its estimate, from a white start; nothing is
    written)."""
    from .optim.transfer import Baseline, coarse_result, destination, write_transferred_rows

    options = options or RunOptions()
    if not 0 < coarse_dpi < spec.dpi:
        raise ParameterError(f"`coarse_dpi` must lie between 0 and the run's DPI ({spec.dpi:g}), got {coarse_dpi:g}")
    if options.started is None:
        options = replace(options, started=time.perf_counter())
    if options.dry_run:
        return run_optimisation(build_scene(spec, inks), out_dir, cfg, options)
    rd = RunDir.create(out_dir)
    with rd.lock(options.log):  # the whole job's, the fine run's taken again inside it
        coarse_dir, start = rd.path / "coarse", rd.path / "coarse" / "fine_start.npz"
        fine_begun = options.resume and rd.checkpoint_path.is_file() and start.is_file()
        coarse_start = per = None
        if not fine_begun:
            coarse_start, per = _coarse_stage(spec, inks, coarse_dir, cfg, coarse_dpi, options)
        if per is not None and cfg.time_budget is not None:  # the fine stage's estimate scaled, not timed again
            options = replace(options, seconds_per_iteration=fine_iteration_seconds(per, coarse_dpi, spec.dpi))
        fine = build_scene(spec, inks)
        if not fine_begun:
            t = time.perf_counter()
            baseline = layers = None
            param = destination(fine.volume, fine.fixed_share)  # the fine run's free voxels
            if coarse_start is not None:  # the correction transfer: the fine grid's baseline plus the change
                layers = baseline_layers(
                    cfg.init, fine.volume, fine.texels, fine.target_rgb, fine.fixed_share, only=param.free_index
                )
                baseline = Baseline(coarse_start, layers)
                options = replace(options, baselines={cfg.init: layers})  # the fine run's guard takes it as made
            source = coarse_result(RunDir(coarse_dir).volume_file())
            write_transferred_rows(source, fine.volume, param, start, baseline=baseline)
            del baseline, coarse_start, source, param, layers  # the layers: the fine run's, released after its guard
            t = time.perf_counter() - t
            how = "" if cfg.init not in BASELINE_INITS else f" as a change of the {cfg.init} baseline"
            options.log(f"coarse result moved onto the {spec.dpi:g}-DPI grid{how} in {t:.0f} s: {start}")
            release_freed_memory()  # the fine stage's peak is the job's: nothing of the stages before it under it
        return run_optimisation(fine, out_dir, replace(cfg, init=str(start)), options)


def _coarse_stage(spec, inks, coarse_dir, cfg: OptimizeConfig, coarse_dpi: float, options: RunOptions):
    """The coarse run of ``run_coarse_to_fine`` in ``coarse_dir``: ``spec`` at ``coarse_dpi``, within
    ``COARSE_BUDGET_SHARE`` of the time budget less what the fine stage is predicted to need beyond the rest
    (``coarse_reserve``); its figures are one pilot pass (informative: the fine stage's are the run's, its baseline
    guard too); the caller's per-step hook sees the fine stage only (another grid here). The coarse result is not
    smoothed at its end (``finish_smooth`` 0): it is the fine stage's start, not an answer, and a pass on the coarse
    grid blurs twice as far as the fine result's own (docs/quality.md, "The duck's margin"). Returns (the coarse run's
    start on the coarse grid, held by its band (``baseline_by_band``), when ``cfg.init`` is a print-shop baseline
    (``optim.param.BASELINE_INITS``: the correction transfer's B_c, made once for the coarse run's start and the
    transfer), else None; the coarse run's seconds per iteration, None when it ran none)."""
    coarse = build_scene(replace(spec, dpi=coarse_dpi), inks)
    budget, log, kept = None, options.log, {}
    after = None
    if cfg.time_budget is not None:
        budget = COARSE_BUDGET_SHARE * cfg.time_budget

        def after(setup_s: float) -> float:  # the fine stage's predicted cost beyond the rest of the budget
            kept.update(setup=setup_s, reserve=coarse_reserve(cfg.time_budget, setup_s))
            return kept["reserve"]

    log(f"coarse stage at {coarse_dpi:g} DPI into {coarse_dir}")
    layers = start = None
    if cfg.init in BASELINE_INITS:  # the coarse grid's baseline: the coarse run's start (before its clip at 1e-6)
        layers = baseline_layers(cfg.init, coarse.volume, coarse.texels, coarse.target_rgb, coarse.fixed_share)
    coarse_options = replace(
        options,
        on_step=None,
        eval_spp=options.eval_spp or PILOT_SPP,
        log=lambda m: log(f"  {m}"),
        baseline_guard=False,
        baselines=None if layers is None else {cfg.init: layers},
        after=after,
    )
    report = run_optimisation(coarse, coarse_dir, replace(cfg, time_budget=budget, finish_smooth=0), coarse_options)
    if kept:
        predicted = fine_stage_seconds(kept["setup"])
        log(
            f"fine stage predicted to need {predicted:.0f} s (the coarse stage's set-up {kept['setup']:.0f} s): the "
            f"coarse stage kept {kept['reserve']:.0f} s of its share for it"
            + (" (at its least share: the job may overrun its budget)" if predicted > _most_fine(cfg) else "")
        )
    if layers is not None:
        start = baseline_by_band(coarse.volume, layers)
    del coarse, layers
    release_freed_memory()
    return start, (report.seconds_per_iteration if report.seconds_iterations > 0 else None)


def baseline_by_band(volume: Volume, layers) -> BandMixture | Volume:
    """The coarse stage's baseline ``layers`` (``BaselineLayers`` on the grid of ``volume``, the coarse scene's) as
    the correction transfer's B_c: held by its band (``model.banded``; the band's core where the scene has one,
    e.g. the white core its fixed shares give the baseline too) when the volume has an inside mask, else whole
    (a ``Volume``)."""
    if volume.inside is None:  # a slab without a mask: small enough to hold whole
        return volume.with_mixture(layers.array())
    return band_mixture(volume, layers, None if volume.band is None else volume.band.core)


def _most_fine(cfg: OptimizeConfig) -> float:
    """The most seconds the fine stage can have of ``cfg.time_budget`` (the coarse stage at its least share)."""
    return (1.0 - COARSE_MIN_SHARE) * cfg.time_budget
