"""``inkopt optimize MESH``: optimise the inks of a textured 3D object (a ``scenes.spec.MeshSpec`` run by
``inkopt.run``)."""
from __future__ import annotations

from ..scenes.spec import UP_AXES
from ..units import OPT_DPI
from .common import (add_optimizer_args, add_ray_arg, add_translucency_args, mesh_spec_from_args, print_run_summary,
                     run_from_args)


def _optimize(args) -> int:
    rep = run_from_args(args, mesh_spec_from_args(args, args.mesh))
    print_run_summary(rep, args.init, f" (peak memory {rep.peak_rss_gb:.1f} GiB)")
    print(f"views: {args.out}/views.png, {args.out}/prediction.glb; report: {args.out}/report.json")
    return 0


def register_cli(sub) -> None:
    p = sub.add_parser("optimize", help="optimise the inks of a textured 3D object (OBJ, glTF/GLB, PLY)",
                       description="Voxelize a textured mesh and optimise the ink mixture of every voxel so that "
                                   "the printed object's surface matches its texture.")
    p.add_argument("mesh", metavar="MESH", help="textured mesh: OBJ (+MTL +texture), glTF/GLB or PLY; must be solid")
    p.add_argument("--out", required=True, metavar="DIR", help="run directory (see docs/run-dir.md)")
    p.add_argument("--height-mm", type=float, metavar="H", help="scale the object to this height (mm)")
    p.add_argument("--scale", type=float, metavar="S", help="or: mm per model unit")
    p.add_argument("--up", choices=UP_AXES, default="y", help="the file's up axis (default y, as OBJ/glTF)")
    p.add_argument("--shell-mm", type=float, metavar="D",
                   help="optimise only voxels less than D mm below the surface; deeper ones are printed white "
                        "(default: every voxel of the object is optimised)")
    p.add_argument("--dpi", type=float, default=OPT_DPI, help=f"optimisation grid resolution (default {OPT_DPI:g})")
    add_translucency_args(p, mesh=True)
    add_optimizer_args(p)
    add_ray_arg(p)
    p.set_defaults(func=_optimize)
