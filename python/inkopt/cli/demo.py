"""``inkopt demo``: the bundled example. Renders a small CMYKW volume, optimises a two-sided slab (a colour chart on
top, the paper's zebra stripes below) and a small textured mesh (Spot, public domain, shipped in
``inkopt/data/spot``), evaluates both against the print-shop baselines and writes their soft-proof pages."""

from __future__ import annotations

import sys
from importlib import resources
from pathlib import Path

import numpy as np

from .common import add_threads_arg

DEMO_TABLE_STEP = 4  # the baselines' colour table at 1/4 steps of ink share (70 patches: seconds, not minutes)
DEMO_EVAL_SPP = 128  # samples per texel of the demo's evaluations (the noise is said on the page)


def _demo(args) -> int:
    from .. import charts
    from ..evaluation.colour_table import colour_table
    from ..evaluation.evaluate import evaluate_run
    from ..evaluation.options import EvaluateOptions
    from ..model import InkTable, Texels, Volume
    from ..optim import OptimizeConfig
    from ..proof import write_proof
    from ..render import render
    from ..run import RunOptions, run_optimisation
    from ..scenes import build_scene
    from ..scenes.spec import MeshSpec, SlabSpec
    from ..units import voxel_mm

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    inks = InkTable.parse("vero-cmykw")
    say = lambda s: print("      " + s)  # noqa: E731

    # 1. Render: a uniform 50 % white / 50 % cyan slab, top face, and what it looks like.
    mix = np.zeros((30, 24, 24, len(inks)), np.float32)
    mix[..., inks.index("cyan")] = mix[..., inks.index("white")] = 0.5
    vol = Volume.from_mixture(voxel_mm=(voxel_mm(),) * 3, mixture=mix, inks=inks, boundary="periodic-xy")
    vol.save(out / "cyan_white.npz")
    res = render(vol, Texels.for_volume(vol, ["top"]), spp=64, seed=0)
    m, e = res.mean_rgb, res.mean_rgb_stderr
    print(
        f"[1/3] rendered {out / 'cyan_white.npz'} (50 % cyan + 50 % white, 2.5 mm, periodic): linear RGB "
        + " ".join(f"{a:.3f}±{b:.3f}" for a, b in zip(m, e))
        + f"  ({res.events / res.seconds / 1e6:.1f} M events/s)"
    )
    table = colour_table(inks, step=DEMO_TABLE_STEP, threads=args.threads)
    pages = []

    def finish(run: Path, rep) -> None:
        ev = evaluate_run(run, EvaluateOptions(spp=DEMO_EVAL_SPP, threads=args.threads, table=table))
        p = write_proof(run)
        pages.append(p.path)
        q = ev.quantized.metrics
        base = ", ".join(f"{k} baseline {v.metrics.delta_e76_mean:.1f}" for k, v in (ev.baselines or {}).items())
        say(
            f"mean ΔE76 {rep.initial_delta_e76_mean:.1f} (start) -> {rep.metrics.delta_e76_mean:.1f} optimised, "
            f"{q.delta_e76_mean:.1f} printed; {base}; {rep.seconds + ev.seconds:.0f} s"
        )

    # 2. Optimise a 6 x 4 x 1 mm two-sided slab.
    top = charts.save(charts.colour_chart(288, 192), out / "chart.png")
    bottom = charts.save(charts.zebra(71, 47), out / "zebra.png")  # the face's texel grid: exact stripe widths
    cfg = OptimizeConfig(iterations=args.iterations, spp=4, seed=0)
    print(
        f"[2/3] optimising a 6 x 4 x 1 mm slab: {top.name} on top, {bottom.name} below, {cfg.iterations} iterations ..."
    )
    scene = build_scene(SlabSpec(top, (6.0, 4.0, 1.0), bottom), inks)
    options = RunOptions(
        resume=True, eval_spp=DEMO_EVAL_SPP, threads=args.threads, progress=sys.stderr.isatty(), log=say
    )
    run = out / "slab"
    finish(run, run_optimisation(scene, run, cfg, options))

    # 3. Optimise Spot, a textured mesh, at a small size.
    with resources.as_file(resources.files("inkopt").joinpath("data", "spot", "spot.obj")) as spot:
        cfg = OptimizeConfig(iterations=args.mesh_iterations, seed=0)
        print(f"[3/3] optimising Spot, {args.mesh_height_mm:g} mm high, {cfg.iterations} iterations ...")
        scene = build_scene(MeshSpec(spot, height_mm=args.mesh_height_mm), inks)
        run = out / "spot"
        finish(run, run_optimisation(scene, run, cfg, options))
    print("open in a browser (3D view, swipe, ΔE76 maps, figures): " + "  ".join(pages))
    return 0


def register_cli(sub) -> None:
    p = sub.add_parser(
        "demo", help="run the bundled example (a render, a small slab and a small textured mesh, their reports)"
    )
    p.add_argument("--out", default="demo-out", help="output folder (default demo-out)")
    p.add_argument("--iterations", type=int, default=100, help="iterations of the slab (default 100)")
    p.add_argument("--mesh-iterations", type=int, default=40, help="iterations of the mesh (default 40)")
    p.add_argument("--mesh-height-mm", type=float, default=6.0, help="height of the mesh (default 6 mm)")
    add_threads_arg(p)
    p.set_defaults(func=_demo)
