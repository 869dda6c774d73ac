"""A (z, y, x) bool mask as bits: the one form of the big masks a run keeps for its whole length, the object's
inside mask (``Volume.inside``, ``VoxelizedObject.inside``) and the optimiser's free mask (``FixedShares.mask``).

:class:`PackedMask` holds 1 bit per grid voxel (``np.packbits`` of the C-order flattening) instead of numpy's byte,
and answers what its readers ask without the dense bytes: the count, a z-plane or a slab of z-planes
(``mask[z]``, ``mask[z0:z1]``), the mask at given flat indices, the sorted flat indices, and the dense array for a
small grid or a short-lived build (``dense()``, ``np.asarray(mask)``: a new array, 1 byte per voxel).
"""

from __future__ import annotations

import numpy as np


class PackedMask:
    """A (z, y, x) bool mask as bits: ``bits`` (ceil(V / 8),) uint8, ``np.packbits`` of its C-order flattening
    (1 bit per voxel), packed and read a slab at a time; ``count`` the voxels in the mask. Immutable."""

    #: voxels packed or unpacked at a time (a multiple of 8: slabs start on byte boundaries)
    STEP = 1 << 24
    ndim = 3
    dtype = np.dtype(bool)

    def __init__(self, mask: np.ndarray):
        mask = np.asarray(mask, bool)
        if mask.ndim != 3:
            raise ValueError(f"a packed mask is (z, y, x), got shape {mask.shape}")
        self.shape = tuple(int(s) for s in mask.shape)
        flat = mask.reshape(-1)
        self.bits = np.empty(-(-flat.size // 8), np.uint8)
        for a in range(0, flat.size, self.STEP):
            self.bits[a // 8 : (a + self.STEP + 7) // 8] = np.packbits(flat[a : a + self.STEP])
        self.bits.flags.writeable = False
        #: voxels in the mask
        self.count = sum(int(np.count_nonzero(self.range(a, a + self.STEP))) for a in range(0, self.size, self.STEP))

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    @property
    def nbytes(self) -> int:
        """Bytes held: the bits."""
        return int(self.bits.nbytes)

    def all(self) -> bool:
        return self.count == self.size

    def any(self) -> bool:
        return self.count > 0

    def at(self, index: np.ndarray) -> np.ndarray:
        """(K,) bool: the mask at the flat (z, y, x) indices ``index`` ((K,) int64)."""
        index = np.asarray(index, np.int64)
        return ((self.bits[index >> 3] >> (7 - (index & 7)).astype(np.uint8)) & 1).astype(bool)

    def range(self, a: int, b: int) -> np.ndarray:
        """(min(b, V) - a,) bool: the flat voxels a:b (any 0 <= a <= V; a new array)."""
        b = min(b, self.size)
        lo = a - a % 8
        return np.unpackbits(self.bits[lo // 8 : (b + 7) // 8], count=b - lo)[a - lo :].view(bool)

    def slab(self, z0: int, z1: int) -> np.ndarray:
        """(z1 - z0, y, x) bool: the z-planes z0:z1 (clipped to the grid; a new array, 1 byte per voxel of it)."""
        nz, ny, nx = self.shape
        z0, z1 = max(0, min(z0, nz)), max(0, min(z1, nz))
        z1 = max(z0, z1)
        return self.range(z0 * ny * nx, z1 * ny * nx).reshape(z1 - z0, ny, nx)

    def __getitem__(self, key) -> np.ndarray:
        """``mask[z]``: plane z, (y, x) bool; ``mask[z0:z1]``: the slab of z-planes, (k, y, x) bool (a step of 1;
        new arrays). Other indexing reads ``dense()`` (or ``at`` for flat indices)."""
        nz = self.shape[0]
        if isinstance(key, slice):
            z0, z1, step = key.indices(nz)
            if step != 1:
                raise IndexError("a packed mask's slab is a slice of z-planes with step 1")
            return self.slab(z0, z1)
        if isinstance(key, (int, np.integer)):
            z = int(key) + (nz if key < 0 else 0)
            if not 0 <= z < nz:
                raise IndexError(f"plane {int(key)} outside 0..{nz - 1}")
            return self.slab(z, z + 1)[0]
        raise IndexError("a packed mask is indexed by a z-plane or a slice of them; use dense() or at() otherwise")

    def dense(self) -> np.ndarray:
        """The (z, y, x) bool mask (1 byte per voxel, a new array)."""
        out = np.empty(self.shape, bool)
        flat = out.reshape(-1)
        for a in range(0, flat.size, self.STEP):
            flat[a : a + self.STEP] = self.range(a, a + self.STEP)
        return out

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        """The dense mask (``dense()``, as ``dtype``) for numpy functions given the mask: a new array."""
        out = self.dense()
        return out if dtype is None else out.astype(dtype, copy=False)

    def nonzero(self) -> np.ndarray:
        """(count,) int64 sorted flat indices of the voxels in the mask, a slab at a time."""
        parts = [np.flatnonzero(self.range(a, a + self.STEP)) + a for a in range(0, self.size, self.STEP)]
        return np.concatenate(parts or [np.empty(0, np.int64)]).astype(np.int64, copy=False)

    def __repr__(self) -> str:
        return f"PackedMask({self.shape}, {self.count} set)"
