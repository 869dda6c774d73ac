"""``inkopt slab``: optimise a textured 2.5D slab (a ``scenes.spec.SlabSpec`` run by ``inkopt.run``)."""

from __future__ import annotations

from ..units import parse_duration
from .common import (
    add_optimizer_args,
    add_ray_arg,
    add_translucency_args,
    print_run_summary,
    run_from_args,
    slab_spec_from_args,
)


def _slab(args) -> int:
    rep = run_from_args(args, slab_spec_from_args(args, args.top))
    if args.dry_run:
        print(rep.line(parse_duration(args.time_budget) if args.time_budget else None))
        return 0
    print_run_summary(rep, rep.init)
    print(f"pictures: {args.out}/face_*.png, {args.out}/loss.png; report: {args.out}/report.json")
    return 0


def register_cli(sub) -> None:
    p = sub.add_parser(
        "slab",
        help="optimise the inks of a textured 2.5D slab",
        description="Optimise the ink mixture of every voxel of a slab so that its printed "
        "appearance matches TOP_IMAGE (and --bottom IMAGE).",
    )
    p.add_argument("top", metavar="TOP_IMAGE", help="picture of the top face (sRGB)")
    p.add_argument("--bottom", metavar="IMAGE", help="picture of the bottom face (seen from below, like a page's back)")
    p.add_argument("--size-mm", required=True, help="WxHxD in mm, e.g. 15x10x2.5 (must match the picture's aspect)")
    p.add_argument("--out", required=True, metavar="DIR", help="run directory (see docs/run-dir.md)")
    add_translucency_args(p)
    add_optimizer_args(p)
    add_ray_arg(p)
    p.set_defaults(func=_slab)
