"""``inkopt optimize MESH``: optimise the inks of a textured 3D object (a ``scenes.spec.MeshSpec`` run by
``inkopt.run``)."""

from __future__ import annotations

from .common import add_mesh_args
from .runargs import add_run_args, mesh_spec_from_args, run_command


def _optimize(args) -> int:
    outputs = f"views: {args.out}/views.png, {args.out}/prediction.glb"
    return run_command(args, mesh_spec_from_args(args, args.mesh), outputs, show_memory=True)


def register_cli(sub) -> None:
    p = sub.add_parser(
        "optimize",
        help="optimise the inks of a textured 3D object (OBJ, glTF/GLB, PLY)",
        description="Voxelize a textured mesh and optimise the ink mixture of every voxel so that "
        "the printed object's surface matches its texture.",
    )
    p.add_argument("mesh", metavar="MESH", help="textured mesh: OBJ (+MTL +texture), glTF/GLB or PLY; must be solid")
    add_mesh_args(p)
    add_run_args(p, translucency="mesh")
    p.set_defaults(func=_optimize)
