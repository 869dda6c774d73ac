"""``inkopt slab``: optimise a textured 2.5D slab (a ``scenes.spec.SlabSpec`` run by ``inkopt.run``)."""

from __future__ import annotations

from .common import add_dpi_arg
from .runargs import add_run_args, run_command, slab_spec_from_args


def _slab(args) -> int:
    return run_command(
        args, slab_spec_from_args(args, args.top), f"pictures: {args.out}/face_*.png, {args.out}/loss.png"
    )


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
    add_dpi_arg(p)
    add_run_args(p, translucency="slab")
    p.set_defaults(func=_slab)
