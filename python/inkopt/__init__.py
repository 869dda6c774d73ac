"""inkopt: gradient-based appearance optimization for full-colour inkjet 3D prints.

Pipeline stages, one module each: materials -> volume -> render -> loss -> optimize -> quantize -> export,
plus mesh (voxelization of textured meshes), slab (2.5D slabs), evaluate and cli.
Conventions (axis order, units, colour spaces, texel order): docs/conventions.md.
"""
__version__ = "0.1.0"
