"""Textured meshes: load them (trimesh), check they enclose a solid, colours at surface points.

Conventions (docs/conventions.md): positions and normals are (x, y, z) in mm; colours are linear RGB inside,
sRGB in files and textures.

Up axis: mesh files are taken as **+y up** (the OBJ and glTF convention; pass ``up="z"`` for z-up files such as
many scans). ``load_mesh`` rotates the up axis onto our +z ((x, y, z) -> (x, -z, y), a proper rotation, so the
winding and the texture are unchanged), scales, and places the object on z = 0 centred on x = y = 0.

Texture seams duplicate vertices; the mesh therefore keeps two views of one face list: ``vertices``/``faces``
(with ``uv``, for colour look-ups) and ``solid_vertices``/``solid_faces`` (vertices merged by position, for
topology, distances and winding numbers). Both list the same faces in the same order.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PIL import Image
from scipy import sparse

from ...color import from_srgb8
from ...errors import ParameterError
from ...images import check_pixels, decode_pixels
from ..picture import picture_rgba
from .checks import check_placement
from .source import (
    MATERIAL_COLOURS,
    check_colour_source,
    check_obj_materials,
    check_resolved,
    has_alpha,
    load_texture,
    srgb_textures,
    uniform_tiles,
)

_CHUNK = 1 << 19  # query points per libigl call (bounds the temporary memory to ~50 MB)


@dataclass
class TexturedMesh:
    """A triangle mesh in mm with its surface colour.

    vertices        (V, 3) float64 mm (x, y, z), z up, standing on z = 0
    faces           (F, 3) int64 into ``vertices`` (texture seams duplicate vertices), outward winding
    solid_vertices  (W, 3) float64 mm, the vertices merged by position
    solid_faces     (F, 3) int64 into ``solid_vertices``; face f of both lists is the same triangle
    Colour, the first that is set: ``texture`` (PIL RGB, sRGB) looked up through ``uv`` (V, 2) float64 (OBJ
    convention: v = 0 at the image's bottom row; wrap mode repeat) and multiplied by ``tint`` (3,) linear (glTF
    baseColorFactor; 1 for OBJ, whose Kd is ignored when a map_Kd exists); ``vertex_colors`` (V, 3) float32
    sRGB; ``face_colors`` (F, 3) float32 sRGB; else the constant ``color`` (3,) float32 sRGB.
    ``texture_alpha``: the texture's alpha channel (H, W) float32 in [0, 1] if it has one (translucency);
    ``texture_name``: the texture's file name(s) where the file names them ("" for embedded textures);
    ``texture_profiles``: the descriptions of the non-sRGB ICC profiles its texture was converted from;
    ``warnings``: one-line notes about the input that the run logs (``_check_solid``: small holes).
    """

    vertices: np.ndarray
    faces: np.ndarray
    solid_vertices: np.ndarray
    solid_faces: np.ndarray
    uv: np.ndarray | None = None
    texture: Image.Image | None = None
    tint: np.ndarray = field(default_factory=lambda: np.ones(3, np.float32))
    vertex_colors: np.ndarray | None = None
    face_colors: np.ndarray | None = None
    color: np.ndarray = field(default_factory=lambda: np.ones(3, np.float32))
    mm_per_unit: float = 1.0
    source: str = ""
    texture_alpha: np.ndarray | None = None
    texture_name: str = ""
    texture_profiles: tuple = ()
    warnings: list = field(default_factory=list)  # one-line notes for the log (e.g. small holes closed over)

    @property
    def color_source(self) -> str:
        """ "texture", "vertex", "face" or "constant": the first colour the mesh has (``describe_colour_source``
        names it for people)."""
        if self.texture is not None and self.uv is not None:
            return "texture"
        return "vertex" if self.vertex_colors is not None else "face" if self.face_colors is not None else "constant"

    def mean_thickness_mm(self) -> float:
        """The enclosed volume over the surface area, in mm: the solid's thickness scale (a sphere of radius r:
        r / 3; a large plate of thickness t: t / 2). The volume by the divergence theorem over the outward-wound
        triangles (exact for a closed surface; texture seams duplicate vertices but not geometry)."""
        tri = self.vertices[self.faces]
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        area = 0.5 * float(np.linalg.norm(cross, axis=1).sum())
        volume = abs(float(np.einsum("ij,ij->", tri[:, 0], cross))) / 6.0
        return volume / area if area > 0 else 0.0

    def solid_trimesh(self):
        """The seam-merged mesh as a ``trimesh.Trimesh`` (no colours)."""
        import trimesh

        return trimesh.Trimesh(self.solid_vertices, self.solid_faces, process=False)

    def colors_at(self, face_index: np.ndarray, bary: np.ndarray) -> np.ndarray:
        """Linear RGB (n, 3) float32 of the surface points given by face (n,) and barycentrics (n, 3)."""
        fi = np.asarray(face_index, np.int64)
        bary = np.asarray(bary, np.float64)
        src = self.color_source
        if src == "texture":
            tex = np.asarray(self.texture.convert("RGB"), np.float32) / 255.0
            return from_srgb8(self.sample_at(tex, fi, bary)) * np.asarray(self.tint, np.float32)
        if src == "vertex":
            return from_srgb8(np.einsum("nk,nkj->nj", bary, self.vertex_colors[self.faces[fi]]))
        if src == "face":
            return from_srgb8(self.face_colors[fi])
        return np.broadcast_to(from_srgb8(self.color), (len(fi), 3)).copy()

    def sample_at(self, image: np.ndarray, face_index: np.ndarray, bary: np.ndarray) -> np.ndarray:
        """Bilinear look-up of an image in texture space (H, W[, C]) at surface points (face (n,), barycentrics
        (n, 3)) through ``uv``: (n[, C]) values as stored (no colour decoding)."""
        fi = np.asarray(face_index, np.int64)
        uv = np.einsum("nk,nkj->nj", np.asarray(bary, np.float64), self.uv[self.faces[fi]])
        return _bilinear(np.asarray(image, np.float32), uv)

    def alpha_at(self, face_index: np.ndarray, bary: np.ndarray) -> np.ndarray:
        """The texture's alpha (n,) float32 at surface points (1 where the texture has no alpha channel)."""
        if self.texture_alpha is None or self.uv is None:
            return np.ones(len(face_index), np.float32)
        return self.sample_at(self.texture_alpha, face_index, bary)


def _bilinear(tex: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear look-up of an image (H, W[, C]) at uv (n, 2), v up (v = 0 the bottom row), wrap mode repeat."""
    h, w = tex.shape[:2]
    x = uv[:, 0] * w - 0.5
    y = (1.0 - uv[:, 1]) * h - 0.5  # image row 0 is the top, v = 0 the bottom
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, y0 = x0.astype(np.int64) % w, y0.astype(np.int64) % h
    x1, y1 = (x0 + 1) % w, (y0 + 1) % h
    if tex.ndim == 2:
        fx, fy = fx[:, 0], fy[:, 0]
    return (
        tex[y0, x0] * (1 - fx) * (1 - fy)
        + tex[y0, x1] * fx * (1 - fy)
        + tex[y1, x0] * (1 - fx) * fy
        + tex[y1, x1] * fx * fy
    )


def load_mesh(
    path,
    height_mm: float | None = None,
    scale: float | None = None,
    up: str = "y",
    texture=None,
    constant_color: bool = False,
) -> TexturedMesh:
    """Load an OBJ (+MTL +texture), glTF/GLB or PLY file; see ``mesh_from_trimesh`` for the placement arguments.

    The colour source is checked (``source``): a missing material library or texture, a texture without uv
    coordinates, or (unless ``constant_color``) a constant target raise a one-line ValueError. ``texture``: an
    image file that replaces the file's texture (looked up through the mesh's uv coordinates)."""
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"mesh file {path} does not exist")
    accept = texture is not None or constant_color
    obj = check_obj_materials(path, accept) if path.suffix.lower() == ".obj" else None
    override = load_texture(texture) if texture is not None else None
    scene = _read(trimesh.load_scene, path, str(path), process=False)
    resolved = check_resolved(scene, str(path), obj, accept)
    profiles = srgb_textures(scene)
    if obj is not None:
        uniform_tiles(scene)
    tm = _read(scene.to_mesh, path)
    # trimesh's grey placeholder texture (an OBJ without a material library, or faces whose material it could not
    # resolve, accepted with `texture` or `constant_color`) is not a colour of the file.
    placeholder = obj is not None and (not obj.mtllibs or resolved.placeholder)
    mesh = mesh_from_trimesh(tm, height_mm=height_mm, scale=scale, up=up, source=str(path), placeholder=placeholder)
    if obj is not None and not obj.has_uv:  # an OBJ without vt lines: uv trimesh made for an atlas are not the file's
        mesh.uv = None
    if not resolved.alpha:  # an atlas's padding is transparent: no alpha of the file's
        mesh.texture_alpha = None
    if override is not None:
        if mesh.uv is None:
            raise ParameterError(f"`texture` {texture}: {path} has no texture coordinates (no uv / vt) to look it up")
        mesh.texture, mesh.texture_alpha, profile = override
        mesh.tint = np.ones(3, np.float32)
        mesh.texture_name = str(texture)
        mesh.texture_profiles = (profile,) if profile else ()
    elif mesh.texture is not None:
        # no file behind the atlas: the tiles of several untextured materials
        mesh.texture_name = resolved.names or MATERIAL_COLOURS
        mesh.texture_profiles = profiles
    if constant_color and mesh.uv is None:  # a texture that cannot be looked up: the accepted constant instead
        mesh.texture, mesh.texture_alpha = None, None
    check_colour_source(mesh, constant_color, texture_named=obj is not None and bool(obj.textures))
    return mesh


def _read(call, path: Path, *args, **kwargs):
    """``call(*args, **kwargs)`` of trimesh's reader; its errors of any kind as one line naming ``path``. Pillow's
    warning for a texture of more than its pixel limit is silenced: the texture is refused, with its name, before
    it is decoded (``_read_colours``)."""
    from PIL import Image

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            return call(*args, **kwargs)
    except Exception as exc:  # parser errors of any kind: one line
        text = " ".join(str(exc).split())
        raise ValueError(f"{path} is not a readable mesh ({type(exc).__name__}: {text})") from None


def mesh_from_trimesh(
    tm,
    height_mm: float | None = None,
    scale: float | None = None,
    up: str = "y",
    source: str = "mesh",
    placeholder: bool = False,
) -> TexturedMesh:
    """Convert a ``trimesh.Trimesh`` (or Scene) into a solid, scaled, z-up ``TexturedMesh``.

    Exactly one of ``height_mm`` (the bounding-box extent along the up axis becomes this many mm) and ``scale``
    (mm per model unit). ``up`` is the file's up axis, "y" or "z". Raises ValueError for a mesh that does not
    enclose a solid (open sheet, large holes). ``placeholder``: the file's texture image is trimesh's stand-in
    for a missing material (an OBJ without ``mtllib``), not a colour; it is ignored (the uv coordinates are kept).
    """
    import trimesh

    if isinstance(tm, trimesh.Scene):
        tm = tm.to_geometry() if hasattr(tm, "to_geometry") else tm.dump(concatenate=True)
    if not isinstance(tm, trimesh.Trimesh):
        raise ValueError(f"{source}: holds no triangle mesh (got {type(tm).__name__})")
    check_placement(height_mm, scale, up)
    verts = np.array(tm.vertices, np.float64).reshape(-1, 3)
    faces = np.array(tm.faces, np.int64).reshape(-1, 3)
    if len(faces) == 0:
        raise ValueError(f"{source}: the mesh has no triangles")
    if not np.all(np.isfinite(verts)):
        raise ValueError(f"{source}: vertex positions contain NaN or infinite values")
    if up == "y":
        verts = np.stack([verts[:, 0], -verts[:, 2], verts[:, 1]], axis=1)
    lo, hi = verts[faces].reshape(-1, 3).min(0), verts[faces].reshape(-1, 3).max(0)
    if height_mm is not None:
        if hi[2] - lo[2] <= 0:
            raise ValueError(f"{source}: the mesh has zero height along its up axis ({up})")
        s = float(height_mm) / (hi[2] - lo[2])
    else:
        s = float(scale)
    verts = (verts - [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]]) * s

    mesh = TexturedMesh(verts, faces, verts, faces, mm_per_unit=s, source=source)
    _read_colours(tm, mesh, placeholder)
    solid = trimesh.Trimesh(verts, faces, process=False)
    solid.merge_vertices(merge_tex=True, merge_norm=True)
    sf = np.array(solid.faces, np.int64)
    if not solid.is_winding_consistent:  # repair, then flip the same faces of the UV'd list
        old = sf.copy()
        trimesh.repair.fix_winding(solid)
        sf = np.array(solid.faces, np.int64)
        flip = np.any(sf != old, axis=1)
        mesh.faces = faces.copy()
        mesh.faces[flip] = faces[flip, ::-1]
    sv = np.array(solid.vertices, np.float64)
    tri = sv[sf]
    if np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() < 0:  # inside-out
        sf, mesh.faces = sf[:, ::-1].copy(), mesh.faces[:, ::-1].copy()
    mesh.solid_vertices, mesh.solid_faces = sv, np.ascontiguousarray(sf)
    _check_solid(mesh)
    return mesh


def _read_colours(tm, mesh: TexturedMesh, placeholder: bool = False) -> None:
    vis = tm.visual
    kind = getattr(vis, "kind", None)
    if kind == "texture":
        mat = getattr(vis, "material", None)
        img = getattr(mat, "image", None) if mat is not None else None
        if img is None and mat is not None:
            img = getattr(mat, "baseColorTexture", None)
        main = np.asarray(getattr(mat, "main_color", [255] * 4), np.float32)[:3] / 255.0
        uv = getattr(vis, "uv", None)
        if uv is not None and len(uv) == len(mesh.vertices):
            mesh.uv = np.array(uv, np.float64)[:, :2]
        if placeholder:
            return  # constant white: the caller refuses it unless a constant colour is wanted
        mesh.color = main.astype(np.float32)  # the material's colour, the target where no texture can be used
        if img is not None:
            fp = img.info.get("file_path")
            name = f"texture {fp} of {mesh.source}" if fp else f"the texture of {mesh.source}"
            check_pixels(img.size, name)  # trimesh opened it; nothing is decoded yet
            decode_pixels(img, name)
            rgba = picture_rgba(img, name)
            mesh.texture = Image.fromarray(np.round(rgba[..., :3] * 255).astype(np.uint8), "RGB")
            if has_alpha(img):
                mesh.texture_alpha = rgba[..., 3].copy()
            if type(mat).__name__ == "PBRMaterial" and getattr(mat, "baseColorFactor", None) is not None:
                mesh.tint = np.asarray(mat.baseColorFactor, np.float32)[:3] / 255.0
    elif kind == "vertex":
        mesh.vertex_colors = np.asarray(vis.vertex_colors, np.float32)[:, :3] / 255.0
    elif kind == "face":
        mesh.face_colors = np.asarray(vis.face_colors, np.float32)[:, :3] / 255.0


def winding_number(v: np.ndarray, f: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Generalized winding number (libigl's fast approximation) at q (n, 3), chunked."""
    import igl

    out = np.empty(len(q), np.float64)
    for a in range(0, len(q), _CHUNK):
        out[a : a + _CHUNK] = igl.fast_winding_number(v, f, np.ascontiguousarray(q[a : a + _CHUNK], np.float64))
    return out


def _check_solid(mesh: TexturedMesh, tol: float = 0.15, need: float = 0.9) -> None:
    """ValueError unless >= ``need`` of the surface area separates winding number ~1 (inside, just below the
    face) from ~0 (outside, just above): an open sheet gives ~0.5 on both sides, large holes pull it off."""
    v, f = mesh.solid_vertices, mesh.solid_faces
    tri = v[f]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    ok = area > 0
    if not ok.any():
        raise ValueError(f"{mesh.source}: every triangle is degenerate (zero area)")
    n = cross[ok] / (2 * area[ok, None])
    eps = (0.01 * np.sqrt(area[ok]))[:, None]
    c = tri[ok].mean(1)
    w = winding_number(v, f, np.concatenate([c - eps * n, c + eps * n]))
    w_in, w_out = w[: len(c)], w[len(c) :]
    good = (np.abs(w_in - 1) < tol) & (np.abs(w_out) < tol)
    frac = float(np.sum(area[ok] * good) / np.sum(area[ok]))
    if frac < need:
        raise ValueError(
            f"{mesh.source}: the mesh does not enclose a solid: only {frac:.0%} of its surface has "
            f"winding number ~1 inside and ~0 outside (open sheet or large holes?)"
        )
    edges = np.sort(f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, count = np.unique(edges, axis=0, return_counts=True)
    open_edges = int(np.sum(count == 1))
    if open_edges:
        mesh.warnings.append(
            f"{mesh.source}: the surface has {open_edges} open edges (holes); the inside is taken from winding "
            f"numbers ({frac:.1%} of the surface separates inside from outside), which closes small holes over: "
            "check the mesh if that is not intended"
        )


def corner_normals(v: np.ndarray, f: np.ndarray, crease_deg: float = 60.0) -> np.ndarray:
    """Smooth shading normals per face corner, (F, 3, 3) float64 unit (x, y, z): the angle-weighted mean of
    the normals of the faces around the corner's vertex that lie within ``crease_deg`` of the face's own
    normal (so cube edges stay sharp and a sphere is smooth)."""
    import trimesh

    tri = v[f]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
    ang = np.nan_to_num(trimesh.triangles.angles(tri)).ravel()
    nc = f.size
    cf = np.repeat(np.arange(len(f)), 3)
    inc = sparse.csr_matrix((np.ones(nc, np.float32), (np.arange(nc), f.ravel())), shape=(nc, len(v)))
    pairs = (inc @ inc.T).tocoo()  # corners sharing a vertex (including each with itself)
    r, c = pairs.row, pairs.col
    keep = np.einsum("ij,ij->i", fn[cf[r]], fn[cf[c]]) >= np.cos(np.radians(crease_deg))
    r, c = r[keep], c[keep]
    acc = np.stack([np.bincount(r, ang[c] * fn[cf[c], k], minlength=nc) for k in range(3)], 1)
    norm = np.linalg.norm(acc, axis=1, keepdims=True)
    acc = np.where(norm > 1e-12, acc / np.maximum(norm, 1e-300), fn[cf])
    return acc.reshape(-1, 3, 3)


def barycentric(tri: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (n, 3) of points p (n, 3) on triangles tri (n, 3, 3); clipped and normalised
    (degenerate triangles get the first vertex)."""
    e0, e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], p - tri[:, 0]
    d00, d01, d11 = (e0 * e0).sum(1), (e0 * e1).sum(1), (e1 * e1).sum(1)
    d20, d21 = (e2 * e0).sum(1), (e2 * e1).sum(1)
    den = d00 * d11 - d01 * d01
    ok = den > 1e-30 * np.maximum(d00 * d11, 1e-300)
    den = np.where(ok, den, 1.0)
    b1 = np.where(ok, (d11 * d20 - d01 * d21) / den, 0.0)
    b2 = np.where(ok, (d00 * d21 - d01 * d20) / den, 0.0)
    bary = np.clip(np.stack([1 - b1 - b2, b1, b2], 1), 0, None)
    return bary / np.maximum(bary.sum(1, keepdims=True), 1e-300)
