"""``inkopt demo``: the bundled example. Renders a small CMYKW volume, then optimises a two-sided slab (a colour
chart on top, the paper's zebra stripes below) and points at the pictures."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np


def _demo(args) -> int:
    from .. import charts
    from ..model import InkTable, Texels, Volume
    from ..optim import OptimizeConfig
    from ..render import render
    from ..run import run_optimisation
    from ..scenes.spec import SlabSpec
    from ..units import voxel_mm

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    inks = InkTable.parse("vero-cmykw")

    # 1. Render: a uniform 50 % white / 50 % cyan slab, top face, and what it looks like.
    mix = np.zeros((30, 24, 24, len(inks)), np.float32)
    mix[..., inks.index("cyan")] = mix[..., inks.index("white")] = 0.5
    vol = Volume.from_mixture(voxel_mm=(voxel_mm(),) * 3, mixture=mix, inks=inks, boundary="periodic-xy")
    vol.save(out / "cyan_white.npz")
    res = render(vol, Texels.for_volume(vol, ["top"]), spp=64, seed=0)
    m, e = res.mean_rgb, res.mean_rgb_stderr
    print(
        f"[1/2] rendered {out / 'cyan_white.npz'} (50 % cyan + 50 % white, 2.5 mm, periodic): linear RGB "
        + " ".join(f"{a:.3f}±{b:.3f}" for a, b in zip(m, e))
        + f"  ({res.events / res.seconds / 1e6:.1f} M events/s)"
    )

    # 2. Optimise a 6 x 4 x 1 mm two-sided slab.
    top = charts.save(charts.colour_chart(288, 192), out / "chart.png")
    bottom = charts.save(charts.zebra(71, 47), out / "zebra.png")  # the face's texel grid: exact stripe widths
    cfg = OptimizeConfig(iterations=args.iterations, spp=4, seed=0)
    print(
        f"[2/2] optimising a 6 x 4 x 1 mm slab: {top.name} on top, {bottom.name} below, {cfg.iterations} iterations ..."
    )
    scene = SlabSpec(top, (6.0, 4.0, 1.0), bottom).build(inks)
    rep = run_optimisation(
        scene, out / "slab", cfg, progress=sys.stderr.isatty(), log=lambda s: print("      " + s), resume=True
    )
    print(
        f"      mean ΔE76 {rep.initial_delta_e76_mean:.1f} (all-white start) -> {rep.metrics.delta_e76_mean:.1f}, "
        f"SSIM {rep.initial_ssim:.3f} -> {rep.metrics.ssim:.3f}, {rep.seconds:.0f} s"
    )
    print(
        f"look at: {out / 'slab' / 'face_top.png'}, {out / 'slab' / 'face_bottom.png'}, "
        f"{out / 'slab' / 'loss.png'}; numbers: {out / 'slab' / 'report.json'}"
    )
    return 0


def register_cli(sub) -> None:
    p = sub.add_parser("demo", help="run the bundled example (a render and a small slab optimisation)")
    p.add_argument("--out", default="demo-out", help="output folder (default demo-out)")
    p.add_argument("--iterations", type=int, default=150)
    p.set_defaults(func=_demo)
