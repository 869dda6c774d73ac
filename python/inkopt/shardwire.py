"""What texel shards send between a Ray driver and its workers (``inkopt.distributed``), in compact exact forms:
:class:`TouchedSlots`, the gradient slots a worker's paths touched and their fixed-point sums (instead of a raw
int64 array per free voxel); :class:`BandObject`, a band volume without grid-sized arrays (instead of the
``Volume``, whose inside mask and label grid are 2 bytes per grid voxel); :func:`payload_bytes`, what an object
carries.
"""

from __future__ import annotations

import dataclasses
import zlib
from dataclasses import dataclass

import numpy as np

from .model import Band, InkTable, SurfaceNormals, Volume
from .model.mask import PackedMask


def payload_bytes(obj) -> int:
    """The bytes ``obj`` carries between processes: its arrays' and byte strings' lengths, in tuples, lists, dicts
    and dataclasses (a Volume, Texels, Lighting), a ``PackedMask``'s bits; 8 for a scalar or another small object
    (Ray's framing is not counted)."""
    if isinstance(obj, (np.ndarray, PackedMask)):
        return int(obj.nbytes)
    if isinstance(obj, (bytes, bytearray, memoryview)):
        return len(obj)
    if isinstance(obj, (list, tuple)):
        return sum(payload_bytes(o) for o in obj)
    if isinstance(obj, dict):
        return sum(payload_bytes(o) for o in obj.values())
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return sum(payload_bytes(getattr(obj, f.name)) for f in dataclasses.fields(obj))
    return 8


def _narrowest(values: np.ndarray, dtypes) -> np.ndarray:
    """``values`` (integers) in the first of ``dtypes`` that holds every one of them exactly."""
    if values.size == 0:
        return values.astype(dtypes[0])
    lo, hi = int(values.min()), int(values.max())
    for dtype in dtypes:
        info = np.iinfo(dtype)
        if info.min <= lo and hi <= info.max:
            return values.astype(dtype, copy=False)
    raise ValueError(f"integers {lo}..{hi} fit none of {dtypes}")


@dataclass(frozen=True)
class TouchedSlots:
    """The gradient slots a shard's paths touched and their fixed-point sums, exactly: what a worker returns
    instead of its two raw (F, 3) int64 arrays, in which most slots are zero when its texels see only part of
    the object.

    shape    the raw arrays' shape: (F, 3) (a slot per free voxel) or (z, y, x, 3)
    first    the first touched slot (0 when none is)
    count    how many slots are touched (a slot is touched when any of its 6 sums is not 0)
    where    which: ``bitmap`` True: ``np.packbits`` of the touched flags of slots first .. last (uint8); else the
             gaps between consecutive touched slots ((count - 1,), the narrowest unsigned dtype); whichever is
             shorter
    dtypes   the dtypes of the 6 columns of sums (sigma_s's channels 0, 1, 2, then sigma_a's), each the narrowest
             signed integer dtype that holds its column's values
    sums     the columns, each (count,) of its dtype, byte-shuffled (a column's lowest bytes, then its next, ...:
             the high bytes of fixed-point sums repeat) and compressed with zlib (``level``, lossless)
    """

    shape: tuple
    first: int
    count: int
    bitmap: bool
    where: np.ndarray
    dtypes: tuple
    sums: bytes

    @classmethod
    def of(cls, sum_s: np.ndarray, sum_a: np.ndarray, level: int = 1) -> TouchedSlots:
        """The touched slots of raw fixed-point sums ``sum_s``, ``sum_a`` (int64, (..., 3), same shape); ``level``:
        zlib's (1: fast; 6 saves ~1.5 % more on Spot's sums at 1.3x the time)."""
        s, a = np.asarray(sum_s, np.int64).reshape(-1, 3), np.asarray(sum_a, np.int64).reshape(-1, 3)
        flags = (s != 0).any(axis=1) | (a != 0).any(axis=1)
        idx = np.flatnonzero(flags)
        first = int(idx[0]) if len(idx) else 0
        span = int(idx[-1]) - first + 1 if len(idx) else 0
        gaps = _narrowest(np.diff(idx), (np.uint8, np.uint16, np.uint32, np.uint64))
        bitmap = (span + 7) // 8 < gaps.nbytes
        where = np.packbits(flags[first : first + span]) if bitmap else gaps
        signed = (np.int8, np.int16, np.int32, np.int64)
        cols = [_narrowest(m[idx, c], signed) for m in (s, a) for c in range(3)]
        planes = b"".join(np.ascontiguousarray(c.view(np.uint8).reshape(-1, c.itemsize).T).tobytes() for c in cols)
        packed = zlib.compress(planes, level)
        return cls(
            tuple(np.shape(sum_s)), first, len(idx), bool(bitmap), where, tuple(c.dtype.str for c in cols), packed
        )

    def columns(self) -> list[np.ndarray]:
        """The 6 columns of sums, (count,) each in its dtype (see the class)."""
        raw, out, at = zlib.decompress(self.sums), [], 0
        for dtype in self.dtypes:
            size = np.dtype(dtype).itemsize
            planes = np.frombuffer(raw, np.uint8, self.count * size, at).reshape(size, self.count)
            out.append(np.ascontiguousarray(planes.T).view(dtype).reshape(-1))
            at += self.count * size
        return out

    def indices(self) -> np.ndarray:
        """The touched slots, (count,) int64, increasing."""
        if self.count == 0:
            return np.empty(0, np.int64)
        if self.bitmap:
            span = len(self.where) * 8
            return np.flatnonzero(np.unpackbits(self.where, count=span)).astype(np.int64) + self.first
        return self.first + np.concatenate([[0], np.cumsum(self.where, dtype=np.int64)])

    def add_to(self, sum_s: np.ndarray, sum_a: np.ndarray) -> None:
        """Add these sums into ``sum_s``, ``sum_a`` (int64 arrays of :attr:`shape`, C-contiguous) in place, wrapping
        as the core's sums do."""
        idx, cols = self.indices(), self.columns()
        for k, m in enumerate((sum_s.reshape(-1, 3), sum_a.reshape(-1, 3))):
            for c in range(3):
                m[idx, c] += cols[3 * k + c].astype(np.int64)

    def dense(self) -> tuple[np.ndarray, np.ndarray]:
        """The raw arrays (sum_s, sum_a), int64 of :attr:`shape`."""
        s, a = np.zeros(self.shape, np.int64), np.zeros(self.shape, np.int64)
        self.add_to(s, a)
        return s, a


@dataclass(frozen=True)
class BandObject:
    """A band volume (``Volume.band``, a label or mixture medium) as a worker's :class:`inkopt.render.Renderer`
    needs it, with no grid-sized array: the inside voxels as runs along x, the medium only at the band's voxels.
    The renderer reads the fields a Volume has (and :meth:`inside_bytes`, the mask it builds its geometry from,
    made when asked and not kept), and renders it bit-identically to the Volume it came from (:meth:`of`).

    shape, voxel_mm, g, ior, boundary, normals   as the Volume's
    starts, ends  (R,) int64: flat (z, y, x) indices of the first and one past the last voxel of each run of inside
                  voxels along x, in grid order (16 bytes per run: a row through the object has a few)
    band, inks    the Volume's ``Band`` and ink table
    band_labels   (K,) uint8: a label medium's labels at the band's voxels; else None
    band_mixture  (K, N) float32: a mixture medium's shares at the band's voxels; else None
    """

    shape: tuple
    voxel_mm: np.ndarray
    g: float
    ior: float
    boundary: str
    normals: SurfaceNormals | None
    starts: np.ndarray
    ends: np.ndarray
    band: Band
    inks: InkTable
    band_labels: np.ndarray | None = None
    band_mixture: np.ndarray | None = None
    #: what the renderer reads as a Volume's medium form
    form = "band"

    @staticmethod
    def fits(volume: Volume) -> bool:
        """Whether ``volume`` has a band and a label or mixture medium (what :meth:`of` takes)."""
        return volume.band is not None and volume.form in ("labels", "mixture")

    @classmethod
    def of(cls, volume: Volume, slab: int = 1 << 24) -> BandObject:
        """``volume``'s band object (``fits(volume)``), its mask read ``slab`` voxels at a time (whole z layers)."""
        assert cls.fits(volume), "a BandObject needs a band volume with a label or mixture medium"
        nz, ny, nx = volume.shape
        layers = max(1, slab // (ny * nx))
        starts, ends = [], []
        for z in range(0, nz, layers):
            part = volume.inside[z : z + layers].reshape(-1, nx).view(np.int8)
            edge = np.diff(np.pad(part, ((0, 0), (1, 1))), axis=1)  # +1 where a run starts, -1 one past its end
            for out, sign in ((starts, 1), (ends, -1)):
                row, x = np.nonzero(edge == sign)  # in grid order
                out.append((z * ny + row.astype(np.int64)) * nx + x)
        index = volume.band.index
        labels = volume.medium.labels_at(index) if volume.form == "labels" else None  # no grid-sized array
        rows = volume.mixture.reshape(-1, len(volume.inks))[index] if volume.form == "mixture" else None
        return cls(
            volume.shape, volume.voxel_mm, volume.g, volume.ior, volume.boundary, volume.normals,
            np.concatenate(starts), np.concatenate(ends), volume.band, volume.inks, labels, rows,
        )  # fmt: skip

    def inside_bytes(self) -> np.ndarray:
        """The inside mask, (z, y, x) uint8 0/1, made from the runs (1 byte per grid voxel, not kept)."""
        edge = np.zeros(int(np.prod(self.shape, dtype=np.int64)) + 1, np.int8)
        edge[self.ends] -= 1  # before the starts: one run's end is the next row's start when both touch
        edge[self.starts] += 1
        np.cumsum(edge, out=edge)
        return edge[:-1].view(np.uint8).reshape(self.shape)

    def coefficients_at(self, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(sigma_s, sigma_a) (K, 3) float32 of the band's voxels (``index`` must be ``band.index``), computed as
        ``Volume.coefficients_at`` computes them, bit for bit."""
        assert np.array_equal(index, self.band.index), "a BandObject holds the medium of its band only"
        k = len(index)
        if k == 0:
            return np.empty((0, 3), np.float32), np.empty((0, 3), np.float32)
        if self.band_labels is not None:
            part = Volume.from_labels(self.voxel_mm, self.band_labels.reshape(1, 1, k), self.inks)
        else:
            part = Volume.from_mixture(self.voxel_mm, self.band_mixture.reshape(1, 1, k, -1), self.inks)
        return part.coefficients_at(np.arange(k))
