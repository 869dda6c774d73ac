"""inkopt: gradient-based appearance optimization for full-colour inkjet 3D prints.

Stages (docs/architecture.md): model (inks, volumes, texels) -> scenes (slabs, meshes) -> render -> loss ->
optim -> printing (quantize, export) -> evaluation; run.py drives one optimisation, rundir.py owns the run
directory, cli/ is the command line. Conventions (axis order, units, colour spaces, texel order):
docs/conventions.md.
"""

__version__ = "0.1.0"
