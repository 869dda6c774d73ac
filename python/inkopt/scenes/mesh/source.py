"""Where a mesh's target colour comes from, checked before anything is optimised.

A mesh whose colour silently falls back to a placeholder optimises for a wrong target and exits 0, so the sources
are checked in one place (``check_obj_materials`` before trimesh reads an OBJ, ``check_colour_source`` after):

- an OBJ's ``mtllib`` that does not exist, or a ``map_Kd`` texture that does not exist: an error naming the file;
- an OBJ without ``mtllib`` while a ``.mtl`` file sits beside it: an error naming that file (trimesh would give
  the mesh a grey 2 x 2 placeholder texture, with an alpha channel);
- a texture without uv coordinates: an error;
- no texture, vertex or face colours at all (a constant target): an error unless the user accepts a constant colour
  on purpose (``--constant-color``).

``--texture FILE`` names the texture directly (any image mode, ``scenes.picture.picture_rgba``); it replaces the
material's and needs the mesh's uv coordinates. ``describe_colour_source`` says in one phrase which source a
loaded mesh uses (the first log line and report.json's ``colour_source``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...errors import ParameterError
from ...images import open_image

FIX = "name the texture with `texture` FILE, or pass `constant_color` to accept a uniform colour"


@dataclass(frozen=True)
class ObjMaterials:
    """What an OBJ file says about its colour: ``mtllibs`` the material libraries it names (resolved, all exist),
    ``textures`` the ``map_Kd`` files they name (resolved, all exist), ``has_uv`` whether it has ``vt`` lines."""

    mtllibs: list[Path] = field(default_factory=list)
    textures: list[Path] = field(default_factory=list)
    has_uv: bool = False


def _named_file(rest: str, folder: Path) -> tuple[str, Path]:
    """The file an ``mtllib``/``map_Kd`` statement's remainder names: the whole remainder if that exists (names
    with spaces), else its last word (after options such as ``-s 1 1 1``)."""
    rest = rest.strip().replace("\\", "/")
    whole = folder / rest
    if whole.is_file() or not rest:
        return rest, whole
    last = rest.split()[-1]
    return last, folder / last


def check_obj_materials(path, skip_files: bool = False) -> ObjMaterials:
    """Read an OBJ's ``mtllib``, ``vt`` and (through its MTL files) ``map_Kd`` lines; one-line ValueError for a
    material library or texture that is named but missing, and for an OBJ without ``mtllib`` beside a ``.mtl``
    file. With ``skip_files`` (``--texture`` or ``--constant-color`` given) the material files are not checked."""
    path = Path(path)
    data = path.read_bytes()
    has_uv = re.search(rb"^[ \t]*vt[ \t]", data, re.M) is not None
    libs = [
        m.group(1).decode("utf-8", "replace") for m in re.finditer(rb"^[ \t]*mtllib[ \t]+(.+?)[ \t\r]*$", data, re.M)
    ]
    if skip_files:
        return ObjMaterials([], [], has_uv)
    folder = path.parent
    if not libs:
        beside = sorted(folder.glob("*.mtl"), key=lambda p: (p.stem != path.stem, p.name))
        if beside:
            raise ParameterError(
                f"{path} names no material library (no mtllib line) but {beside[0].name} is beside it: add the "
                f"line 'mtllib {beside[0].name}' to the OBJ, or {FIX}"
            )
        return ObjMaterials([], [], has_uv)
    mtllibs, textures = [], []
    for rest in libs:
        name, lib = _named_file(rest, folder)
        if not lib.is_file():
            raise ParameterError(
                f"{path} names material library {name}, which does not exist in {folder}: put it there, or {FIX}"
            )
        mtllibs.append(lib)
        text = lib.read_text(errors="replace")
        for m in re.finditer(r"^[ \t]*map_Kd[ \t]+(.+?)[ \t\r]*$", text, re.M):
            tname, tex = _named_file(m.group(1), lib.parent)
            if not tex.is_file():
                raise ParameterError(
                    f"{lib} names texture {tname}, which does not exist in {lib.parent}: put it there, or {FIX}"
                )
            textures.append(tex)
    return ObjMaterials(mtllibs, textures, has_uv)


def load_texture(path):
    """``texture``, an image file: (PIL RGB image of the sRGB colours, (H, W) float32 alpha or None where opaque).
    One-line ValueError (``images.ImageError``) for a missing, unreadable or too large file."""
    from PIL import Image

    from ..picture import picture_rgba

    with open_image(path, f"texture {path}") as im:
        rgba = picture_rgba(im, f"texture {path}")
    rgb = Image.fromarray(np.round(rgba[..., :3] * 255).astype(np.uint8), "RGB")
    alpha = rgba[..., 3] if np.any(rgba[..., 3] < 1) else None
    return rgb, alpha


def check_colour_source(mesh, constant_color: bool = False, texture_named: bool = False) -> None:
    """One-line ValueError for a mesh whose texture cannot be looked up (no uv coordinates) or, unless
    ``constant_color``, whose target is one constant colour. ``texture_named``: the file names a texture (an
    OBJ's ``map_Kd``), so a constant source means its uv coordinates are missing."""
    if (mesh.texture is not None or texture_named) and mesh.uv is None:
        raise ParameterError(
            f"{mesh.source} has a texture but no texture coordinates (no uv / vt): export it with its UVs, or pass "
            f"`constant_color` to accept a uniform colour"
        )
    if mesh.color_source == "constant" and not constant_color:
        raise ParameterError(
            f"{mesh.source} has no texture, vertex colours or face colours, so the target would be the constant "
            f"{_hex(mesh.color)}: {FIX}"
        )


def _hex(srgb) -> str:
    return "#" + "".join(f"{int(round(float(v) * 255)):02X}" for v in np.clip(srgb, 0, 1)[:3])


def describe_colour_source(mesh) -> str:
    """One phrase: "texture NAME (W x H px)", "vertex colours", "face colours" or "constant colour #RRGGBB"."""
    src = mesh.color_source
    if src == "texture":
        w, h = mesh.texture.size
        alpha = ", with alpha" if mesh.texture_alpha is not None else ""
        return f"texture {mesh.texture_name or '(embedded)'} ({w} x {h} px{alpha})"
    if src in ("vertex", "face"):
        return f"{src} colours"
    return f"constant colour {_hex(mesh.color)}"
