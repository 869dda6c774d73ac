"""A mixture volume file read lazily, without the whole (z, y, x, N) mixture in memory.

``MixtureSource`` reads the file's small arrays (voxel size, ink table, ``g``, ``ior``, boundary, origin, the
``inside`` mask: 1 byte per voxel, the shading normals of the surface voxels) at once, and the ``mixture`` member
by decompressing it sequentially from its zip member: one (y, x, N) layer at a time (``[z]``: quantization, 3MF
and the soft-proof page; layers are asked for in increasing z, and going back further than the two layers it keeps
reopens the member), or as consecutive blocks of flat (z, y, x) voxels (``blocks``: a run's start read from a
volume file, ``optim.param.initial_free_mixture``). Its format version is checked as ``Volume.load`` checks it
(``upgrade_volume``). A mixture numpy stored in Fortran order (``np.savez`` of a transposed array; inkopt never
writes one) cannot be read in z order from the stream: it is read whole on first use.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from .inks import DEFAULT_G, InkTable
from .media import VolumeError
from .normals import SurfaceNormals
from .volume import Quantization, Volume, upgrade_volume

HEAVY = ("mixture", "normals")  # members not loaded at once (dense normals: a pre-release layout, refused)


def _read_header(fh):
    major, _ = np.lib.format.read_magic(fh)
    read = np.lib.format.read_array_header_1_0 if major == 1 else np.lib.format.read_array_header_2_0
    return read(fh)


class MixtureSource:
    """A mixture volume file read lazily (module docstring). ``shape`` (z, y, x, N); ``[z]`` one layer
    (y, x, N) in the file's dtype; ``blocks(voxels)`` the whole mixture as (K, N) float32 blocks; ``inside``
    (z, y, x) bool or None; ``voxel_mm``, ``inks``, ``g``, ``ior``, ``boundary``, ``origin_mm``; ``normals``
    (``SurfaceNormals`` or None). ``what``: the step that reads it, named when the file is not a mixture volume.
    Bad files are one-line ``VolumeError``s (``FormatError`` for a format version it cannot read)."""

    def __init__(self, path, what: str = "this step"):
        self.path, self._zip, self._whole = path, None, None
        if not Path(path).is_file():
            raise VolumeError(f"volume file {path} does not exist")
        try:
            self._zip = zipfile.ZipFile(path)
            names = {n[:-4]: n for n in self._zip.namelist() if n.endswith(".npy")}
            small = {
                k: np.lib.format.read_array(self._zip.open(n), allow_pickle=False)
                for k, n in names.items()
                if k not in HEAVY
            }
        except (OSError, zipfile.BadZipFile, ValueError) as exc:
            self.close()
            raise VolumeError(f"{path} is not a readable .npz volume file ({type(exc).__name__}: {exc})") from None
        try:
            small = upgrade_volume({**small, **dict.fromkeys(set(HEAVY) & set(names))}, path)
        except ValueError:
            self.close()
            raise
        if "mixture" not in names:
            self.close()
            form = "labels" if "labels" in names or "labels_file" in names else "dense"
            raise VolumeError(f"{path} holds a {form} volume; {what} needs a mixture volume")
        try:
            self.g = float(small["g"]) if "g" in small else DEFAULT_G
            self.voxel_mm = np.asarray(small["voxel_mm"], np.float64).reshape(-1)
            self.inks = InkTable.from_arrays(small, self.g)
        except (KeyError, ValueError) as exc:
            self.close()
            raise VolumeError(f"{path}: bad volume file ({type(exc).__name__}: {exc})") from None
        self.ior = float(small["ior"]) if "ior" in small else 1.5
        self.boundary = str(small["boundary"]) if "boundary" in small else "box"
        self.origin_mm = small.get("origin_mm")
        self.inside = np.asarray(small["inside"], bool) if "inside" in small else None
        self._member = names["mixture"]
        try:
            self._open()
        except (OSError, zipfile.BadZipFile, ValueError) as exc:
            self.close()
            raise VolumeError(f"{path}: unreadable mixture ({type(exc).__name__}: {exc})") from None
        if len(self.shape) != 4 or self.shape[3] != len(self.inks) or self.dtype.hasobject:
            self.close()
            raise VolumeError(f"{path}: mixture of shape {self.shape} does not fit {len(self.inks)} inks")
        self.normals = None
        try:
            if "normal_index" in small:
                self.normals = SurfaceNormals(self.shape[:3], small["normal_index"], small["normal_vectors"])
            if self.normals is not None and self.normals.shape != tuple(self.shape[:3]):
                raise ValueError(f"normals for a grid of {self.normals.shape}, the mixture is {self.shape[:3]}")
        except (KeyError, ValueError) as exc:
            self.close()
            raise VolumeError(f"{path}: bad shading normals ({exc})") from None

    def __enter__(self) -> MixtureSource:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _open(self) -> None:
        self._fh = self._zip.open(self._member)
        self.shape, self._fortran, self.dtype = _read_header(self._fh)
        self._next = 0
        self._kept: dict[int, np.ndarray] = {}

    def _read(self, n: int) -> bytes:
        """The next ``n`` bytes of the mixture member (a one-line error if it ends before)."""
        data = self._fh.read(n)
        if len(data) != n:
            raise VolumeError(f"{self.path}: the mixture ends early (a truncated file)")
        return data

    def _fortran_whole(self) -> np.ndarray:
        """The whole mixture of a Fortran-order member (read once, kept)."""
        if self._whole is None:
            self._whole = np.lib.format.read_array(self._zip.open(self._member), allow_pickle=False)
        return self._whole

    def __getitem__(self, z: int) -> np.ndarray:
        z = int(z)
        if z in self._kept:
            return self._kept[z]
        if not 0 <= z < self.shape[0]:
            raise IndexError(f"layer {z} outside 0..{self.shape[0] - 1}")
        if self._fortran:
            return np.ascontiguousarray(self._fortran_whole()[z])
        if z < self._next:
            self._fh.close()
            self._open()
        n = int(np.prod(self.shape[1:])) * self.dtype.itemsize
        while self._next <= z:
            data = self._read(n)
            self._next += 1
        lay = np.frombuffer(data, self.dtype).reshape(self.shape[1:])
        if len(self._kept) >= 2:
            self._kept.pop(min(self._kept))
        self._kept[z] = lay
        return lay

    def blocks(self, voxels: int = 1 << 20):
        """The whole mixture as consecutive blocks of flat (z, y, x) voxels in C order, ``voxels`` at a time (the
        last one shorter): an iterator of (v0, rows), ``rows`` (K, N) float32 the mixtures of voxels v0:v0+K (a
        block may end anywhere, inside a row of the grid). Values are those ``Volume.load(path).mixture`` holds, bit
        for bit (cast to float32 as ``Mixture`` casts), and each block is checked as ``Mixture`` checks the whole
        (finite, non-negative). Reads the member from its start (the layer reader starts again after it)."""
        if voxels < 1:
            raise ValueError(f"blocks of at least one voxel, got {voxels}")
        total, n = int(np.prod(self.shape[:3])), int(self.shape[3])
        self._fh.close()
        self._open()
        self._next = self.shape[0]  # the layer reader's position is lost: its next layer reopens the member
        flat = None if not self._fortran else self._fortran_whole().reshape(-1, n)  # a C-order copy
        for v0 in range(0, total, voxels):
            k = min(voxels, total - v0)
            if flat is not None:
                rows = flat[v0 : v0 + k].astype(np.float32, copy=False)
            else:
                raw = np.frombuffer(self._read(k * n * self.dtype.itemsize), self.dtype)
                rows = raw.astype(np.float32, copy=False).reshape(k, n)
            if not np.all(np.isfinite(rows)) or np.any(rows < 0):
                raise VolumeError(f"{self.path}: mixture must be finite and non-negative")
            yield v0, rows

    def labels_meta(self, vp, q: Quantization) -> Volume:
        """A labels Volume with this file's inks, g, ior, boundary and origin on the printer grid ``vp``, for
        ``RunDir.quantized_writer`` (its one-voxel labels are a placeholder: the real ones go to the file)."""
        return Volume.from_labels(
            vp,
            labels=np.zeros((1, 1, 1), np.uint8),
            inks=self.inks,
            g=self.g,
            ior=self.ior,
            boundary=self.boundary,
            origin_mm=self.origin_mm,
            quantization=q,
        )

    def close(self) -> None:
        self._whole = None
        for handle in (getattr(self, "_fh", None), self._zip):
            if handle is not None:
                handle.close()
