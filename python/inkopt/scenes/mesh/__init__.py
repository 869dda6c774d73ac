"""Textured 3D objects: load (``load``), voxelize (``voxelize``), view (``views``) and the optimisation scene
(``scene``)."""
from .load import TexturedMesh, load_mesh, mesh_from_trimesh
from .scene import MeshScene, build_mesh_scene, free_voxels
from .views import bake_vertex_colors, render_views, write_glb
from .voxelize import VoxelizedObject, voxelize

__all__ = ["TexturedMesh", "load_mesh", "mesh_from_trimesh", "MeshScene", "build_mesh_scene", "free_voxels",
           "bake_vertex_colors", "render_views", "write_glb", "VoxelizedObject", "voxelize"]
