"""Per-texel colours as pictures for the soft-proof page: texture atlases of a mesh, face pictures of a slab, and
the ΔE76 heat maps of both.

A mesh's atlas does not use the mesh's own UV map (which may overlap, e.g. mirrored halves, and would then show
two places of the print in one pixel): every triangle gets its own half of a square cell of ``cell`` x ``cell``
pixels in a grid of cells, and each atlas pixel shows the scene texel nearest to the surface point it covers
(among the texels facing the same way as the triangle, so that the two sides of a thin part stay apart). That is
what the printed surface shows at that point: a texel is one surface voxel of the optimisation grid.
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np
from PIL import Image
from scipy.spatial import cKDTree

from ..color import to_srgb8
from ..scenes.mesh.load import corner_normals

ATLAS_MAX = 2048  # pixels per side of a mesh's atlas (larger objects are shown downsampled, and the page says so)
ATLAS_MIN = 1024  # at least this many pixels per side where the cells allow (a sharp picture when zoomed in)
MIN_CELL = 4  # pixels per side of one triangle pair's cell
MARGIN = 0.75  # pixels between a triangle's corner and its cell's border: linear filtering stays inside
HEAT_MIN_SCALE = 10.0  # ΔE76 at the top of the heat scale is at least this (a good result is not shown red)


@dataclass
class MeshAtlas:
    """A mesh laid out for the viewer: non-indexed triangles (3 corners per face).

    positions (3F, 3) float32 mm, centred on the bounding box's centre (z up); normals (3F, 3) float32 unit;
    uv (3F, 2) float32 in [0, 1] (v up, as WebGL samples it); size: pixels per side of the atlas; texel (size,
    size) int64: the scene texel each atlas pixel shows (row 0 = top = v 1), -1 for unused cells;
    pixel_mm: the surface length one atlas pixel spans, on average; texel_mm: the optimisation grid's voxel.
    """

    positions: np.ndarray
    normals: np.ndarray
    uv: np.ndarray
    size: int
    texel: np.ndarray
    pixel_mm: float
    texel_mm: float
    cell: int

    @property
    def grid(self) -> int:
        """Cells per side of the atlas."""
        return self.size // self.cell

    @property
    def pixels_per_texel(self) -> float:
        """Atlas pixels along one texel's side, on average (the page wants 2)."""
        return self.texel_mm / self.pixel_mm

    @property
    def downsampled(self) -> bool:
        """True when an atlas pixel is coarser than half a texel (the page then says so)."""
        return self.pixel_mm > 0.5 * self.texel_mm

    def picture(self, per_texel_rgb8: np.ndarray) -> np.ndarray:
        """(size, size, 3) uint8 of a per-texel (I, 3) uint8 colour; unused cells grey."""
        out = np.full((self.size, self.size, 3), 128, np.uint8)
        used = self.texel >= 0
        out[used] = per_texel_rgb8[self.texel[used]]
        return out


def mesh_atlas(vertices, faces, texel_pos_mm, texel_normal, voxel_mm: float, max_size: int = ATLAS_MAX) -> MeshAtlas:
    """Lay out a mesh (vertices (V, 3) mm, faces (F, 3)) and find the scene texel (positions (I, 3) mm on the
    surface, normals (I, 3)) under every atlas pixel. The cell size gives about two pixels per texel along each
    side where ``max_size`` allows."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    nf = len(f)
    if nf == 0:
        raise ValueError("the mesh has no triangles")
    grid = int(np.ceil(np.sqrt((nf + 1) // 2)))
    tri = v[f]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    edge_mm = float(np.sqrt(2.0 * area.mean()))  # side of a square holding two mean triangles
    margin = MARGIN
    want = max(np.ceil(2.0 * edge_mm / voxel_mm + 2 * margin), ATLAS_MIN // grid)
    cell = int(np.clip(want, MIN_CELL, max(MIN_CELL, max_size // grid)))
    if grid * cell > max(max_size, grid * MIN_CELL) or grid * cell > 8192:
        raise ValueError(f"the mesh has too many triangles ({nf}) for the report's texture; decimate it")
    size = grid * cell

    # pixel -> (triangle, barycentrics): cell (cy, cx), lower-left half = triangle 2k, upper-right = 2k + 1
    py, px = np.divmod(np.arange(size * size, dtype=np.int64), size)
    u = px % cell + 0.5
    w = cell - (py % cell + 0.5)  # v up within the cell
    k = (grid - 1 - py // cell) * grid + px // cell  # cells counted from the bottom row, as the UVs below
    upper = (u + w) > cell
    t = 2 * k + upper
    span = cell - 2 * margin
    s = np.where(upper, (cell - margin - u) / span, (u - margin) / span)
    r = np.where(upper, (cell - margin - w) / span, (w - margin) / span)
    bary = np.clip(np.stack([1 - s - r, s, r], 1), 0, None)
    bary /= bary.sum(1, keepdims=True)
    texel = np.full(size * size, -1, np.int64)
    use = t < nf
    t, bary = t[use], bary[use]
    p = np.einsum("nk,nkj->nj", bary, tri[t])
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    texel[use] = _nearest_facing(p, fn[t], np.asarray(texel_pos_mm, np.float64), np.asarray(texel_normal))

    # the corners' UVs: lower-left triangle (0,0) (1,0) (0,1) of its cell, upper-right (1,1) (0,1) (1,0)
    ids = np.arange(nf)
    kk, up = ids // 2, ids % 2 == 1
    x0, y0 = (kk % grid) * cell, (kk // grid) * cell
    lo, hi = margin, cell - margin
    cu = np.where(up[:, None], [hi, lo, hi], [lo, hi, lo]) + x0[:, None]
    cv = np.where(up[:, None], [hi, hi, lo], [lo, lo, hi]) + y0[:, None]
    uv = (np.stack([cu, cv], 2) / size).reshape(-1, 2)
    centre = 0.5 * (v.min(0) + v.max(0))
    return MeshAtlas(
        positions=(tri - centre).reshape(-1, 3).astype(np.float32),
        normals=corner_normals(v, f).reshape(-1, 3).astype(np.float32),
        uv=uv.astype(np.float32),
        size=size,
        texel=texel.reshape(size, size),
        pixel_mm=edge_mm / (cell - 2 * margin),
        texel_mm=float(voxel_mm),
        cell=cell,
    )


def _nearest_facing(points, face_normal, texel_pos, texel_normal, k: int = 6) -> np.ndarray:
    """Index (n,) of the texel nearest each point among its ``k`` nearest that face the way the point's triangle
    faces (the nearest of all where none does)."""
    k = int(min(k, len(texel_pos)))
    _, j = cKDTree(texel_pos).query(points, k=k, workers=-1)
    j = j.reshape(len(points), k)
    facing = np.einsum("nj,nkj->nk", face_normal, texel_normal[j]) > 0
    first = np.where(facing.any(1), facing.argmax(1), 0)
    return j[np.arange(len(points)), first]


def heat_scale(delta_e: list[np.ndarray]) -> float:
    """The ΔE76 at the top of the heat maps' shared scale: the 99th percentile over all results, at least
    ``HEAT_MIN_SCALE``."""
    return float(max(HEAT_MIN_SCALE, np.percentile(np.concatenate([d.ravel() for d in delta_e]), 99)))


def heat_rgb8(delta_e: np.ndarray, scale: float) -> np.ndarray:
    """(..., 3) uint8 colours of ΔE76 values on the magma map, 0 .. ``scale`` (as the PNG error maps)."""
    from matplotlib import colormaps

    return (colormaps["magma"](np.clip(delta_e / scale, 0, 1))[..., :3] * 255 + 0.5).astype(np.uint8)


def heat_legend(scale: float, width: int = 256) -> np.ndarray:
    """(12, width, 3) uint8 colour bar of the heat maps, ΔE76 0 (left) to ``scale`` (right)."""
    return np.repeat(heat_rgb8(np.linspace(0, scale, width), scale)[None], 12, 0)


def srgb8(rgb_linear: np.ndarray) -> np.ndarray:
    """(..., 3) uint8 sRGB of linear RGB, clipped to [0, 1]."""
    return to_srgb8(np.clip(rgb_linear, 0, 1))


def encode(image: np.ndarray, fmt: str = "PNG", quality: int = 90) -> bytes:
    """An image (H, W, 3) uint8 as PNG or JPEG bytes."""
    buf = io.BytesIO()
    im = Image.fromarray(np.ascontiguousarray(image))
    im.save(buf, format=fmt, **({"quality": quality} if fmt == "JPEG" else {"optimize": True}))
    return buf.getvalue()
