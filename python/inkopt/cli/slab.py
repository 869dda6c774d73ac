"""``inkopt slab``: optimise a textured 2.5D slab (its scene from the pictures, then ``inkopt.run``)."""
from __future__ import annotations

import sys

from .common import (add_optimizer_args, add_ray_arg, add_translucency_args, config_from_args, lighting_from_args,
                     print_run_summary, ray_from_args, stderr_log)


def _slab(args) -> int:
    from ..model import InkTable
    from ..run import run_optimisation
    from ..scenes.slab import load_slab
    from ..units import parse_size_mm

    inks = InkTable.parse(args.inks)
    cfg = config_from_args(args)
    ray = ray_from_args(args)
    lighting = lighting_from_args(args)
    scene = load_slab(args.top, args.bottom, parse_size_mm(args.size_mm), inks, translucency=args.translucency,
                      translucency_depth_mm=args.translucency_depth_mm)
    rep = run_optimisation(scene, args.out, cfg, resume=args.resume, eval_spp=args.eval_spp, threads=args.threads,
                           progress=sys.stderr.isatty(), lighting=lighting, ray=ray, log=stderr_log)
    print_run_summary(rep, args.init)
    print(f"pictures: {args.out}/face_*.png, {args.out}/loss.png; report: {args.out}/report.json")
    return 0


def register_cli(sub) -> None:
    p = sub.add_parser("slab", help="optimise the inks of a textured 2.5D slab",
                       description="Optimise the ink mixture of every voxel of a slab so that its printed "
                                   "appearance matches TOP_IMAGE (and --bottom IMAGE).")
    p.add_argument("top", metavar="TOP_IMAGE", help="picture of the top face (sRGB)")
    p.add_argument("--bottom", metavar="IMAGE", help="picture of the bottom face (seen from below, like a page's back)")
    p.add_argument("--size-mm", required=True, help="WxHxD in mm, e.g. 15x10x2.5 (must match the picture's aspect)")
    p.add_argument("--out", required=True, metavar="DIR", help="run directory (see docs/run-dir.md)")
    add_translucency_args(p)
    add_optimizer_args(p)
    add_ray_arg(p)
    p.set_defaults(func=_slab)
