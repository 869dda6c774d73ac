"""``inkopt optimize MESH``: optimise the inks of a textured 3D object (a ``scenes.spec.MeshSpec`` run by
``inkopt.run``)."""

from __future__ import annotations

from ..units import parse_duration
from .common import (
    add_mesh_args,
    add_optimizer_args,
    add_ray_arg,
    add_translucency_args,
    mesh_spec_from_args,
    print_run_summary,
    run_from_args,
)


def _optimize(args) -> int:
    rep = run_from_args(args, mesh_spec_from_args(args, args.mesh))
    if args.dry_run:
        print(rep.line(parse_duration(args.time_budget) if args.time_budget else None))
        return 0
    print_run_summary(rep, rep.init, f" (peak memory {rep.peak_rss_gb:.1f} GiB)")
    print(f"views: {args.out}/views.png, {args.out}/prediction.glb; report: {args.out}/report.json")
    return 0


def register_cli(sub) -> None:
    p = sub.add_parser(
        "optimize",
        help="optimise the inks of a textured 3D object (OBJ, glTF/GLB, PLY)",
        description="Voxelize a textured mesh and optimise the ink mixture of every voxel so that "
        "the printed object's surface matches its texture.",
    )
    p.add_argument("mesh", metavar="MESH", help="textured mesh: OBJ (+MTL +texture), glTF/GLB or PLY; must be solid")
    p.add_argument("--out", required=True, metavar="DIR", help="run directory (see docs/run-dir.md)")
    add_mesh_args(p)
    add_translucency_args(p, mesh=True)
    add_optimizer_args(p)
    add_ray_arg(p)
    p.set_defaults(func=_optimize)
