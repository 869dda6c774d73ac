"""Textured 3D objects: load (``load``), voxelize (``voxelize``), view (``views``) and the optimisation scene
(``scene``)."""

from .load import UP_AXES, TexturedMesh, check_placement, load_mesh, mesh_from_trimesh
from .scene import MeshScene, build_mesh_scene, check_mesh_inputs, free_voxels
from .views import bake_vertex_colors, render_views, write_glb
from .voxelize import VoxelizedObject, voxelize

__all__ = [
    "UP_AXES",
    "TexturedMesh",
    "check_placement",
    "load_mesh",
    "mesh_from_trimesh",
    "MeshScene",
    "build_mesh_scene",
    "check_mesh_inputs",
    "free_voxels",
    "bake_vertex_colors",
    "render_views",
    "write_glb",
    "VoxelizedObject",
    "voxelize",
]
