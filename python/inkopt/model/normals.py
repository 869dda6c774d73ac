"""Shading normals of a voxelized surface, stored only at the voxels that have one.

A mesh's shading normals live on its surface voxels (a few per cent of the grid at 40 mm), so a dense
(z, y, x, 3) float32 array spends 12 bytes per grid voxel on zeros (0.7 GB for Spot at 40 mm). ``SurfaceNormals``
keeps ``index`` (K,) int64, the voxels' linear indices in the grid's C order of (z, y, x), strictly increasing,
and ``vectors`` (K, 3) float32 outward normals with (x, y, z) components: 20 bytes per surface voxel. The Rust core
reads this form directly (``Scene(normal_index=, normal_vectors=)``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(eq=False)
class SurfaceNormals:
    """Normals at some voxels of a grid of ``shape`` (z, y, x): ``index`` (K,) int64 increasing linear indices,
    ``vectors`` (K, 3) float32 (x, y, z)."""

    shape: tuple[int, int, int]
    index: np.ndarray
    vectors: np.ndarray

    def __post_init__(self):
        self.shape = tuple(int(s) for s in self.shape)
        self.index = np.ascontiguousarray(self.index, np.int64).reshape(-1)
        self.vectors = np.ascontiguousarray(self.vectors, np.float32)
        if self.vectors.shape != (len(self.index), 3):
            raise ValueError(f"normals: {self.vectors.shape} vectors for {len(self.index)} voxels (want (K, 3))")
        size = int(np.prod(self.shape, dtype=np.int64))
        if len(self.index) and (self.index[0] < 0 or self.index[-1] >= size or np.any(np.diff(self.index) <= 0)):
            raise ValueError(f"normals: voxel indices must increase and lie in the grid {self.shape}")

    @classmethod
    def from_dense(cls, dense: np.ndarray) -> SurfaceNormals:
        """From a (z, y, x, 3) array that is zero where there is no normal."""
        dense = np.asarray(dense, np.float32)
        if dense.ndim != 4 or dense.shape[-1] != 3:
            raise ValueError(f"dense normals must have shape (z, y, x, 3), got {dense.shape}")
        flat = dense.reshape(-1, 3)
        index = np.flatnonzero(np.any(flat != 0, axis=1))
        return cls(dense.shape[:3], index, flat[index])

    @classmethod
    def from_voxels(cls, shape, voxels: np.ndarray, vectors: np.ndarray) -> SurfaceNormals:
        """From (K, 3) voxel coordinates (z, y, x) in any order (no repeats) and their (K, 3) vectors."""
        index = np.ravel_multi_index(tuple(np.asarray(voxels, np.int64).T), tuple(shape))
        order = np.argsort(index, kind="stable")
        return cls(shape, index[order], np.asarray(vectors, np.float32)[order])

    def at(self, voxels: np.ndarray) -> np.ndarray:
        """(M, 3) float32 normals of voxels (M, 3) (z, y, x); zero where a voxel has none."""
        j = np.ravel_multi_index(tuple(np.asarray(voxels, np.int64).T), self.shape)
        k = np.minimum(np.searchsorted(self.index, j), max(len(self.index) - 1, 0))
        out = np.zeros((len(j), 3), np.float32)
        if len(self.index):
            hit = self.index[k] == j
            out[hit] = self.vectors[k[hit]]
        return out

    def layer(self, z: int) -> np.ndarray:
        """Layer z as a dense (y, x, 3) float32 array."""
        ny, nx = self.shape[1:]
        a, b = np.searchsorted(self.index, [z * ny * nx, (z + 1) * ny * nx])
        out = np.zeros((ny * nx, 3), np.float32)
        out[self.index[a:b] - z * ny * nx] = self.vectors[a:b]
        return out.reshape(ny, nx, 3)

    def dense(self) -> np.ndarray:
        """The (z, y, x, 3) float32 array (12 bytes per grid voxel: for small grids and tests)."""
        out = np.zeros(self.shape + (3,), np.float32)
        out.reshape(-1, 3)[self.index] = self.vectors
        return out

    @property
    def nbytes(self) -> int:
        return self.index.nbytes + self.vectors.nbytes
