"""What the subcommands share: the usage error, the display-lighting options, the optimiser options of ``slab``
and ``optimize``, the scene specs of their inputs (``scenes.spec``) and their one-line summaries."""

from __future__ import annotations

import sys


class UsageError(ValueError):
    """A problem with the user's input; reported as one line, exit status 2."""


#: Library parameters whose flag is not ``--`` + the name with dashes (``inkopt.errors.ParameterError``).
FLAGS: dict[str, str] = {}


def flag_of(name: str) -> str:
    """The command line's flag of a library parameter (``eval_spp`` -> ``--eval-spp``)."""
    return FLAGS.get(name) or "--" + name.replace("_", "-")


def stderr_log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def parse_gamma(text: str) -> tuple[float, float, float]:
    try:
        g = tuple(float(v) for v in text.split(","))
    except ValueError:
        g = ()
    if len(g) != 3 or min(g) < 0 or sum(g) <= 0:
        raise ValueError(f"--gamma must be three non-negative weights g1,g2,g3 with a positive sum, got '{text}'")
    return g


def add_lighting_args(p, what: str = "render") -> None:
    """``--lighting uniform|FILE`` and ``--lighting-rotate DEG`` (``inkopt.lighting``)."""
    p.add_argument(
        "--lighting",
        default="uniform",
        metavar="uniform|FILE",
        help=f"display lighting to {what} under: uniform (radiance 1 from every direction, the default) "
        "or an equirectangular environment map of linear radiance (.hdr, .exr, or .npy (H, 2H, 3)); "
        "row 0 looks up (+z), column 0 starts at +x, longitude grows towards +y",
    )
    p.add_argument(
        "--lighting-rotate",
        type=float,
        default=0.0,
        metavar="DEG",
        help="turn the map about z by DEG degrees, from +x towards +y (default 0)",
    )


def add_mesh_args(p, what: str = "") -> None:
    """The inputs of a mesh scene (``scenes.spec.MeshSpec``): ``--height-mm`` or ``--scale``, ``--up``,
    ``--shell-mm`` and ``--dpi``; ``what`` prefixes their help (e.g. "mesh: ")."""
    from ..scenes.mesh import UP_AXES
    from ..units import OPT_DPI

    p.add_argument("--height-mm", type=float, metavar="H", help=f"{what}scale the object to this height (mm)")
    p.add_argument("--scale", type=float, metavar="S", help=f"{what}or scale it by S mm per model unit")
    p.add_argument("--up", choices=UP_AXES, default="y", help=f"{what}the file's up axis (default y, as OBJ/glTF)")
    p.add_argument(
        "--shell-mm",
        type=float,
        metavar="D",
        help=f"{what}optimise only voxels less than D mm below the surface; deeper ones are printed white "
        "(default: every voxel of the object is optimised)",
    )
    p.add_argument("--dpi", type=float, default=OPT_DPI, help=f"optimisation grid resolution (default {OPT_DPI:g})")
    p.add_argument(
        "--texture",
        metavar="FILE",
        help=f"{what}the texture image, looked up through the mesh's uv coordinates (replaces the one its "
        "material names; for an OBJ without or with a broken MTL file)",
    )
    p.add_argument(
        "--constant-color",
        action="store_true",
        help=f"{what}accept a mesh without texture, vertex or face colours: the target is its material's "
        "colour (white without one); without this flag such a mesh is refused",
    )


def add_translucency_args(p, mesh: bool = False, both: bool = False) -> None:
    """``--translucency`` and ``--translucency-depth-mm`` (``inkopt.scenes.translucency``) of a slab, a mesh or
    (``both``) either."""
    if both:
        p.add_argument(
            "--translucency",
            metavar="MASK|alpha",
            help="translucent regions: a grey mask image (slab: of the picture's size; mesh: in texture "
            "space; grey level 0..1 = required share of transparent ink) or, for a mesh, 'alpha' "
            "(share = 1 - the texture's alpha); needs a transparent ink in --always",
        )
    elif mesh:
        p.add_argument(
            "--translucency",
            metavar="alpha|MASK",
            help="translucent regions: 'alpha' (share of transparent ink = 1 - the texture's alpha) or a "
            "grey mask image in texture space (grey level 0..1 = share); needs a transparent ink",
        )
    else:
        p.add_argument(
            "--translucency",
            metavar="MASK",
            help="translucent regions: a grey mask image of the top picture's size (grey level 0..1 = "
            "required share of transparent ink under that pixel); needs a transparent ink "
            "(e.g. --inks vero-cmykwt)",
        )
    p.add_argument(
        "--translucency-depth-mm",
        type=float,
        metavar="D",
        help="how deep below the surface the translucent regions reach (default: through the whole "
        + ("object)" if mesh or both else "slab)"),
    )


def check_budget(max_spp, time_budget, spp_flag: str = "--max-spp", time_flag: str = "--time-budget") -> None:
    """One-line ValueErrors for a sample cap below 1 or a time budget that is not positive."""
    if max_spp is not None and max_spp < 1:
        raise ValueError(f"{spp_flag} must be at least 1, got {max_spp}")
    if time_budget is not None and not (time_budget > 0):
        raise ValueError(f"{time_flag} must be a positive number of seconds, got {time_budget}")


def lighting_from_args(args):
    from ..lighting import load_lighting

    return load_lighting(args.lighting, args.lighting_rotate)


def add_optimizer_args(p, single_run: bool = True) -> None:
    """Options shared by `inkopt slab` and `inkopt optimize` (``single_run``) and, without the options of a single
    run's evaluation budget, estimate and progress lines, `inkopt select-inks`."""
    from ..evaluation.noise import MAX_SPP
    from ..optim import EXTRUSION_START_MM, SCENE_DEFAULTS, OptimizeConfig
    from ..optim.config import WARM_LR_FACTOR

    d, slab, mesh = OptimizeConfig(), SCENE_DEFAULTS["slab"], SCENE_DEFAULTS["mesh"]
    p.add_argument(
        "--inks",
        default="vero-cmykw",
        help="ink set: a preset (vero-cmykw, vero-cmykw+orange, vero-cmykwt), a comma list of ink names, "
        "or a JSON/TOML file of inks (default vero-cmykw)",
    )
    p.add_argument(
        "--iterations",
        type=int,
        default=d.iterations,
        help=f"the most iterations (default {d.iterations}); the run stops earlier when done (--stop-gain)",
    )
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
        "--gamma",
        default=",".join(f"{g:g}" for g in d.gamma),
        help="loss weights g1,g2,g3 of colour (dE76^2), SSIM and edge terms (default %(default)s)",
    )
    p.add_argument(
        "--lr",
        type=float,
        help="step size (default: 2 for eg, 0.5 for adagrad, 0.1 for adam; from a warm start (--init) and in a "
        f"coarse-to-fine run's fine stage {WARM_LR_FACTOR:g} of that)",
    )
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
        type=int,
        metavar="PASSES",
        help="passes of that smoothing over the result after the last iteration, against the voxel-scale "
        f"variation the iterations leave (default {slab['finish_smooth']} on slabs, {mesh['finish_smooth']} on "
        "meshes; 0: off)",
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
        f"{slab['init']} on slabs, {mesh['init']} on meshes; with --time-budget, extrusion on meshes at least "
        f"{EXTRUSION_START_MM:g} mm thick (volume / area)). A start other than white or random takes "
        f"{WARM_LR_FACTOR:g} of the default step (--lr)",
    )
    p.add_argument(
        "--gradient",
        choices=("replay", "li1"),
        default=d.grad_method,
        help="unbiased path replay (default) or the paper's biased L_i = 1 approximation",
    )
    p.add_argument("--seed", type=int, default=d.seed)
    p.add_argument("--checkpoint-every", type=int, default=d.checkpoint_every)
    p.add_argument(
        "--eval-spp",
        type=int,
        help="spp of the final evaluation renders, used exactly (default: "
        "adaptive, until the Monte Carlo noise adds less than 0.5 to the mean ΔE76 and SSIM's and "
        "the mottle's noise correction is accurate)",
    )
    p.add_argument("--threads", type=int, help="worker threads (default: all cores)")
    p.add_argument("--resume", action="store_true", help="continue from DIR/checkpoint.npz if present")
    add_lighting_args(p, "optimise and evaluate")
    if single_run:  # a single run's evaluation budget, estimate and progress lines (not select-inks' many runs)
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
            "--dry-run",
            action="store_true",
            help="build the scene, measure a short calibration and print only the run's estimated time, peak memory "
            "and disk; write nothing",
        )
        p.add_argument(
            "--log-every",
            type=float,
            default=30.0,
            metavar="SECONDS",
            help="when stderr is not a terminal (a log file, a scheduler): a progress line (iteration, loss, ΔE76, "
            "ETA) at least this often (default 30)",
        )


def add_ray_arg(p) -> None:
    """``--ray auto|ADDRESS`` of ``slab`` and ``optimize`` (``inkopt.distributed``)."""
    p.add_argument(
        "--ray",
        metavar="auto|ADDRESS",
        help="render texel shards on Ray workers, one per node, with results identical to a "
        "single-machine run: 'auto' starts a local instance, ADDRESS joins a cluster (pip install "
        "'inkopt[ray]')",
    )


def ray_from_args(args) -> str | None:
    """``--ray``, checked before any work: a one-line error if Ray is not installed."""
    if args.ray:
        from ..distributed import import_ray

        import_ray()
    return args.ray


def config_from_args(args):
    from ..optim import OptimizeConfig
    from ..units import parse_duration

    cfg = OptimizeConfig(
        iterations=args.iterations,
        spp=args.spp,
        forward_spp=args.forward_spp,
        gamma=parse_gamma(args.gamma),
        lr=args.lr,
        optimizer=args.optimizer,
        param=args.param,
        init=args.init,
        seed=args.seed,
        grad_method=args.gradient,
        checkpoint_every=args.checkpoint_every,
        smooth=args.smooth,
        finish_smooth=args.finish_smooth,
        smooth_edge=args.smooth_edge,
        decay=args.decay,
        adjoint_ema=args.adjoint_ema,
        # select-inks compares its candidates at equal iterations: no stopping when done there
        stop_gain=getattr(args, "stop_gain", 0.0),
        time_budget=parse_duration(args.time_budget) if getattr(args, "time_budget", None) else None,
    )
    cfg.validate()
    return cfg


def slab_spec_from_args(args, top: str):
    """The ``SlabSpec`` of ``top`` and the slab options (``--size-mm``, ``--bottom``, ``--dpi``, translucency)."""
    from ..scenes.spec import SlabSpec
    from ..units import OPT_DPI, parse_size_mm

    return SlabSpec(
        top,
        parse_size_mm(args.size_mm),
        args.bottom,
        getattr(args, "dpi", OPT_DPI),
        args.translucency,
        args.translucency_depth_mm,
    )


def mesh_spec_from_args(args, path: str):
    """The ``MeshSpec`` of ``path`` and the mesh options (``--height-mm`` or ``--scale``, ``--shell-mm``,
    ``--dpi``, ``--up``, translucency, ``--texture``, ``--constant-color``)."""
    from ..scenes.spec import MeshSpec

    return MeshSpec(
        path,
        args.height_mm,
        args.scale,
        args.shell_mm,
        args.dpi,
        args.up,
        args.translucency,
        args.translucency_depth_mm,
        args.texture,
        args.constant_color,
    )


def run_from_args(args, spec):
    """``slab`` and ``optimize``: check ``spec`` (before the ink set and the optimiser settings are read), build
    its scene with ``--inks`` and optimise it into ``--out``; returns the run's ``Report`` (with ``--dry-run`` its
    ``estimate.Estimate``, nothing written)."""
    import time

    from ..model import InkTable
    from ..run import deadline_plan, run_coarse_to_fine, run_optimisation

    started = time.perf_counter()  # a time budget counts the scene's building (voxelization) too
    spec.validate()
    if not (args.log_every >= 0):
        raise ValueError(f"--log-every must be a number of seconds >= 0, got {args.log_every}")
    check_budget(args.eval_max_spp, args.eval_time_budget, "--eval-max-spp", "--eval-time-budget")
    if args.eval_spp is not None and args.eval_spp < 1:
        raise ValueError(f"--eval-spp must be at least 1 (leave it out for adaptive samples), got {args.eval_spp}")
    inks = InkTable.parse(args.inks)
    cfg = config_from_args(args)
    ray = ray_from_args(args)
    lighting = lighting_from_args(args)
    kw = dict(
        resume=args.resume,
        eval_spp=args.eval_spp,
        threads=args.threads,
        progress=sys.stderr.isatty(),
        lighting=lighting,
        ray=ray,
        log=stderr_log,
        log_every_s=args.log_every,
        dry_run=args.dry_run,
        eval_max_spp=args.eval_max_spp,
        eval_time_budget=args.eval_time_budget,
        started=started,
    )
    coarse_dpi = args.coarse_dpi
    if coarse_dpi is None and cfg.time_budget is not None:
        coarse_dpi, cfg = deadline_plan(spec, cfg, log=stderr_log)
    if coarse_dpi:
        return run_coarse_to_fine(spec, inks, args.out, cfg, coarse_dpi, **kw)
    return run_optimisation(spec.build(inks), args.out, cfg, **kw)


def print_run_summary(rep, init: str, extra: str = "") -> None:
    """The closing line of ``slab`` and ``optimize`` from their ``Report``."""
    m = rep.metrics
    total = rep.seconds_total or rep.seconds
    whole = f" (whole run across resumes {total:.0f} s)" if total > rep.seconds + 1e-3 else ""  # resumed
    print(
        f"mean ΔE76 {rep.initial_delta_e76_mean:.2f} ({init} start) -> {m.delta_e76_mean:.2f} "
        f"(p95 {m.delta_e76_p95:.2f}, ΔE2000 {m.delta_e2000_mean:.2f}, SSIM {m.ssim:.3f}) "
        f"after {rep.iterations} iterations{stopped(rep)} in {rep.seconds:.0f} s{whole}{extra}"
    )


def stopped(rep) -> str:
    """ " (converged)" or " (time budget)" when the run ended before its maximum, else ""."""
    reason = (rep.stop or {}).get("reason")
    return f" ({reason})" if reason in ("converged", "time budget") else ""
