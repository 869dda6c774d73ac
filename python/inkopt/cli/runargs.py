"""The options of an optimisation run (``slab``, ``optimize`` and, without a single run's own, ``select-inks``) and
the typed bundles built from them in one place: the scene's spec (``scenes.spec``), the optimiser's settings
(``optim.OptimizeConfig``) and how the run is carried out (``run.RunOptions``)."""

from __future__ import annotations

import sys

from .common import (
    add_inks_arg,
    add_lighting_args,
    add_ray_arg,
    add_seed_arg,
    add_threads_arg,
    add_translucency_args,
    lighting_from_args,
    ray_from_args,
    stderr_log,
)
from .jobplan import plan_job
from .lights import add_light_args, under_lights, viewing_from_args


def parse_gamma(text: str) -> tuple[float, float, float]:
    """'g1,g2,g3' -> the loss weights; a one-line error unless three non-negative numbers with a positive sum."""
    from ..errors import ParameterError

    try:
        g = tuple(float(v) for v in text.split(","))
    except ValueError:
        g = ()
    if len(g) != 3 or min(g) < 0 or sum(g) <= 0:
        raise ParameterError(f"`gamma` must be three non-negative weights g1,g2,g3 with a positive sum, got '{text}'")
    return g


def finish_passes(text: str) -> int:
    """``--finish-smooth``'s value: a number of passes, or "auto" (``optim.config.FINISH_AUTO``)."""
    import argparse

    from ..optim.config import FINISH_AUTO

    if text.strip().lower() == "auto":
        return FINISH_AUTO
    if not text.strip().isdigit():
        raise argparse.ArgumentTypeError(f"a number of passes (0..8) or auto, got '{text}'")
    return int(text)


def add_run_args(p, translucency: str) -> None:
    """Everything ``slab`` and ``optimize`` share after their scene's own options: the run directory, the
    translucency options (``translucency``: "slab" or "mesh"), the ink set, the optimiser's options, a single run's
    options and ``--ray``."""
    p.add_argument("--out", required=True, metavar="DIR", help="run directory (see docs/run-dir.md)")
    add_translucency_args(p, mesh=translucency == "mesh")
    add_inks_arg(p)
    add_optimizer_args(p)
    add_single_run_args(p)
    add_light_args(p)
    add_ray_arg(p)


def add_optimizer_args(p) -> None:
    """The optimiser's options (``OptimizeConfig``), the final figures' samples, threads, resume and the display
    lighting: shared by ``slab``, ``optimize`` and ``select-inks``."""
    from ..optim import OptimizeConfig

    d = OptimizeConfig()
    p.add_argument(
        "--iterations",
        type=int,
        help=f"the most iterations; the run stops earlier when done (--stop-gain). Default {d.iterations} with "
        "--time-budget; with neither, slab and optimize plan their time: the time of 40 iterations at the run's "
        "estimated cost, at least 3 minutes (docs/performance.md, 'A time plan by default')",
    )
    _add_sampling_args(p, d)
    _add_step_args(p, d)
    _add_smoothing_args(p, d)
    add_seed_arg(p, "seed of every random number of the run (renders, gradients, a random start)")
    p.add_argument("--checkpoint-every", type=int, default=d.checkpoint_every)
    add_threads_arg(p)
    p.add_argument("--resume", action="store_true", help="continue from DIR/checkpoint.npz if present")
    add_lighting_args(p, "optimise and evaluate")


def _add_sampling_args(p, d) -> None:
    p.add_argument("--spp", type=int, default=d.spp, help=f"samples per texel of the gradient pass (default {d.spp})")
    p.add_argument(
        "--forward-spp",
        type=int,
        default=d.forward_spp,
        help="samples per texel of the forward render the loss is evaluated at "
        f"(default {d.forward_spp}; 0: no forward renders after the first iteration, the loss is "
        "taken on the average of the gradient passes' own estimates: cheaper iterations, each worth "
        "less)",
    )
    p.add_argument(
        "--eval-spp",
        type=int,
        help="spp of the final evaluation renders, used exactly (default: "
        "adaptive, until the Monte Carlo noise adds less than 0.5 to the mean ΔE76 and SSIM's and "
        "the mottle's noise correction is accurate)",
    )
    p.add_argument(
        "--gradient",
        choices=("replay", "li1"),
        default=d.grad_method,
        help="unbiased path replay (default) or the paper's biased L_i = 1 approximation",
    )


def _add_step_args(p, d) -> None:
    from ..optim import SCENE_DEFAULTS
    from ..optim.config import WARM_LR_FACTOR

    slab, mesh = SCENE_DEFAULTS["slab"], SCENE_DEFAULTS["mesh"]
    p.add_argument(
        "--gamma",
        default=",".join(f"{g:g}" for g in d.gamma),
        help="loss weights g1,g2,g3 of colour (dE76^2), SSIM and edge terms (default %(default)s)",
    )
    p.add_argument(
        "--colour-term",
        choices=["squared", "linear"],
        help="the colour term: squared, the mean dE76^2, or linear, the mean dE76 that the figures report "
        f"(default: {slab['colour_term']} on slabs, {mesh['colour_term']} on meshes; docs/quality.md)",
    )
    p.add_argument(
        "--lr",
        type=float,
        help="step size (default: 2 for eg, 0.5 for adagrad, 0.1 for adam; from a warm start (--init) and in a "
        f"coarse-to-fine run's fine stage {WARM_LR_FACTOR:g} of that)",
    )
    p.add_argument(
        "--decay",
        type=float,
        default=d.decay,
        metavar="FRACTION",
        help="step decay: over this last fraction of the iterations the step size halves three times, so "
        f"that the mixtures settle (default {d.decay:g}; 0: a constant step)",
    )
    p.add_argument(
        "--optimizer",
        choices=("eg", "adam", "adagrad"),
        default=d.optimizer,
        help="eg: exponentiated gradient with momentum (default); adagrad: the paper's; adam",
    )
    p.add_argument(
        "--param",
        choices=("softmax", "sigmoid"),
        default=d.param,
        help="variables -> mixture map (sigmoid = the paper's sigmoid + normalisation)",
    )
    p.add_argument(
        "--init",
        help="white (97 %% white), random, surface or extrusion (start from that print-shop baseline of "
        "`inkopt evaluate`; builds or reuses its cached colour table), or a volume .npz (default: "
        f"{slab['init']} on slabs, {mesh['init']} on meshes; with --time-budget, a mesh goes coarse to fine from "
        "extrusion). A start other than white or random takes "
        f"{WARM_LR_FACTOR:g} of the default step (--lr)",
    )


def _add_smoothing_args(p, d) -> None:
    from ..optim import SCENE_DEFAULTS

    slab, mesh = SCENE_DEFAULTS["slab"], SCENE_DEFAULTS["mesh"]
    p.add_argument(
        "--smooth",
        type=float,
        metavar="VOXELS",
        help="width in voxels of the step's spatial smoothing under texels where the target is flat: "
        f"damps voxel-to-voxel mottle (default {slab['smooth']:g} on slabs, {mesh['smooth']:g} on "
        "meshes; 0: off)",
    )
    p.add_argument(
        "--finish-smooth",
        type=finish_passes,
        metavar="PASSES|auto",
        help="passes of that smoothing over the result after the last iteration, against the voxel-scale "
        f"variation the iterations leave; auto: one pass, kept unless the run's paired render of the result with "
        f"and without it says it raises the loss beyond the noise (default {slab['finish_smooth']} on slabs, "
        f"{mesh['finish_smooth']} on meshes; 0: off)",
    )
    p.add_argument(
        "--smooth-edge",
        type=float,
        default=d.smooth_edge,
        metavar="DE76",
        help="target-colour difference at which the smoothing between two voxels fades to 1/e, so that "
        f"it stops at the target's edges (default {d.smooth_edge:g}; 0: smooth everywhere, across "
        "edges too)",
    )
    p.add_argument(
        "--adjoint-ema",
        type=float,
        metavar="DECAY",
        help="per-iteration decay of the running average of the prediction the loss is evaluated at "
        f"(default: {slab['adjoint_ema']:g} on slabs, {mesh['adjoint_ema']:g} on meshes, where a "
        "longer average lags enough to make the run oscillate; 0: this iteration's render only)",
    )


def add_single_run_args(p) -> None:
    """A single run's options (not select-inks' many runs): when it stops, coarse to fine, its time budget, its
    figures' budget, the dry run and the progress lines."""
    from ..evaluation.noise import MAX_SPP
    from ..optim import OptimizeConfig

    d = OptimizeConfig()
    p.add_argument(
        "--stop-gain",
        type=float,
        default=d.stop_gain,
        metavar="DE76",
        help="stop when done: once the training ΔE76 is not expected to fall by more than this over the next "
        f"{d.stop_horizon} iterations, the step decay begins and the run ends after it (default "
        f"{d.stop_gain:g}; 0: run all --iterations)",
    )
    p.add_argument(
        "--coarse-dpi",
        type=float,
        metavar="DPI",
        help="coarse to fine: optimise first on a grid of this resolution (e.g. 150: an eighth of the voxels), "
        "then at --dpi from its result (the coarse run is kept in DIR/coarse/; default: half of --dpi with "
        "--time-budget unless a thick mesh starts from the extrusion baseline (--init), else off; 0: off)",
    )
    p.add_argument(
        "--time-budget",
        metavar="DURATION",
        help="finish the whole run (set-up, iterations, its figures) within this time, e.g. 30m, 1h30m, "
        "1800: the step decay is placed so that the run ends by then (default: none)",
    )
    p.add_argument(
        "--eval-max-spp",
        type=int,
        default=MAX_SPP,
        metavar="N",
        help=f"cap of the adaptive final evaluation's samples per texel (default {MAX_SPP})",
    )
    p.add_argument(
        "--eval-time-budget",
        type=float,
        metavar="SECONDS",
        help="time budget of each adaptive final figure (the result's, the start's): it stops adding samples when "
        "the time measured per sample says more would not fit (default: none)",
    )
    p.add_argument(
        "--figure-texel-sample",
        type=int,
        metavar="N",
        help="the start's, the extrusion baseline's and the result's figures from a random sample of N texels (and "
        "100 SSIM windows; the pictures still show every texel); 0: every texel (default: a sample where a short "
        "pilot predicts it at least twice as fast, then as many samples per texel as every texel's pass would have "
        "taken the time for)",
    )
    p.add_argument(
        "--dry-run",
        action="store_true",
        help="print only the run's estimated time, peak memory and disk and write nothing: a mesh's from its "
        "size (the mesh is loaded, not voxelized), a slab's from a short calibration of its scene",
    )
    p.add_argument(
        "--memory-gb",
        type=float,
        metavar="GIB",
        help="the memory the job may use: a job estimated to need more is refused before anything large is "
        "built (default: $INKOPT_MEMORY_GB, else 80%% of the available memory)",
    )
    p.add_argument(
        "--log-every",
        type=float,
        default=30.0,
        metavar="SECONDS",
        help="when stderr is not a terminal (a log file, a scheduler): a progress line (iteration, loss, ΔE76, "
        "ETA) at least this often (default 30)",
    )


#: the ``OptimizeConfig`` fields whose option has the field's name (``--forward-spp`` -> ``forward_spp``)
CONFIG_OPTIONS = (
    "iterations",
    "spp",
    "forward_spp",
    "lr",
    "optimizer",
    "param",
    "init",
    "seed",
    "checkpoint_every",
    "smooth",
    "finish_smooth",
    "smooth_edge",
    "decay",
    "adjoint_ema",
    "colour_term",
)


def config_from_args(args):
    """The ``OptimizeConfig`` of the parsed options (checked)."""
    from ..optim import OptimizeConfig
    from ..units import parse_duration

    given = {name: getattr(args, name) for name in CONFIG_OPTIONS}
    if given["iterations"] is None:  # the default maximum (a single run without --time-budget plans its time)
        given["iterations"] = OptimizeConfig().iterations
    cfg = OptimizeConfig(
        **given,
        gamma=parse_gamma(args.gamma),
        grad_method=args.gradient,
        # select-inks compares its candidates at equal iterations: no stopping when done there
        stop_gain=getattr(args, "stop_gain", 0.0),
        time_budget=parse_duration(args.time_budget) if getattr(args, "time_budget", None) else None,
    )
    cfg.validate()
    return cfg


def run_options_from_args(args, started: float, table=None):
    """The ``run.RunOptions`` of ``slab``'s and ``optimize``'s parsed options (checked; Ray's presence too);
    ``table``: the spectral ink table of ``--inks`` (None: an RGB table)."""
    from ..run import RunOptions

    options = RunOptions(
        resume=args.resume,
        eval_spp=args.eval_spp,
        eval_max_spp=args.eval_max_spp,
        eval_time_budget=args.eval_time_budget,
        figure_texel_sample=args.figure_texel_sample,
        threads=args.threads,
        progress=sys.stderr.isatty(),
        lighting=lighting_from_args(args),
        viewing=viewing_from_args(args, table),
        ray=ray_from_args(args),
        log=stderr_log,
        log_every_s=args.log_every,
        dry_run=args.dry_run,
        started=started,
    )
    options.validate()
    return options


def slab_spec_from_args(args, top: str):
    """The ``SlabSpec`` of ``top`` and the slab options (``--size-mm``, ``--bottom``, ``--dpi``, translucency)."""
    from ..scenes.spec import SlabSpec
    from ..units import parse_size_mm

    return SlabSpec(
        top,
        parse_size_mm(args.size_mm),
        bottom=args.bottom,
        dpi=args.dpi,
        translucency=args.translucency,
        translucency_depth_mm=args.translucency_depth_mm,
    )


def mesh_spec_from_args(args, path: str):
    """The ``MeshSpec`` of ``path`` and the mesh options, each named as the spec's field (``--height-mm`` or
    ``--scale``, ``--shell-mm``, ``--dpi``, ``--up``, translucency, ``--texture``, ``--constant-color``);
    ``--shell-mm 0``: every voxel free (no shell)."""
    from dataclasses import fields

    from ..scenes.spec import MeshSpec

    given = {f.name: getattr(args, f.name) for f in fields(MeshSpec) if f.name not in ("path", "shell_chosen")}
    if given["shell_mm"] == 0:
        given["shell_mm"] = None
    return MeshSpec(path, **given)


def run_from_args(args, spec):
    """``slab`` and ``optimize``: check ``spec`` (before the ink set and the optimiser settings are read) and that
    its job fits the memory (``footprint``: a mesh is loaded, not voxelized; a mesh given no ``--shell-mm`` takes a
    band when every voxel free does not fit, ``footprint.fits.choose_shell``), plan its time when neither
    ``--time-budget`` nor ``--iterations`` is given (the first log line says so), build its scene with ``--inks``
    and optimise it into ``--out``. Returns (the run's ``Report``, or with ``--dry-run`` an estimate with a
    ``line(time_budget)``, nothing written; the run's time budget in seconds or None)."""
    import time

    from ..coarse import deadline_plan, run_coarse_to_fine
    from ..run import run_optimisation
    from ..scenes import build_scene
    from ..spectral.inks import run_inks

    started = time.perf_counter()  # a time budget counts the scene's building (voxelization) too
    spec.validate()
    inks, table = run_inks(args.inks)  # the scene's RGB table; a spectral one renders the run's bands
    options = run_options_from_args(args, started, table)
    spec, cfg, options, dry = plan_job(args, spec, inks, config_from_args(args), options)
    if dry is not None:
        return dry, cfg.time_budget
    coarse_dpi = args.coarse_dpi
    if coarse_dpi is None and cfg.time_budget is not None:
        coarse_dpi, cfg = deadline_plan(spec, cfg, log=options.log)
    if coarse_dpi:
        return run_coarse_to_fine(spec, inks, args.out, cfg, coarse_dpi, options), cfg.time_budget
    return run_optimisation(build_scene(spec, inks), args.out, cfg, options), cfg.time_budget


def run_command(args, spec, outputs: str, show_memory: bool = False) -> int:
    """Run ``spec`` as ``slab`` and ``optimize`` do and print the closing lines: the summary and where its
    ``outputs`` are (``--dry-run``: the estimate's line only)."""
    rep, time_budget = run_from_args(args, spec)
    if args.dry_run:
        print(rep.line(time_budget))
        if getattr(rep, "refusal", None) is not None:  # the job would be refused: the one-line error, status 2
            raise rep.refusal
        return 0
    print_run_summary(rep, rep.init, f" (peak memory {rep.peak_rss_gb:.1f} GiB)" if show_memory else "")
    print(f"{outputs}; report: {args.out}/report.json")
    return 0


def print_run_summary(rep, init: str, extra: str = "") -> None:
    """The closing line of ``slab`` and ``optimize`` from their ``Report``, with the result against the baseline
    the run measured (``evaluation.guard``; its noise-corrected mean ΔE76) when it measured one."""
    m = rep.metrics
    total = rep.seconds_total or rep.seconds
    whole = f" (whole run across resumes {total:.0f} s)" if total > rep.seconds + 1e-3 else ""  # resumed
    against = ""
    for kind, b in (rep.baseline or {}).items():  # one kind: the guard's
        diff, tol = b["difference_delta_e76"], b["tolerance_delta_e76"]
        verdict = "better" if diff < -tol else "within the noise" if rep.beats_baseline else f"WORSE: try --init {kind}"
        against = (
            f"; corrected ΔE76 {m.delta_e76_mean_corrected:.2f} ± {b['result_delta_e76_error']:.2f} against the {kind} "
            f"baseline's {b['delta_e76_mean_corrected']:.2f} ± {b['delta_e76_error']:.2f}: {verdict}"
        )
    start, result = ((t or {}).get("sample") for t in (rep.initial_texel_sample, rep.texel_sample))
    on = f", {start['texels']} sampled texels" if start and not result else ""
    both = "" if not result else f"; {'both ' if start == result else ''}on {result['texels']} sampled texels"
    print(
        f"mean ΔE76 {rep.initial_delta_e76_mean:.2f} ({init} start{on}) -> {m.delta_e76_mean:.2f} "
        f"(p95 {m.delta_e76_p95:.2f}, ΔE2000 {m.delta_e2000_mean:.2f}, SSIM {m.ssim:.3f}{both}) "
        f"after {rep.iterations} iterations{stopped(rep)} in {rep.seconds:.0f} s{whole}{extra}{against}"
    )
    if rep.viewing is not None:  # a spectral run: the figures above are under its first light
        print(under_lights(rep.viewing))


def stopped(rep) -> str:
    """ " (converged)" or " (time budget)" when the run ended before its maximum, else ""."""
    reason = (rep.stop or {}).get("reason")
    return f" ({reason})" if reason in ("converged", "time budget") else ""
