"""Where a mesh's target colour comes from, checked before anything is optimised.

A mesh whose colour silently falls back to a placeholder optimises for a wrong target and exits 0, so the sources
are checked in one place: ``check_obj_materials`` reads an OBJ's material statements before trimesh reads the
file, ``check_resolved`` looks at what trimesh made of them, ``check_colour_source`` at the loaded mesh.

trimesh resolves an OBJ's colour as follows: it reads the material library of the *first* ``mtllib`` statement
only; a group of faces whose ``usemtl`` material that library does not define (a wrong name, no ``usemtl`` at all,
a library that is not a material file such as ``mtllib /etc/passwd``, a missing one) gets a grey 2 x 2
placeholder texture with alpha, without a word. So these are errors naming the file, the material and the fix:

- an ``mtllib`` that does not exist, defines no material, or more than one ``mtllib`` (only the first is read);
- a ``usemtl`` material the library does not define, faces before the first ``usemtl``, or none at all;
- a used material's ``map_Kd`` texture that does not exist, is not an image, or is too large
  (``images.open_image``: its header is read, its pixels are not);
- after trimesh has read the file, any face group it gave its placeholder texture (``check_resolved``: trimesh
  marks every texture it read from a file with the file's name; its placeholder has none);
- an OBJ without ``mtllib`` while a ``.mtl`` file sits beside it;
- a texture without uv coordinates;
- no texture, vertex or face colours at all (a constant target), unless the user accepts a constant colour on
  purpose (``constant_color``).

Textures with an embedded RGB ICC profile other than sRGB are converted to sRGB before trimesh joins the materials
(``srgb_textures``; ``scenes.picture``), and ``describe_colour_source`` names the profile.

``texture``, an image file, names the texture directly (any image mode, ``scenes.picture.picture_rgba``); it
replaces the material's and needs the mesh's uv coordinates. ``describe_colour_source`` says in one phrase which
source a loaded mesh uses, with the size of the texture actually used (the first log line and report.json's
``colour_source``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...errors import ParameterError
from ...images import ImageError, ImageTooLargeError, open_image

#: the texture name of an atlas made of untextured materials' colours alone (``uniform_tiles``)
MATERIAL_COLOURS = "material colours (Kd)"
FIX = "name the texture with `texture` FILE, or pass `constant_color` to accept a uniform colour"


@dataclass(frozen=True)
class ObjMaterials:
    """What an OBJ file says about its colour: ``mtllibs`` the material library it names (resolved, exists; at
    most one), ``textures`` the ``map_Kd`` files of the materials it uses, by material name (resolved, readable
    images), ``has_uv`` whether it has ``vt`` lines."""

    mtllibs: list[Path] = field(default_factory=list)
    textures: dict[str, Path] = field(default_factory=dict)
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


def _statements(text: str, key: str) -> list[str]:
    """The remainders of every ``key`` statement of an OBJ text, in order."""
    return [m.group(1) for m in re.finditer(rf"^[ \t]*{key}[ \t]+(.+?)[ \t\r]*$", text, re.M)]


def _library(lib: Path) -> dict[str, str | None]:
    """An MTL file's materials as trimesh reads them: name (its words joined by one space) -> the remainder of its
    ``map_Kd`` statement (None without one), in file order."""
    materials: dict[str, str | None] = {}
    current = None
    for line in lib.read_text(errors="replace").splitlines():
        words = line.split()
        if len(words) < 2:
            continue
        key = words[0].lower()
        if key == "newmtl":
            current = " ".join(words[1:])
            materials[current] = None
        elif key == "map_kd" and current is not None:
            materials[current] = line[line.lower().index("map_kd") + 6 :].strip()
    return materials


def _listed(names) -> str:
    names = list(names)
    return ", ".join(names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else "")


def check_obj_materials(path, skip_files: bool = False) -> ObjMaterials:
    """Read an OBJ's ``mtllib``, ``usemtl`` and ``vt`` statements and, through its material library, the used
    materials' ``map_Kd`` textures; one-line ValueError for every way trimesh would fall back to its placeholder
    texture (module docstring) and for an OBJ without ``mtllib`` beside a ``.mtl`` file. With ``skip_files``
    (``texture`` or ``constant_color`` given) the material files are not checked."""
    path = Path(path)
    text = path.read_bytes().decode("utf-8", "replace")
    has_uv = re.search(r"^[ \t]*vt[ \t]", text, re.M) is not None
    libs = _statements(text, "mtllib")
    if skip_files:
        return ObjMaterials([], {}, has_uv)
    folder = path.parent
    if not libs:
        beside = sorted(folder.glob("*.mtl"), key=lambda p: (p.stem != path.stem, p.name))
        if beside:
            raise ParameterError(
                f"{path} names no material library (no mtllib line) but {beside[0].name} is beside it: add the "
                f"line 'mtllib {beside[0].name}' to the OBJ, or {FIX}"
            )
        return ObjMaterials([], {}, has_uv)
    if len(libs) > 1:
        raise ParameterError(
            f"{path} names {len(libs)} material libraries ({_listed(libs)}), but only the first is read: merge "
            f"them into one .mtl file, or {FIX}"
        )
    _check_first_mention(path, text)
    name, lib = _named_file(libs[0], folder)
    if not lib.is_file():
        raise ParameterError(
            f"{path} names material library {name}, which does not exist in {folder}: put it there, or {FIX}"
        )
    materials = _library(lib)
    if not materials:
        raise ParameterError(
            f"{path} names material library {lib}, which defines no material (no newmtl line): point the "
            f"mtllib line at the OBJ's .mtl file, or {FIX}"
        )
    return ObjMaterials([lib], _used_textures(path, text, lib, materials), has_uv)


def _check_first_mention(path: Path, text: str) -> None:
    """trimesh takes the first "mtllib" anywhere in the file (a comment, a name) for the statement: one-line
    ValueError where that is not the first ``mtllib`` statement."""
    stmt = re.search(r"^[ \t]*(mtllib)[ \t]", text, re.M)
    first = text.find("mtllib")
    if stmt is not None and first != stmt.start(1):
        line = text.count("\n", 0, first) + 1
        raise ParameterError(
            f"{path} mentions 'mtllib' on line {line}, before its mtllib statement, and the mesh reader takes that "
            f"mention for the statement: remove it, or {FIX}"
        )


def _used_textures(path: Path, text: str, lib: Path, materials: dict) -> dict[str, Path]:
    """The ``map_Kd`` files of the materials the OBJ uses (name -> path), each checked to be a readable image of
    at most ``images.MAX_IMAGE_PIXELS`` pixels; one-line ValueErrors for faces without a material."""
    used = list(dict.fromkeys(_statements(text, "usemtl")))
    first_face = re.search(r"^[ \t]*f[ \t]", text, re.M)
    first_use = re.search(r"^[ \t]*usemtl[ \t]", text, re.M)
    if first_face and (first_use is None or first_face.start() < first_use.start()):
        which = "its faces" if first_use is None else "the faces before its first usemtl line"
        raise ParameterError(
            f"{path} gives {which} no material ({lib.name} defines {_listed(materials)}): add a line "
            f"'usemtl NAME' before them, or {FIX}"
        )
    for m in used:
        if m not in materials:
            raise ParameterError(
                f"{path} uses material {m} (usemtl), which {lib} does not define (it defines "
                f"{_listed(materials)}): rename one of them, or {FIX}"
            )
    textures = {}
    for m in used:
        if not materials[m]:
            continue
        tname, tex = _named_file(materials[m], lib.parent)
        if not tex.is_file():
            raise ParameterError(
                f"{lib} names texture {tname}, which does not exist in {lib.parent}: put it there, or {FIX}"
            )
        try:
            with open_image(tex, f"texture {tex} (map_Kd of material {m} in {lib.name})", decode=False):
                textures[m] = tex
        except ImageTooLargeError as exc:
            raise ParameterError(f"{exc}, or {FIX}") from None
        except ImageError as exc:
            raise ParameterError(f"{exc}; fix the map_Kd line or the image, or {FIX}") from None
    return textures


@dataclass(frozen=True)
class Resolved:
    """What trimesh made of a mesh file's materials (``check_resolved``): ``placeholder`` some face group of an OBJ
    got trimesh's grey placeholder texture (not a colour of the file: the caller ignores the texture); ``names``
    the file names of the textures the mesh uses, comma-separated ("" for embedded ones); ``alpha`` whether one of
    them has an alpha channel (an atlas trimesh packs from several has one for its padding, which is no alpha of
    the file's)."""

    placeholder: bool = False
    names: str = ""
    alpha: bool = False


def has_alpha(img) -> bool:
    """Whether a PIL image carries an alpha channel (RGBA, LA, PA, or a palette with a transparent entry)."""
    return img.mode in ("RGBA", "LA", "PA") or (img.mode == "P" and "transparency" in img.info)


def _image(mat):
    img = getattr(mat, "image", None)
    return getattr(mat, "baseColorTexture", None) if img is None else img


def check_resolved(scene, source: str, obj: ObjMaterials | None, accept: bool = False) -> Resolved:
    """What trimesh made of a mesh file's materials (``scene``: its ``trimesh.Scene`` before the geometries are
    joined; ``Resolved``). One-line ValueError, unless ``accept`` (``texture`` or ``constant_color`` given), for a
    placeholder of an OBJ that names a material library and for a used material's texture that trimesh could not
    read."""
    lost, total, names, alpha = 0, 0, [], False
    for geom in scene.geometry.values():
        total += len(getattr(geom, "faces", ()))
        mat = getattr(getattr(geom, "visual", None), "material", None)
        img = _image(mat)
        wanted = obj.textures.get(getattr(mat, "name", None)) if obj is not None else None
        if img is None and wanted is not None and not accept:
            raise ParameterError(
                f"{source}: the mesh reader could not read texture {wanted} of material {mat.name} (map_Kd "
                f"options such as -s are not supported): write the map_Kd line as 'map_Kd FILE', or {FIX}"
            )
        if img is None:
            continue
        file_path = img.info.get("file_path")
        if obj is not None and file_path is None:
            lost += len(geom.faces)
            continue
        alpha |= has_alpha(img)
        if file_path:
            names.append(Path(str(file_path).replace("\\", "/")).name)
    if lost and obj.mtllibs and not accept:
        raise ParameterError(
            f"{source}: {lost} of its {total} faces have no material the mesh reader could resolve (it would give "
            f"them a grey placeholder texture): check the mtllib and usemtl lines, or {FIX}"
        )
    return Resolved(lost > 0, ", ".join(sorted(set(names))), alpha)


def srgb_textures(scene) -> tuple[str, ...]:
    """Replace, in place, every material texture of ``scene`` (a ``trimesh.Scene`` before its geometries are
    joined, after ``check_resolved``) that carries a non-sRGB RGB ICC profile by its sRGB conversion, so that the
    joined mesh's texture (an atlas where there are several) holds sRGB numbers. Returns the converted profiles'
    descriptions, sorted and without repeats. One-line ValueError for an unreadable profile or texture."""
    from ...images import check_pixels, decode_pixels
    from ..picture import rgb_profile, rgb_to_srgb

    converted = set()
    for geom in scene.geometry.values():
        mat = getattr(getattr(geom, "visual", None), "material", None)
        img = _image(mat)
        if img is None:
            continue
        name = f"texture {img.info.get('file_path') or '(embedded)'}"
        profile = rgb_profile(img, name)
        if profile is None:
            continue
        check_pixels(img.size, name)
        decode_pixels(img, name)
        out = rgb_to_srgb(img, name)
        out.info["file_path"] = img.info.get("file_path")
        setattr(mat, "image" if getattr(mat, "image", None) is not None else "baseColorTexture", out)
        converted.add(profile)
    return tuple(sorted(converted))


def uniform_tiles(scene, size: int = 8) -> None:
    """Give every untextured material of an OBJ with several materials a uniform ``size`` x ``size`` image of its
    colour (Kd), in place. trimesh packs the materials of a mesh with several into one atlas, an untextured one as
    a tile of a few pixels without padding whose colour the bilinear look-up blends with the atlas's transparent
    black around it (a blue Kd came out 25 % darker on some faces); an image is packed like a texture, padded."""
    from PIL import Image
    from trimesh.visual.material import SimpleMaterial

    geoms = list(scene.geometry.values())
    if len(geoms) < 2:
        return
    for g in geoms:
        mat = getattr(g.visual, "material", None)
        if type(mat) is SimpleMaterial and mat.image is None and getattr(g.visual, "uv", None) is not None:
            colour = tuple(int(v) for v in np.asarray(mat.main_color)[:3])
            g.visual.material = SimpleMaterial(
                image=Image.new("RGB", (size, size), colour), diffuse=mat.diffuse, name=mat.name
            )


def load_texture(path):
    """``texture``, an image file: (PIL RGB image of the sRGB colours, (H, W) float32 alpha or None where opaque,
    the description of the ICC profile it was converted from or None). One-line ValueError
    (``images.ImageError``) for a missing, unreadable or too large file."""
    from PIL import Image

    from ..picture import picture_rgba, rgb_profile

    with open_image(path, f"texture {path}") as im:
        profile = rgb_profile(im, f"texture {path}")
        rgba = picture_rgba(im, f"texture {path}")
    rgb = Image.fromarray(np.round(rgba[..., :3] * 255).astype(np.uint8), "RGB")
    alpha = rgba[..., 3] if np.any(rgba[..., 3] < 1) else None
    return rgb, alpha, profile


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
        profile = f", converted to sRGB from ICC profile {', '.join(mesh.texture_profiles)}"
        profile = profile if mesh.texture_profiles else ""
        return f"texture {mesh.texture_name or '(embedded)'} ({w} x {h} px{alpha}{profile})"
    if src in ("vertex", "face"):
        return f"{src} colours"
    return f"constant colour {_hex(mesh.color)}"
