"""``inkopt optimize MESH``: optimise the inks of a textured 3D object (``inkopt.run.run_mesh``)."""
from __future__ import annotations

import sys

from ..units import OPT_DPI
from .common import (add_optimizer_args, add_ray_arg, add_translucency_args, config_from_args, lighting_from_args,
                     print_run_summary, ray_from_args, stderr_log)


def _optimize(args) -> int:
    from ..model import InkTable
    from ..run import run_optimisation
    from ..scenes.mesh import build_mesh_scene

    if (args.height_mm is None) == (args.scale is None):
        raise ValueError("give exactly one of --height-mm H (the object's height in mm) and --scale S "
                         "(mm per model unit)")
    inks = InkTable.parse(args.inks)
    cfg = config_from_args(args)
    ray = ray_from_args(args)
    lighting = lighting_from_args(args)
    scene = build_mesh_scene(args.mesh, inks, args.height_mm, args.scale, args.shell_mm, args.dpi, args.up,
                             args.translucency, args.translucency_depth_mm)
    rep = run_optimisation(scene, args.out, cfg, resume=args.resume, eval_spp=args.eval_spp, threads=args.threads,
                           progress=sys.stderr.isatty(), lighting=lighting, ray=ray, log=stderr_log)
    print_run_summary(rep, args.init, f" (peak memory {rep['peak_rss_gb']:.1f} GiB)")
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
    p.add_argument("--up", choices=("y", "z"), default="y", help="the file's up axis (default y, as OBJ/glTF)")
    p.add_argument("--shell-mm", type=float, metavar="D",
                   help="optimise only voxels less than D mm below the surface; deeper ones are printed white "
                        "(default: every voxel of the object is optimised)")
    p.add_argument("--dpi", type=float, default=OPT_DPI, help=f"optimisation grid resolution (default {OPT_DPI:g})")
    add_translucency_args(p, mesh=True)
    add_optimizer_args(p)
    add_ray_arg(p)
    p.set_defaults(func=_optimize)
