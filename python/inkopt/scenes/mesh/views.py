"""Look at a mesh result: bake per-texel colours onto the mesh's vertices, write GLB files and a PNG of views.

Colours are linear RGB (I, 3) per texel; files are sRGB and written atomically.
"""

from __future__ import annotations

import io

import numpy as np
from PIL import Image, ImageDraw
from scipy.spatial import cKDTree

from ...color import from_srgb8, to_srgb8
from ...io import atomic_write_bytes
from .load import TexturedMesh


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
    rgba = np.concatenate([to_srgb8(col), np.full((len(verts), 1), 255, np.uint8)], 1)
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
    return from_srgb8(c[:, :3] / 255.0) if c.dtype == np.uint8 else np.asarray(c[:, :3], np.float32)


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


def render_views(
    mesh,
    colors_target,
    colors_pred,
    path_png,
    views: int = 3,
    size: int = 320,
    elevation_deg: float = 20.0,
    shade: float = 0.35,
    supersample: int = 2,
) -> None:
    """Write a PNG (2*size rows x views*size columns): row 0 the target, row 1 the prediction
    (``render_view_rows``)."""
    rows = [("target", colors_target), ("prediction", colors_pred)]
    render_view_rows(mesh, rows, path_png, views, size, elevation_deg, shade, supersample)


def render_view_rows(
    mesh,
    rows,
    path_png,
    views: int = 3,
    size: int = 320,
    elevation_deg: float = 20.0,
    shade: float = 0.35,
    supersample: int = 2,
) -> None:
    """Write a PNG (len(rows)*size rows x views*size columns): one row per (label, colours) of ``rows``, one
    column per view (cameras spread evenly in azimuth, the first at (-x, -y), i.e. 45 deg left of the front view
    from -y, raised by ``elevation_deg``), orthographic, white background, each row labelled.

    mesh: TexturedMesh (its seam-merged solid is drawn) or Trimesh. colours: per-vertex colours of that mesh:
    float (V, 3) linear RGB, uint8 (V, 3|4) sRGB, or a Trimesh carrying vertex colours (e.g. from
    ``bake_vertex_colors``). ``shade`` in [0, 1] darkens by a head-light (1 - shade + shade cos) for shape cues.
    CPU only: a vectorised numpy z-buffer rasterizer with Gouraud colours, supersampled ``supersample``^2.
    """
    if views < 1 or size < 8 or not rows:
        raise ValueError(f"need views >= 1, size >= 8 and a row, got {views}, {size}, {len(rows)}")
    verts, faces = _geometry(mesh)
    cols = [_vertex_rgb(c, len(verts)) for _, c in rows]
    n = len(cols)
    radius = np.linalg.norm(verts - 0.5 * (verts.min(0) + verts.max(0)), axis=1).max()
    s = int(size * supersample)
    el = np.radians(elevation_deg)
    tiles = []
    for i in range(views):
        az = np.radians(-45.0 + 360.0 * i / views)
        view_dir = np.array([np.sin(az) * np.cos(el), -np.cos(az) * np.cos(el), np.sin(el)])
        img = _raster(verts, faces, cols, view_dir, s, radius, shade)
        tiles.append(img.reshape(n, size, supersample, size, supersample, 3).mean((2, 4)))
    grid = np.concatenate([np.concatenate([t[r] for t in tiles], 1) for r in range(n)], 0)
    im = Image.fromarray(to_srgb8(grid))
    draw = ImageDraw.Draw(im)
    for r, (label, _) in enumerate(rows):
        draw.text((4, r * size + 4), label, fill=(0, 0, 0))
    buf = io.BytesIO()
    im.save(buf, format="PNG")
    atomic_write_bytes(path_png, buf.getvalue())


EVALUATION_VIEW_SIZE = 240  # pixels per view in an evaluation's views picture (tests lower it)


def result_views(info, texel_normal, results, path_png, views: int = 4, size: int | None = None) -> None:
    """The views picture of an evaluation of a mesh run: the mesh of ``info`` (a ``model.MeshInfo``: the file,
    scale and up axis the run used, so it sits where the texels do) with one row per (label, linear RGB (I, 3) per
    texel) of ``results``, baked onto its vertices from the texels' closest surface points. Only the geometry is
    read (the texture is not needed). ValueError (one line) if the mesh file cannot be read."""
    from .load import load_mesh

    mesh = load_mesh(info.mesh_path, scale=info.mesh_scale, up=info.up, constant_color=True)
    rows = [
        (label, bake_vertex_colors(mesh, info.texel_closest_mm, np.clip(rgb, 0, 1), texel_normal=texel_normal))
        for label, rgb in results
    ]
    render_view_rows(mesh, rows, path_png, views=views, size=size or EVALUATION_VIEW_SIZE)
