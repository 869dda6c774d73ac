"""Textured 3D objects: load (``load``), voxelize (``voxelize``), view (``views``) and the optimisation scene
(``scene``)."""

from .checks import UP_AXES, check_mesh_inputs, check_placement
from .load import TexturedMesh, load_mesh, mesh_from_trimesh
from .scene import MeshScene, build_mesh_scene, free_voxels, load_spec_mesh
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
    "load_spec_mesh",
    "bake_vertex_colors",
    "render_views",
    "write_glb",
    "VoxelizedObject",
    "voxelize",
]
