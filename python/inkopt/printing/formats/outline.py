"""The outline mesh of a job's printed voxels, shared by GCVF (``Mesh.stl``) and 3MF (the object's mesh).

Marching cubes on the printer-grid occupancy at level 0.5 gives a watertight mesh on the voxel faces, with the
voxels' convex edges and corners cut (every voxel centre lies inside). Grids above ``OUTLINE_MAX_CELLS`` printer
voxels (marching cubes on 10^9 voxels would need tens of GB) use blocks of fz x fy x fx printer voxels instead
(``outline_factors``: the smallest near-cubic blocks that bring the grid under the limit; about 0.1 mm for a 40 mm
object): a block is occupied if any of its voxels or of its 26 neighbour blocks' voxels is (``block_outline``;
without that margin the cut corners of a block would leave out voxel centres), so the outline encloses every
printed voxel and lies within two blocks of them.
"""

from __future__ import annotations

import numpy as np

OUTLINE_MAX_CELLS = 2**24  # marching cubes on at most this many cells (float32: 64 MB)


def outline_mesh(occupied, voxel_mm_printer):
    """A watertight ``trimesh.Trimesh`` (mm, x y z) around the True voxels of ``occupied`` (Z, Y, X)."""
    import trimesh
    from skimage.measure import marching_cubes

    vp = np.asarray(voxel_mm_printer, np.float64)
    pad = np.pad(np.asarray(occupied, np.float32), 1)
    verts, faces, _, _ = marching_cubes(pad, level=0.5, spacing=(vp[2], vp[1], vp[0]))
    # padded index i sits at (i - 0.5) voxels; marching_cubes winds the faces for (z, y, x) with the normals into
    # the lower values, so swapping the axes to (x, y, z) turns them outwards
    return trimesh.Trimesh(verts[:, ::-1] - 0.5 * vp, faces, process=True)


def grown(coarse: np.ndarray) -> np.ndarray:
    """A block occupancy grown by one block in every direction (the blocks inside a block outline)."""
    from scipy.ndimage import binary_dilation

    return binary_dilation(coarse, np.ones((3, 3, 3), bool))


def block_outline(coarse, voxel_mm_printer, factors):
    """The outline mesh of a (Z', Y', X') block occupancy with blocks of ``factors`` (fz, fy, fx) printer voxels
    of ``voxel_mm_printer`` (x, y, z) mm: blocks grown by one block in every direction unless they are single
    voxels (module docstring), then ``outline_mesh``."""
    fz, fy, fx = factors
    if (fz, fy, fx) != (1, 1, 1):
        block = np.asarray(voxel_mm_printer) * np.array([fx, fy, fz])
        mesh = outline_mesh(grown(np.pad(coarse, 1)), block)
        mesh.apply_translation(-block)  # the pad's block
        return mesh
    return outline_mesh(coarse, voxel_mm_printer)


def outline_factors(shape, voxel_mm_printer, max_cells: int | None = None) -> tuple[int, int, int]:
    """Block size (fz, fy, fx) in printer voxels for the outline of a (Z, Y, X) grid: (1, 1, 1) up to
    ``max_cells`` (default ``OUTLINE_MAX_CELLS``) voxels, else grown one step at a time along the axis whose
    block is thinnest in mm."""
    max_cells = OUTLINE_MAX_CELLS if max_cells is None else max_cells
    shape = np.asarray(shape, np.int64)
    size = np.asarray(voxel_mm_printer, np.float64)[::-1]  # (z, y, x) mm
    f = np.ones(3, np.int64)
    while np.prod(-(-shape // f)) > max_cells:
        grow = f < shape
        i = int(np.argmin(np.where(grow, size * f, np.inf)))
        f[i] += 1
    return tuple(int(v) for v in f)


def block_any(occ, fy: int, fx: int) -> np.ndarray:
    """(Y, X) bool -> (ceil(Y / fy), ceil(X / fx)): True where any voxel of the block is."""
    if fy == fx == 1:
        return occ
    Y, X = occ.shape
    pad = np.pad(occ, ((0, -Y % fy), (0, -X % fx)))
    return pad.reshape(pad.shape[0] // fy, fy, pad.shape[1] // fx, fx).any(axis=(1, 3))


def coarse_grid(shape, factors) -> np.ndarray:
    """An all-False block occupancy of a (Z, Y, X) grid in blocks of ``factors`` (fz, fy, fx)."""
    return np.zeros(tuple(-(-int(n) // f) for n, f in zip(shape, factors, strict=True)), bool)
