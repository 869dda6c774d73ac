"""Textured meshes: load them, voxelize them into the renderer's inputs, bake results back for viewing.

Conventions (docs/conventions.md): arrays are (z, y, x[, c]); positions, normals and ``voxel_mm`` are (x, y, z)
in mm; colours are linear RGB inside, sRGB in files and textures.

Up axis: mesh files are taken as **+y up** (the OBJ and glTF convention; pass ``up="z"`` for z-up files such as
many scans). ``load_mesh`` rotates the up axis onto our +z ((x, y, z) -> (x, -z, y), a proper rotation, so the
winding and the texture are unchanged), scales, and places the object on z = 0 centred on x = y = 0.

Texture seams duplicate vertices; the mesh therefore keeps two views of one face list: ``vertices``/``faces``
(with ``uv``, for colour look-ups) and ``solid_vertices``/``solid_faces`` (vertices merged by position, for
topology, distances and winding numbers). Both list the same faces in the same order.
"""
from __future__ import annotations

import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw
from scipy import ndimage, sparse
from scipy.spatial import cKDTree

from .volume import FACE_NORMALS, Texels, atomic_write_bytes

DEFAULT_VOXEL_MM = 25.4 / 300
_CHUNK = 1 << 19  # query points per libigl call (bounds the temporary memory to ~50 MB)


# (loss.py has float64, unclipped public versions; these are float32 and clip to [0, 1] for colour files)
def _srgb_to_linear(c) -> np.ndarray:
    """sRGB-encoded values in [0, 1] -> linear RGB (float32, same shape)."""
    c = np.clip(np.asarray(c, np.float32), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def _linear_to_srgb(c) -> np.ndarray:
    """Linear RGB -> sRGB-encoded values in [0, 1] (float32, same shape; clipped to [0, 1] first)."""
    c = np.clip(np.asarray(c, np.float32), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055).astype(np.float32)


def _to_u8(c_linear) -> np.ndarray:
    return np.round(_linear_to_srgb(c_linear) * 255).astype(np.uint8)


# --------------------------------------------------------------------------------------------- the mesh
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

    @property
    def color_source(self) -> str:
        if self.texture is not None and self.uv is not None:
            return "texture"
        return "vertex" if self.vertex_colors is not None else "face" if self.face_colors is not None \
            else "constant"

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
            uv = np.einsum("nk,nkj->nj", bary, self.uv[self.faces[fi]])
            tex = np.asarray(self.texture.convert("RGB"), np.float32) / 255.0
            return _sample_bilinear(tex, uv) * np.asarray(self.tint, np.float32)
        if src == "vertex":
            return _srgb_to_linear(np.einsum("nk,nkj->nj", bary, self.vertex_colors[self.faces[fi]]))
        if src == "face":
            return _srgb_to_linear(self.face_colors[fi])
        return np.broadcast_to(_srgb_to_linear(self.color), (len(fi), 3)).copy()


def _sample_bilinear(tex: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear look-up of an sRGB texture (H, W, 3) float in [0, 1] at uv (n, 2), v up, wrap mode repeat;
    interpolates the sRGB values, then decodes: returns linear RGB (n, 3) float32."""
    h, w = tex.shape[:2]
    x = uv[:, 0] * w - 0.5
    y = (1.0 - uv[:, 1]) * h - 0.5  # image row 0 is the top, v = 0 the bottom
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, y0 = x0.astype(np.int64) % w, y0.astype(np.int64) % h
    x1, y1 = (x0 + 1) % w, (y0 + 1) % h
    c = (tex[y0, x0] * (1 - fx) * (1 - fy) + tex[y0, x1] * fx * (1 - fy)
         + tex[y1, x0] * (1 - fx) * fy + tex[y1, x1] * fx * fy)
    return _srgb_to_linear(c)


def load_mesh(path, height_mm: float | None = None, scale: float | None = None, up: str = "y") -> TexturedMesh:
    """Load an OBJ (+MTL +texture), glTF/GLB or PLY file; see ``mesh_from_trimesh`` for the arguments."""
    import trimesh
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"mesh file {path} does not exist")
    try:
        tm = trimesh.load(str(path), force="mesh", process=False)
    except Exception as exc:  # parser errors of any kind: one line
        raise ValueError(f"{path} is not a readable mesh ({type(exc).__name__}: {exc})") from None
    return mesh_from_trimesh(tm, height_mm=height_mm, scale=scale, up=up, source=str(path))


def mesh_from_trimesh(tm, height_mm: float | None = None, scale: float | None = None, up: str = "y",
                      source: str = "mesh") -> TexturedMesh:
    """Convert a ``trimesh.Trimesh`` (or Scene) into a solid, scaled, z-up ``TexturedMesh``.

    Exactly one of ``height_mm`` (the bounding-box extent along the up axis becomes this many mm) and ``scale``
    (mm per model unit). ``up`` is the file's up axis, "y" or "z". Raises ValueError for a mesh that does not
    enclose a solid (open sheet, large holes).
    """
    import trimesh
    if isinstance(tm, trimesh.Scene):
        tm = tm.to_geometry() if hasattr(tm, "to_geometry") else tm.dump(concatenate=True)
    if not isinstance(tm, trimesh.Trimesh):
        raise ValueError(f"{source}: holds no triangle mesh (got {type(tm).__name__})")
    if (height_mm is None) == (scale is None):
        raise ValueError("give exactly one of height_mm and scale")
    if up not in ("y", "z"):
        raise ValueError(f"up must be 'y' or 'z', got {up!r}")
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
        if not (np.isfinite(height_mm) and height_mm > 0):
            raise ValueError(f"height_mm must be positive, got {height_mm}")
        if hi[2] - lo[2] <= 0:
            raise ValueError(f"{source}: the mesh has zero height along its up axis ({up})")
        s = float(height_mm) / (hi[2] - lo[2])
    else:
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError(f"scale must be positive (mm per model unit), got {scale}")
        s = float(scale)
    verts = (verts - [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]]) * s

    mesh = TexturedMesh(verts, faces, verts, faces, mm_per_unit=s, source=source)
    _read_colours(tm, mesh)
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


def _read_colours(tm, mesh: TexturedMesh) -> None:
    vis = tm.visual
    kind = getattr(vis, "kind", None)
    if kind == "texture":
        mat = getattr(vis, "material", None)
        img = getattr(mat, "image", None) if mat is not None else None
        if img is None and mat is not None:
            img = getattr(mat, "baseColorTexture", None)
        main = np.asarray(getattr(mat, "main_color", [255] * 4), np.float32)[:3] / 255.0
        uv = getattr(vis, "uv", None)
        if img is not None and uv is not None and len(uv) == len(mesh.vertices):
            mesh.texture = img.convert("RGB")
            mesh.uv = np.array(uv, np.float64)[:, :2]
            if type(mat).__name__ == "PBRMaterial" and getattr(mat, "baseColorFactor", None) is not None:
                mesh.tint = np.asarray(mat.baseColorFactor, np.float32)[:3] / 255.0
        else:
            mesh.color = main.astype(np.float32)
    elif kind == "vertex":
        mesh.vertex_colors = np.asarray(vis.vertex_colors, np.float32)[:, :3] / 255.0
    elif kind == "face":
        mesh.face_colors = np.asarray(vis.face_colors, np.float32)[:, :3] / 255.0


def _fwn(v: np.ndarray, f: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Generalized winding number (libigl's fast approximation) at q (n, 3), chunked."""
    import igl
    out = np.empty(len(q), np.float64)
    for a in range(0, len(q), _CHUNK):
        out[a:a + _CHUNK] = igl.fast_winding_number(v, f, np.ascontiguousarray(q[a:a + _CHUNK], np.float64))
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
    w = _fwn(v, f, np.concatenate([c - eps * n, c + eps * n]))
    w_in, w_out = w[: len(c)], w[len(c):]
    good = (np.abs(w_in - 1) < tol) & (np.abs(w_out) < tol)
    frac = float(np.sum(area[ok] * good) / np.sum(area[ok]))
    if frac < need:
        raise ValueError(f"{mesh.source}: the mesh does not enclose a solid: only {frac:.0%} of its surface has "
                         f"winding number ~1 inside and ~0 outside (open sheet or large holes?)")


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


# --------------------------------------------------------------------------------------------- voxelize
@dataclass
class VoxelizedObject:
    """A mesh on the voxel grid.

    inside     (z, y, x) bool       voxel centre inside (generalized winding number > 0.5)
    sdf        (z, y, x) float32    signed distance of the voxel centre to the surface, mm, negative inside
                                    (never 0): exact where |sdf| < band_mm; beyond, correctly signed with
                                    |sdf| >= band_mm interpolated from exact distances every 8 voxels (off by
                                    at most 4 voxel diagonals, 0.59 mm at 300 DPI)
    voxel_mm   (3,) float64 (x, y, z);  origin_mm (3,) float64 (x, y, z) of voxel (0, 0, 0)'s low corner
    texels     Texels: surface voxels (inside, a 6-neighbour outside or off-grid) in C order of (z, y, x);
               face = the exposed face most aligned with the normal; normal = see ``voxelize``
    targets    (I, 3) float32 linear RGB of the closest surface point
    closest_mm (I, 3) float64 closest surface point (x, y, z) to each texel's voxel centre
    face_index (I,) int64 the triangle holding it (index into the mesh's faces)
    normals    (z, y, x, 3) float32 texel normals at surface voxels, zero elsewhere (for ``Volume.normals``)
    """

    inside: np.ndarray
    sdf: np.ndarray
    voxel_mm: np.ndarray
    origin_mm: np.ndarray
    texels: Texels
    targets: np.ndarray
    closest_mm: np.ndarray
    face_index: np.ndarray
    normals: np.ndarray
    band_mm: float

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(int(s) for s in self.inside.shape)

    def texel_centres_mm(self) -> np.ndarray:
        """(I, 3) float64 world positions (x, y, z, mm) of the texels' voxel centres."""
        return self.origin_mm + (self.texels.voxel[:, ::-1] + 0.5) * self.voxel_mm


_B1, _B2 = 8, 2  # coarse block and sub-block edge (voxels)


def _inside_sdf(vs, fs, origin, v, shape, band_mm):
    """inside (z, y, x) bool and sdf (z, y, x) float32 mm on the grid (see ``voxelize``), in two levels.

    A block whose centre is farther from the surface than from any of its voxel centres (h) holds voxel centres
    of one side only. Coarse 8^3 blocks beyond h + band: one winding-number query at the centre. In the others,
    2^3 sub-blocks: beyond h + band one query; beyond h one query for the sign plus exact per-voxel distances;
    else per-voxel winding numbers and distances. Beyond the band, |sdf| = max(band, trilinear interpolation of
    the exact distances at the coarse block centres), off by at most half a coarse block's diagonal."""
    import igl
    unsigned = igl.SignedDistanceType.SIGNED_DISTANCE_TYPE_UNSIGNED
    nb = -(-np.array(shape) // _B1)  # coarse blocks (z, y, x)
    full = tuple(int(k) * _B1 for k in nb)
    diag = np.linalg.norm(v)
    h1, h2 = 0.5 * (_B1 - 1) * diag, 0.5 * (_B2 - 1) * diag  # block centre to its farthest voxel centre

    def centres(idx_zyx, size):  # (n, 3) zyx block index -> (n, 3) xyz mm centres
        return np.ascontiguousarray(origin + (idx_zyx[:, ::-1] * size + 0.5 * size) * v)

    bidx = np.stack(np.meshgrid(*[np.arange(k) for k in nb], indexing="ij"), -1).reshape(-1, 3)
    d1 = np.sqrt(igl.point_mesh_squared_distance(centres(bidx, _B1), vs, fs)[0])
    near1 = d1 <= h1 + band_mm
    blk_in = np.zeros(len(bidx), bool)
    blk_in[~near1] = _fwn(vs, fs, centres(bidx[~near1], _B1)) > 0.5
    inside = np.repeat(np.repeat(np.repeat(blk_in.reshape(tuple(nb)), _B1, 0), _B1, 1), _B1, 2)
    sdf = np.where(inside, np.float32(-band_mm), np.float32(band_mm))
    flat_in, flat_sdf = inside.reshape(-1), sdf.reshape(-1)

    r = _B1 // _B2
    sub_local = np.stack(np.meshgrid(*[np.arange(r)] * 3, indexing="ij"), -1).reshape(-1, 3)
    vox_local = np.stack(np.meshgrid(*[np.arange(_B2)] * 3, indexing="ij"), -1).reshape(-1, 3)
    near_idx = np.flatnonzero(near1)
    step = max(1, _CHUNK // r**3)
    for a in range(0, len(near_idx), step):
        sub = (bidx[near_idx[a:a + step], None, :] * r + sub_local[None]).reshape(-1, 3)  # sub-block zyx
        d2 = igl.signed_distance(centres(sub, _B2), vs, fs, unsigned, -(h2 + band_mm), h2 + band_mm)[0]
        d2 = np.where(np.isnan(d2), np.inf, np.abs(d2))
        fine = d2 <= h2  # the surface may cross: per-voxel winding numbers
        one = ~fine
        sgn = np.zeros(len(sub), bool)
        sgn[one] = _fwn(vs, fs, centres(sub[one], _B2)) > 0.5
        need_d = d2 <= h2 + band_mm
        vox = (sub[need_d, None, :] * _B2 + vox_local[None]).reshape(-1, 3)
        lin = np.ravel_multi_index(tuple(vox.T), full)
        p = centres(vox, 1)
        d = igl.signed_distance(p, vs, fs, unsigned, -band_mm, band_mm)[0]
        d = np.where(np.isnan(d), band_mm, np.clip(np.abs(d), 1e-6, band_mm)).astype(np.float32)  # sdf != 0
        ins = np.repeat(sgn[need_d], _B2**3)
        fine_v = np.repeat(fine[need_d], _B2**3)
        ins[fine_v] = _fwn(vs, fs, p[fine_v]) > 0.5
        flat_in[lin] = ins
        flat_sdf[lin] = np.where(ins, -d, d)
        far_sub = sub[~need_d]  # whole sub-block beyond the band: one sign
        vox = (far_sub[:, None, :] * _B2 + vox_local[None]).reshape(-1, 3)
        lin = np.ravel_multi_index(tuple(vox.T), full)
        ins = np.repeat(sgn[~need_d], _B2**3)
        flat_in[lin] = ins
        flat_sdf[lin] = np.where(ins, -band_mm, band_mm)
    inside = np.ascontiguousarray(inside[: shape[0], : shape[1], : shape[2]])
    sdf = np.ascontiguousarray(sdf[: shape[0], : shape[1], : shape[2]])
    # far field: slab by slab (bounded memory), linear interpolation of the coarse-centre distances
    d1 = d1.reshape(tuple(nb)).astype(np.float32)
    slab = 16
    for k0 in range(0, int(nb[0]), slab):
        k1 = min(k0 + slab, int(nb[0]))
        c0, c1 = max(k0 - 1, 0), min(k1 + 1, int(nb[0]))
        z = ndimage.zoom(d1[c0:c1], _B1, order=1, mode="nearest", grid_mode=True, output=np.float32)
        z = z[(k0 - c0) * _B1:(k1 - c0) * _B1, : shape[1], : shape[2]]
        zs = slice(k0 * _B1, min(k1 * _B1, shape[0]))
        z = z[: zs.stop - zs.start]
        part = sdf[zs]
        far = np.abs(part) >= band_mm
        part[far] = np.copysign(np.maximum(z[far], band_mm), part[far])
    return inside, sdf



def voxelize(mesh: TexturedMesh, voxel_mm=DEFAULT_VOXEL_MM, pad: int = 1, band: float = 3.0,
             crease_deg: float = 60.0) -> VoxelizedObject:
    """Voxelize ``mesh`` on a grid of ``voxel_mm`` (scalar or (x, y, z)) with ``pad`` empty voxels around its
    bounding box (whose low corner is a voxel corner).

    Inside = generalized winding number > 0.5 at the voxel centre (robust to small holes and seams), queried
    per voxel only near the surface and once per block elsewhere (``_inside_sdf``); |sdf| is exact within
    ``band`` voxels (of the largest edge). Texel normals are the closest triangle's smooth normal
    (``corner_normals`` interpolated barycentrically at the closest point): more robust than the gradient of
    the voxel SDF, which is noisy at one-voxel resolution and undefined on thin parts. Targets: the closest
    point's colour (``TexturedMesh.colors_at``). Needs ~17 bytes per grid voxel (``normals`` takes 12).
    """
    import igl
    v = np.broadcast_to(np.asarray(voxel_mm, np.float64), (3,)).copy()
    if not (np.all(np.isfinite(v)) and np.all(v > 0)):
        raise ValueError(f"voxel_mm must be positive, got {voxel_mm}")
    if int(pad) != pad or pad < 0:
        raise ValueError(f"pad must be a non-negative integer, got {pad}")
    if not band >= 1:
        raise ValueError(f"band must be at least 1 voxel, got {band}")
    vs, fs = mesh.solid_vertices, mesh.solid_faces
    lo, hi = vs[fs].reshape(-1, 3).min(0), vs[fs].reshape(-1, 3).max(0)
    n_xyz = np.maximum(np.ceil((hi - lo) / v - 1e-9).astype(np.int64), 1) + 2 * int(pad)
    if np.prod(n_xyz) > 2**31:
        raise ValueError(f"grid {tuple(n_xyz[::-1])} (z, y, x) has more than 2^31 voxels; use larger voxels")
    origin = lo - pad * v
    shape = tuple(int(s) for s in n_xyz[::-1])
    band_mm = float(band * v.max())

    inside, sdf = _inside_sdf(vs, fs, origin, v, shape, band_mm)
    if not inside.any():
        raise ValueError(f"{mesh.source}: no voxel centre lies inside the mesh; the voxels are too coarse")

    # ---- texels: surface voxels, closest points, normals, faces, colours
    surface = inside & ~ndimage.binary_erosion(inside, ndimage.generate_binary_structure(3, 1), border_value=0)
    idx = np.argwhere(surface).astype(np.int32)  # C order of (z, y, x)
    centres = origin + (idx[:, ::-1] + 0.5) * v
    _, fi, closest = igl.point_mesh_squared_distance(centres, vs, fs)
    bary = _barycentric(vs[fs[fi]], closest)
    nrm = np.einsum("nk,nkj->nj", bary, corner_normals(vs, fs, crease_deg)[fi])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    normals = np.zeros(shape + (3,), np.float32)
    normals[idx[:, 0], idx[:, 1], idx[:, 2]] = nrm
    texels = Texels.from_normals(inside, normals)  # the same texels a saved volume gives back
    if not np.array_equal(texels.voxel, idx):
        raise RuntimeError("Texels.from_normals lists other surface voxels than voxelize")
    normals[idx[:, 0], idx[:, 1], idx[:, 2]] = texels.normal  # as re-normalised there
    return VoxelizedObject(inside=inside, sdf=sdf, voxel_mm=v, origin_mm=origin,
                           texels=texels, targets=mesh.colors_at(fi, bary),
                           closest_mm=closest, face_index=fi.astype(np.int64), normals=normals, band_mm=band_mm)


def _barycentric(tri: np.ndarray, p: np.ndarray) -> np.ndarray:
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


# --------------------------------------------------------------------------------------------- viewing
def _geometry(mesh) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(mesh, TexturedMesh):
        return mesh.solid_vertices, mesh.solid_faces
    return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)


def bake_vertex_colors(mesh, texel_pos_mm, texel_rgb_linear, k: int = 4, texel_normal=None):
    """A ``trimesh.Trimesh`` of ``mesh`` (a TexturedMesh: its seam-merged solid; or a Trimesh) whose vertex
    colours (sRGB uint8 RGBA) are the inverse-distance mean (in linear RGB) of the ``k`` texels nearest each
    vertex. texel_pos_mm (I, 3) mm (x, y, z), e.g. ``VoxelizedObject.closest_mm``; texel_rgb_linear (I, 3);
    texel_normal (I, 3) optional: texels facing away from the vertex normal are ignored (thin parts)."""
    import trimesh
    verts, faces = _geometry(mesh)
    pos = np.asarray(texel_pos_mm, np.float64).reshape(-1, 3)
    rgb = np.asarray(texel_rgb_linear, np.float32).reshape(-1, 3)
    if len(pos) != len(rgb) or len(pos) == 0:
        raise ValueError(f"need as many texel positions as colours (got {len(pos)} and {len(rgb)}), at least 1")
    k = int(min(k, len(pos)))
    dist, j = cKDTree(pos).query(verts, k=k)
    dist, j = dist.reshape(len(verts), k), j.reshape(len(verts), k)
    w = 1.0 / np.maximum(dist, 1e-6)
    if texel_normal is not None:
        vn = trimesh.Trimesh(verts, faces, process=False).vertex_normals
        facing = np.einsum("vj,vkj->vk", vn, np.asarray(texel_normal, np.float64)[j]) > 0
        w = np.where(facing.any(1, keepdims=True), w * facing, w)
    col = np.einsum("vk,vkc->vc", w, rgb[j]) / w.sum(1, keepdims=True)
    rgba = np.concatenate([_to_u8(col), np.full((len(verts), 1), 255, np.uint8)], 1)
    return trimesh.Trimesh(verts, faces, vertex_colors=rgba, process=False)


def write_glb(mesh_with_colors, path) -> None:
    """Write a coloured ``trimesh.Trimesh`` as binary glTF (atomically)."""
    atomic_write_bytes(path, mesh_with_colors.export(file_type="glb"))


def _vertex_rgb(colors, n: int) -> np.ndarray:
    """Per-vertex linear RGB (n, 3) from a float linear array, a uint8 sRGB array, or a coloured Trimesh."""
    if hasattr(colors, "visual"):
        colors = np.asarray(colors.visual.vertex_colors)
    c = np.asarray(colors)
    if c.ndim != 2 or len(c) != n or c.shape[1] not in (3, 4):
        raise ValueError(f"vertex colours must have shape ({n}, 3), got {c.shape}")
    return _srgb_to_linear(c[:, :3] / 255.0) if c.dtype == np.uint8 else np.asarray(c[:, :3], np.float32)


def _raster(verts, faces, colours, view_dir, size, radius, shade) -> np.ndarray:
    """Orthographic z-buffer render (size, size, 3) linear RGB, white background, Gouraud colours; colours is a
    list of (V, 3) arrays rendered with the same visibility -> (len(colours), size, size, 3)."""
    d = view_dir / np.linalg.norm(view_dir)
    right = np.cross(-d, [0.0, 0.0, 1.0])
    right = right / np.linalg.norm(right) if np.linalg.norm(right) > 1e-9 else np.array([1.0, 0, 0])
    upv = np.cross(right, -d)
    c = verts - 0.5 * (verts.min(0) + verts.max(0))
    sx = (c @ right / (2.1 * radius) + 0.5) * size
    sy = (0.5 - c @ upv / (2.1 * radius)) * size  # image rows go down
    depth = c @ d
    p = np.stack([sx, sy], 1)[faces]  # (F, 3, 2)
    area = (p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1])
    keep = area < -1e-12  # front-facing (counter-clockwise on screen with y down flips the sign)
    f, p, area = faces[keep], p[keep], area[keep]
    x0 = np.clip(np.floor(p[..., 0].min(1) - 0.5), 0, size - 1).astype(np.int64)
    x1 = np.clip(np.ceil(p[..., 0].max(1) - 0.5), 0, size - 1).astype(np.int64)
    y0 = np.clip(np.floor(p[..., 1].min(1) - 0.5), 0, size - 1).astype(np.int64)
    y1 = np.clip(np.ceil(p[..., 1].max(1) - 0.5), 0, size - 1).astype(np.int64)
    wdt, cnt = x1 - x0 + 1, (x1 - x0 + 1) * (y1 - y0 + 1)
    t = np.repeat(np.arange(len(f)), cnt)
    loc = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    px, py = x0[t] + loc % wdt[t], y0[t] + loc // wdt[t]
    q = np.stack([px + 0.5, py + 0.5], 1)
    a, bb, cc = p[t, 0], p[t, 1], p[t, 2]

    def edge(u, w_, z):
        return (w_[:, 0] - u[:, 0]) * (z[:, 1] - u[:, 1]) - (z[:, 0] - u[:, 0]) * (w_[:, 1] - u[:, 1])
    l0, l1, l2 = edge(bb, cc, q) / area[t], edge(cc, a, q) / area[t], edge(a, bb, q) / area[t]
    hit = (l0 >= -1e-9) & (l1 >= -1e-9) & (l2 >= -1e-9)
    t, px, py, lam = t[hit], px[hit], py[hit], np.stack([l0, l1, l2], 1)[hit]
    z = np.einsum("nk,nk->n", lam, depth[f[t]])
    pid = py * size + px
    order = np.lexsort((-z, pid))
    first = order[np.r_[True, pid[order][1:] != pid[order][:-1]]]
    import trimesh
    vn = trimesh.Trimesh(verts, faces, process=False).vertex_normals
    light = (1 - shade) + shade * np.clip(vn @ d, 0, 1)
    out = np.ones((len(colours), size * size, 3), np.float32)
    for i, col in enumerate(colours):
        val = col * light[:, None]
        out[i, pid[first]] = np.einsum("nk,nkc->nc", lam[first], val[f[t[first]]])
    return out.reshape(len(colours), size, size, 3)


def render_views(mesh, colors_target, colors_pred, path_png, views: int = 3, size: int = 320,
                 elevation_deg: float = 20.0, shade: float = 0.35, supersample: int = 2) -> None:
    """Write a PNG (2*size rows x views*size columns): row 0 the target, row 1 the prediction, one column per
    view (cameras spread evenly in azimuth, the first at (-x, -y), i.e. 45 deg left of the front view from -y,
    raised by ``elevation_deg``), orthographic, white background.

    mesh: TexturedMesh (its seam-merged solid is drawn) or Trimesh. colors_*: per-vertex colours of that mesh:
    float (V, 3) linear RGB, uint8 (V, 3|4) sRGB, or a Trimesh carrying vertex colours (e.g. from
    ``bake_vertex_colors``). ``shade`` in [0, 1] darkens by a head-light (1 - shade + shade cos) for shape cues.
    CPU only: a vectorised numpy z-buffer rasterizer with Gouraud colours, supersampled ``supersample``^2.
    """
    if views < 1 or size < 8:
        raise ValueError(f"need views >= 1 and size >= 8, got {views}, {size}")
    verts, faces = _geometry(mesh)
    cols = [_vertex_rgb(colors_target, len(verts)), _vertex_rgb(colors_pred, len(verts))]
    radius = np.linalg.norm(verts - 0.5 * (verts.min(0) + verts.max(0)), axis=1).max()
    s = int(size * supersample)
    el = np.radians(elevation_deg)
    tiles = []
    for i in range(views):
        az = np.radians(-45.0 + 360.0 * i / views)
        view_dir = np.array([np.sin(az) * np.cos(el), -np.cos(az) * np.cos(el), np.sin(el)])
        img = _raster(verts, faces, cols, view_dir, s, radius, shade)
        tiles.append(img.reshape(2, size, supersample, size, supersample, 3).mean((2, 4)))
    grid = np.concatenate([np.concatenate([t[r] for t in tiles], 1) for r in range(2)], 0)
    im = Image.fromarray(_to_u8(grid))
    draw = ImageDraw.Draw(im)
    for r, label in enumerate(("target", "prediction")):
        draw.text((4, r * size + 4), label, fill=(0, 0, 0))
    buf = io.BytesIO()
    im.save(buf, format="PNG")
    atomic_write_bytes(path_png, buf.getvalue())
