"""Voxelize a textured mesh onto the optimisation grid: inside mask, signed distances, surface texels with
shading normals and target colours (the texture colour of each texel's closest surface point).

Conventions (docs/conventions.md): arrays are (z, y, x[, c]); positions, normals and ``voxel_mm`` are (x, y, z)
in mm; colours are linear RGB.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...model import SurfaceNormals, Texels
from ...model.mask import PackedMask
from ...units import voxel_mm as _voxel_mm
from .load import TexturedMesh, barycentric, corner_normals, winding_number

DEFAULT_VOXEL_MM = _voxel_mm()


@dataclass(frozen=True)
class NearDepth:
    """Inside voxels near the surface and their distance below it.

    index (K,) int64 flat (z, y, x) indices of the inside voxels whose centre lies less than ``band_mm`` below the
    surface (block order, each voxel once); mm (K,) float32 that distance, exact (point-to-mesh), in
    [1e-6, band_mm). 12 bytes per near voxel (K ~ band depth x surface voxels).
    """

    index: np.ndarray
    mm: np.ndarray
    band_mm: float

    def within(self, depth_mm: float) -> np.ndarray:
        """(M,) int64 flat indices of the inside voxels at most ``depth_mm`` (< ``band_mm``) below the surface
        (float32 comparison: the voxels whose signed distance is >= -depth_mm)."""
        if not depth_mm < self.band_mm:
            raise ValueError(f"depth {depth_mm} mm reaches the exact-distance band's {self.band_mm} mm")
        return self.index[self.mm <= np.float32(depth_mm)]


@dataclass
class VoxelizedObject:
    """A mesh on the voxel grid.

    inside     ``PackedMask`` (z, y, x), a bit per voxel: voxel centre inside (generalized winding number > 0.5)
    depth      ``NearDepth``: the exact distance below the surface (mm) of the inside voxels less than
               ``band_mm`` deep (the only distances the scene reads: shell and translucency depths lie within the
               band), a few bytes per near voxel instead of 4 per grid voxel; None once dropped
    voxel_mm   (3,) float64 (x, y, z);  origin_mm (3,) float64 (x, y, z) of voxel (0, 0, 0)'s low corner
    texels     Texels: surface voxels (inside, a 6-neighbour outside or off-grid) in C order of (z, y, x);
               face = the exposed face most aligned with the normal; normal = see ``voxelize``
    targets    (I, 3) float32 linear RGB of the closest surface point
    closest_mm (I, 3) float64 closest surface point (x, y, z) to each texel's voxel centre
    face_index (I,) int64 the triangle holding it (index into the mesh's faces)
    normals    ``SurfaceNormals``: the texels' normals at the surface voxels (for ``Volume.normals``)
    """

    inside: PackedMask
    depth: NearDepth | None
    voxel_mm: np.ndarray
    origin_mm: np.ndarray
    texels: Texels
    targets: np.ndarray
    closest_mm: np.ndarray
    face_index: np.ndarray
    normals: SurfaceNormals
    band_mm: float

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.inside.shape

    def texel_centres_mm(self) -> np.ndarray:
        """(I, 3) float64 world positions (x, y, z, mm) of the texels' voxel centres."""
        return self.origin_mm + (self.texels.voxel[:, ::-1] + 0.5) * self.voxel_mm


_B1, _B2 = 8, 2  # coarse block and sub-block edge (voxels)
#: voxels of near-surface coarse blocks queried at a time (``_inside_depth``: ~100 bytes each while queried)
_NEAR_VOXELS = 1 << 20


def _on_grid(vox: np.ndarray, shape) -> tuple[np.ndarray, np.ndarray]:
    """The voxels (n, 3) (z, y, x) that lie on the grid of ``shape`` (blocks overhang its high ends), and (n,) bool
    which they were."""
    on = np.all(vox < np.asarray(shape), axis=1)
    return vox[on], on


def _inside_depth(vs, fs, origin, v, shape, band_mm) -> tuple[np.ndarray, NearDepth]:
    """inside (z, y, x) bool on the grid and the near inside voxels' depths (``NearDepth``; see ``voxelize``), in
    two levels.

    A block whose centre is farther from the surface than from any of its voxel centres (h) holds voxel centres
    of one side only. Coarse 8^3 blocks beyond h + band: one winding-number query at the centre. In the others,
    2^3 sub-blocks: beyond h + band one query; beyond h one query for the sign plus exact per-voxel distances;
    else per-voxel winding numbers and distances. Only the inside mask is grid-sized (1 byte per voxel)."""
    import igl

    unsigned = igl.SignedDistanceType.SIGNED_DISTANCE_TYPE_UNSIGNED
    nb = -(-np.array(shape) // _B1)  # coarse blocks (z, y, x)
    diag = np.linalg.norm(v)
    h1, h2 = 0.5 * (_B1 - 1) * diag, 0.5 * (_B2 - 1) * diag  # block centre to its farthest voxel centre

    def centres(idx_zyx, size):  # (n, 3) zyx block index -> (n, 3) xyz mm centres
        return np.ascontiguousarray(origin + (idx_zyx[:, ::-1] * size + 0.5 * size) * v)

    bidx = np.stack(np.meshgrid(*[np.arange(k) for k in nb], indexing="ij"), -1).reshape(-1, 3)
    d1 = np.sqrt(igl.point_mesh_squared_distance(centres(bidx, _B1), vs, fs)[0])
    near1 = d1 <= h1 + band_mm
    blk_in = np.zeros(len(bidx), bool)
    blk_in[~near1] = winding_number(vs, fs, centres(bidx[~near1], _B1)) > 0.5
    del d1
    # the grid's mask at its own shape, filled one coarse layer at a time (no padded copy)
    inside = np.empty(shape, bool)
    blk = blk_in.reshape(tuple(nb))
    for kz in range(int(nb[0])):
        inside[kz * _B1 : (kz + 1) * _B1] = np.repeat(np.repeat(blk[kz], _B1, 0), _B1, 1)[: shape[1], : shape[2]]
    flat_in = inside.reshape(-1)

    r = _B1 // _B2
    sub_local = np.stack(np.meshgrid(*[np.arange(r)] * 3, indexing="ij"), -1).reshape(-1, 3)
    vox_local = np.stack(np.meshgrid(*[np.arange(_B2)] * 3, indexing="ij"), -1).reshape(-1, 3)
    near_idx = np.flatnonzero(near1)
    step = max(1, _NEAR_VOXELS // _B1**3)
    near_lin, near_mm = [], []
    for a in range(0, len(near_idx), step):
        sub = (bidx[near_idx[a : a + step], None, :] * r + sub_local[None]).reshape(-1, 3)  # sub-block zyx
        d2 = igl.signed_distance(centres(sub, _B2), vs, fs, unsigned, -(h2 + band_mm), h2 + band_mm)[0]
        d2 = np.where(np.isnan(d2), np.inf, np.abs(d2))
        fine = d2 <= h2  # the surface may cross: per-voxel winding numbers
        one = ~fine
        sgn = np.zeros(len(sub), bool)
        sgn[one] = winding_number(vs, fs, centres(sub[one], _B2)) > 0.5
        need_d = d2 <= h2 + band_mm
        vox, on = _on_grid((sub[need_d, None, :] * _B2 + vox_local[None]).reshape(-1, 3), shape)
        lin = np.ravel_multi_index(tuple(vox.T), shape)
        p = centres(vox, 1)
        d = igl.signed_distance(p, vs, fs, unsigned, -band_mm, band_mm)[0]
        d = np.where(np.isnan(d), band_mm, np.clip(np.abs(d), 1e-6, band_mm)).astype(np.float32)
        ins = np.repeat(sgn[need_d], _B2**3)[on]
        fine_v = np.repeat(fine[need_d], _B2**3)[on]
        ins[fine_v] = winding_number(vs, fs, p[fine_v]) > 0.5
        flat_in[lin] = ins
        keep = ins & (d < np.float32(band_mm))  # inside and less than the band deep
        near_lin.append(lin[keep])
        near_mm.append(d[keep])
        vox, on = _on_grid((sub[~need_d, None, :] * _B2 + vox_local[None]).reshape(-1, 3), shape)  # one sign each
        flat_in[np.ravel_multi_index(tuple(vox.T), shape)] = np.repeat(sgn[~need_d], _B2**3)[on]
    depth = NearDepth(
        np.concatenate(near_lin or [np.empty(0, np.int64)]).astype(np.int64, copy=False),
        np.concatenate(near_mm or [np.empty(0, np.float32)]),
        band_mm,
    )
    return inside, depth


def _surface_voxels(inside: np.ndarray) -> np.ndarray:
    """(I, 3) int32 (z, y, x) of the surface voxels (inside, with a 6-neighbour outside or off the grid) in C order,
    from the exposed faces (found a few layers at a time: ``Texels.exposed_faces``)."""
    faces = Texels.exposed_faces(inside)
    flat = np.unique(np.ravel_multi_index(tuple(faces.voxel.T.astype(np.int64)), inside.shape))
    return np.stack(np.unravel_index(flat, inside.shape), axis=1).astype(np.int32)


def voxelize(
    mesh: TexturedMesh, voxel_mm=DEFAULT_VOXEL_MM, pad: int = 1, band: float = 3.0, crease_deg: float = 60.0
) -> VoxelizedObject:
    """Voxelize ``mesh`` on a grid of ``voxel_mm`` (scalar or (x, y, z)) with ``pad`` empty voxels around its
    bounding box (whose low corner is a voxel corner).

    Inside = generalized winding number > 0.5 at the voxel centre (robust to small holes and seams), queried
    per voxel only near the surface and once per block elsewhere (``_inside_depth``); the depth below the surface
    is exact, and kept, for the inside voxels less than ``band`` voxels (of the largest edge) deep. Texel normals
    are the closest triangle's smooth normal (``corner_normals`` interpolated barycentrically at the closest
    point): more robust than the gradient of a voxel SDF, which is noisy at one-voxel resolution and undefined on
    thin parts. Targets: the closest point's colour (``TexturedMesh.colors_at``). Needs 1 byte per grid voxel, 12
    per near voxel and ~0.1 GB for the queries.
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
        raise ValueError(
            f"grid {' x '.join(str(int(n)) for n in n_xyz[::-1])} (z, y, x) has more than 2^31 voxels; "
            "use larger voxels"
        )
    origin = lo - pad * v
    shape = tuple(int(s) for s in n_xyz[::-1])
    band_mm = float(band * v.max())

    inside, depth = _inside_depth(vs, fs, origin, v, shape, band_mm)
    if not inside.any():
        raise ValueError(f"{mesh.source}: no voxel centre lies inside the mesh; the voxels are too coarse")

    # ---- texels: surface voxels, closest points, normals, faces, colours
    idx = _surface_voxels(inside)
    centres = origin + (idx[:, ::-1] + 0.5) * v
    _, fi, closest = igl.point_mesh_squared_distance(centres, vs, fs)
    bary = barycentric(vs[fs[fi]], closest)
    nrm = np.einsum("nk,nkj->nj", bary, corner_normals(vs, fs, crease_deg)[fi])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    texels = Texels.from_normals(inside, SurfaceNormals.from_voxels(shape, idx, nrm))  # as a saved volume gives
    if not np.array_equal(texels.voxel, idx):
        raise RuntimeError("Texels.from_normals lists other surface voxels than voxelize")
    normals = SurfaceNormals.from_voxels(shape, idx, texels.normal)  # as re-normalised there
    return VoxelizedObject(
        inside=PackedMask(inside),
        depth=depth,
        voxel_mm=v,
        origin_mm=origin,
        texels=texels,
        targets=mesh.colors_at(fi, bary),
        closest_mm=closest,
        face_index=fi.astype(np.int64),
        normals=normals,
        band_mm=band_mm,
    )
