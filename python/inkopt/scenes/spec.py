"""Scene specs: every user input of a scene in one frozen, picklable value, checked in one place and built into a
``Scene`` for any ink set.

A spec holds paths and numbers only (no arrays), so it travels in a few hundred bytes to a worker process or a Ray
task, which builds its scene there (``scenes.build_scene(spec, inks)``: the spec is checked, then
``scenes.slab.build_slab_scene`` or ``scenes.mesh.build_mesh_scene`` take it whole); the command line (``slab``,
``optimize``, ``select-inks``, ``demo``), the run driver and the ink-set search build their scenes through it alike.

- ``SlabSpec``: pictures on a slab (``scenes.slab``): the top picture, an optional bottom one, the size (W, H, D) mm.
- ``MeshSpec``: a textured mesh (``scenes.mesh``) scaled to ``height_mm`` or by ``scale`` mm per model unit,
  optimised within ``shell_mm`` of its surface (None: everywhere inside), the core below it printed as the fixed
  mixture ``core`` (``model.fixed.core_shares``).

Both take a translucency constraint (``scenes.translucency``): ``translucency`` a mask file (meshes also "alpha",
the texture's alpha channel) and ``translucency_depth_mm`` (None: through the whole object).

``to_json()`` is the spec as a JSON object (the target of a selection's state file); ``spec_from_json`` reads it
back. Slabs are written with kind "image" and the inputs a spec leaves at None (or off) are left out, so the targets of
selections made before translucency could be given read and compare the same.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from ..errors import ParameterError
from ..model import InkTable, transparent_ink
from ..model.fixed import DEFAULT_CORE, core_shares, parse_core
from ..model.volume import check_grid_budget
from ..units import OPT_DPI, voxel_mm
from .translucency import ALPHA, check_depth


def check_slab_size(size_mm, dpi: float = OPT_DPI) -> None:
    """One-line error unless ``size_mm`` is three positive numbers W, H, D (mm), each at least one voxel of the grid
    at ``dpi``: the grid holds round(side / voxel) voxels a side, and a thinner side would silently become one
    voxel, thicker than asked."""
    if len(size_mm) != 3 or not all(np.isfinite(v) and v > 0 for v in size_mm):
        raise ParameterError(f"`size_mm` sizes must be three positive numbers W x H x D, got {tuple(size_mm)}")
    vox = voxel_mm(dpi)
    for side, v in zip(("width", "height", "depth"), size_mm):
        if v < vox * (1 - 1e-9):
            raise ParameterError(
                f"`size_mm` {'x'.join(f'{s:g}' for s in size_mm)} mm: the {side} {v:g} mm is less than one voxel "
                f"({vox:.4g} mm at {dpi:g} DPI); every side must be at least one voxel"
            )


def _check_file(path, what: str) -> None:
    if not Path(path).is_file():
        raise ValueError(f"{what} {path} does not exist")


@dataclass(frozen=True)
class SlabSpec:
    """Pictures on a slab: ``top`` (and ``bottom``) picture files (sRGB), ``size_mm`` (W, H, D) mm, the grid at
    ``dpi``; ``translucency``: a grey mask file of the top picture's size, down to ``translucency_depth_mm``."""

    top: str
    size_mm: tuple[float, float, float]
    bottom: str | None = None
    dpi: float = OPT_DPI
    translucency: str | None = None
    translucency_depth_mm: float | None = None
    kind: ClassVar[str] = "slab"

    def __post_init__(self):
        object.__setattr__(self, "top", str(self.top))
        object.__setattr__(self, "bottom", None if self.bottom is None else str(self.bottom))
        object.__setattr__(self, "size_mm", tuple(float(v) for v in self.size_mm))
        object.__setattr__(self, "dpi", float(self.dpi))
        if self.translucency is not None:
            object.__setattr__(self, "translucency", str(self.translucency))

    def validate(self, inks: InkTable | None = None) -> None:
        """One-line ValueErrors for inputs that are wrong before any file is read (sizes, dpi, depth, missing
        files); with ``inks``, also an ink set that cannot honour the constraints."""
        check_slab_size(self.size_mm, self.dpi)  # and the one-line error of a dpi that is not positive
        w, h, depth = self.size_mm  # a slab's grid holds its mixture (4 bytes per ink) and, rendered, σs and σa (24)
        check_grid_budget(self.top, (w, h, depth), self.dpi, 24 + 4 * len(inks or ()), "size_mm")
        _check_translucency(self.translucency, self.translucency_depth_mm, inks, mesh=False)
        _check_file(self.top, "picture")
        if self.bottom is not None:
            _check_file(self.bottom, "picture")

    def to_json(self) -> dict:
        d = {"kind": "image", "top": self.top, "bottom": self.bottom, "size_mm": list(self.size_mm), "dpi": self.dpi}
        return _with_translucency(d, self)


@dataclass(frozen=True)
class MeshSpec:
    """A textured mesh file ``path`` (OBJ, glTF/GLB, PLY) scaled to ``height_mm`` or by ``scale`` mm per model
    unit (exactly one), ``up`` its up axis ("y" or "z"), optimised within ``shell_mm`` of the surface (None:
    every inside voxel) on a grid at ``dpi``; ``core``: the fixed mixture of the voxels below the shell ("white",
    "start" or ink shares "white=0.9,black=0.1"; ``model.fixed.core_shares``); ``translucency``: "alpha" or a grey
    mask file in texture space, down to ``translucency_depth_mm`` below the surface; ``texture``: an image file
    replacing the file's texture; ``constant_color``: a mesh without colours is accepted (its target is one
    colour); ``shell_chosen``: why the shell was chosen for the run rather than given (``footprint.fits.choose_shell``;
    None: given, or every voxel free), in report.json's scene entries."""

    path: str
    height_mm: float | None = None
    scale: float | None = None
    shell_mm: float | None = None
    dpi: float = OPT_DPI
    up: str = "y"
    translucency: str | None = None
    translucency_depth_mm: float | None = None
    texture: str | None = None
    constant_color: bool = False
    core: str = DEFAULT_CORE
    shell_chosen: str | None = None
    kind: ClassVar[str] = "mesh"

    def __post_init__(self):
        object.__setattr__(self, "path", str(self.path))
        object.__setattr__(self, "dpi", float(self.dpi))
        for name in ("height_mm", "scale", "shell_mm"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, float(getattr(self, name)))
        if self.translucency is not None:
            object.__setattr__(self, "translucency", str(self.translucency))
        if self.texture is not None:
            object.__setattr__(self, "texture", str(self.texture))
        object.__setattr__(self, "constant_color", bool(self.constant_color))
        object.__setattr__(self, "core", str(self.core))

    def validate(self, inks: InkTable | None = None) -> None:
        """One-line ValueErrors for inputs that are wrong before the mesh is read; with ``inks``, also an ink set
        that cannot honour the constraints (the white core, translucency)."""
        from .mesh.checks import check_mesh_inputs, check_placement  # the mesh modules only when a mesh is given

        check_placement(self.height_mm, self.scale, self.up)
        check_mesh_inputs(self.shell_mm, inks)
        parse_core(self.core) if inks is None else core_shares(self.core, inks)
        if self.shell_mm is None and self.core != DEFAULT_CORE:
            raise ParameterError(f"`core` {self.core} fills the voxels below `shell_mm`, but every voxel is free")
        voxel_mm(self.dpi)  # its one-line error for a dpi that is not positive
        _check_translucency(self.translucency, self.translucency_depth_mm, inks, mesh=True)
        _check_file(self.path, "mesh file")
        if self.texture is not None:
            _check_file(self.texture, "texture")
        if Path(self.path).suffix.lower() == ".obj":  # its material library and texture files, named but missing
            from .mesh.source import check_obj_materials

            check_obj_materials(self.path, skip_files=self.texture is not None or self.constant_color)

    def to_json(self) -> dict:
        d = {
            "kind": "mesh",
            "path": self.path,
            "height_mm": self.height_mm,
            "shell_mm": self.shell_mm,
            "dpi": self.dpi,
            "up": self.up,
        }
        if self.scale is not None:
            d["scale"] = self.scale
        if self.texture is not None:
            d["texture"] = self.texture
        if self.constant_color:
            d["constant_color"] = True
        if self.core != "white":  # written only where it differs from the white core of specs without one
            d["core"] = self.core
        if self.shell_chosen is not None:
            d["shell_chosen"] = self.shell_chosen
        return _with_translucency(d, self)


SceneSpec = SlabSpec | MeshSpec


def _check_translucency(translucency, depth_mm, inks, mesh: bool) -> None:
    if translucency is None:
        if depth_mm is not None:
            raise ParameterError("`translucency_depth_mm` needs `translucency`")
        return
    check_depth(depth_mm)
    if inks is not None:
        transparent_ink(inks)
    if not (mesh and translucency == ALPHA):
        _check_file(translucency, "translucency mask")


def _with_translucency(d: dict, spec) -> dict:
    if spec.translucency is not None:
        d["translucency"] = spec.translucency
        d["translucency_depth_mm"] = spec.translucency_depth_mm
    return d


def spec_from_json(d: dict) -> SceneSpec:
    """The spec of a ``to_json()`` object (kind "image" or "slab": a ``SlabSpec``; "mesh": a ``MeshSpec``)."""
    kind = d.get("kind")
    tr = {"translucency": d.get("translucency"), "translucency_depth_mm": d.get("translucency_depth_mm")}
    if kind in ("image", "slab"):
        return SlabSpec(d["top"], tuple(d["size_mm"]), bottom=d.get("bottom"), dpi=d.get("dpi", OPT_DPI), **tr)
    if kind == "mesh":
        return MeshSpec(
            d["path"],
            height_mm=d.get("height_mm"),
            scale=d.get("scale"),
            shell_mm=d.get("shell_mm"),
            dpi=d.get("dpi", OPT_DPI),
            up=d.get("up", "y"),
            **tr,
            texture=d.get("texture"),
            constant_color=bool(d.get("constant_color", False)),
            core=d.get("core", "white"),
            shell_chosen=d.get("shell_chosen"),
        )
    raise ValueError(f"unknown scene kind {kind!r}; expected 'image' (a slab) or 'mesh'")
