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
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from ..io import ZIP_READ_ERRORS
from .banded import BandMixture, band_mixture, most_common_row
from .inks import DEFAULT_G, InkTable
from .mask import PackedMask
from .media import InsideLabels, VolumeError
from .volume import Quantization, Volume, check_kinds, file_normals, naming_file, upgrade_volume

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
        self.path, self._zip, self._fh, self._whole = path, None, None, None
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
            small = upgrade_volume({**small, **dict.fromkeys(set(HEAVY) & set(names))}, path)
            check_kinds(small, path)
            if "mixture" not in names:
                form = "labels" if "labels" in names or "labels_file" in names else "dense"
                raise VolumeError(f"{path} holds a {form} volume; {what} needs a mixture volume")
            self._read_small(small)
            self._member = names["mixture"]
            self._open()
            if len(self.shape) != 4 or self.shape[3] != len(self.inks) or self.dtype.kind not in "fiu":
                raise VolumeError(f"{path}: mixture of {self.dtype} {self.shape} does not fit {len(self.inks)} inks")
            self.normals = None
            if "normal_index" in small:
                self.normals = file_normals(self.shape[:3], small)
        except BaseException as exc:
            self.close()
            if isinstance(exc, (*ZIP_READ_ERRORS, TypeError, KeyError, IndexError, OverflowError)):
                raise self._error(exc) from None
            raise

    def _read_small(self, small: dict) -> None:
        """The file's small arrays as this source's attributes (``inside`` checked against ``voxel_mm``'s grid
        when the mixture's shape is known, in ``_open``)."""
        self.g = float(small["g"]) if "g" in small else DEFAULT_G
        self.voxel_mm = np.asarray(small["voxel_mm"], np.float64).reshape(-1)
        if self.voxel_mm.shape != (3,) or not np.all(np.isfinite(self.voxel_mm)) or np.any(self.voxel_mm <= 0):
            raise VolumeError(f"{self.path}: voxel_mm must be 3 positive sizes (x, y, z) in mm")
        self.inks = InkTable.from_arrays(small, self.g)
        self.ior = float(small["ior"]) if "ior" in small else 1.5
        self.boundary = str(small["boundary"]) if "boundary" in small else "box"
        self.origin_mm = None if "origin_mm" not in small else np.asarray(small["origin_mm"], np.float64).reshape(3)
        if self.origin_mm is not None and not np.all(np.isfinite(self.origin_mm)):
            raise VolumeError(f"{self.path}: origin_mm must be finite (x, y, z) in mm")
        self.inside = np.asarray(small["inside"], bool) if "inside" in small else None

    def _error(self, exc: BaseException) -> Exception:
        """What reading the file raised, as one line naming it."""
        if isinstance(exc, ParameterError) or not isinstance(exc, ZIP_READ_ERRORS):
            return naming_file(exc, self.path)
        text = " ".join(str(exc).split())
        return VolumeError(f"{self.path} is not a readable .npz volume file ({type(exc).__name__}: {text})")

    @contextmanager
    def _reading(self) -> Iterator[None]:
        """Errors of reading the mixture member (a bad CRC, corrupt data) as one line naming the file."""
        try:
            yield
        except (*ZIP_READ_ERRORS, TypeError) as exc:
            raise self._error(exc) from None

    def __enter__(self) -> MixtureSource:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _open(self) -> None:
        self._fh = self._zip.open(self._member)
        self.shape, self._fortran, self.dtype = _read_header(self._fh)
        if self.inside is not None and self.inside.shape != tuple(self.shape[:3]):
            raise VolumeError(f"{self.path}: inside mask {self.inside.shape} differs from the mixture's grid")
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
            with self._reading():
                self._whole = np.lib.format.read_array(self._zip.open(self._member), allow_pickle=False)
        return self._whole

    def __getitem__(self, z: int) -> np.ndarray:
        z = int(z)
        if z in self._kept:
            return self._kept[z]
        if not 0 <= z < self.shape[0]:
            raise IndexError(f"layer {z} outside 0..{self.shape[0] - 1}")
        if self._fortran:
            return self._checked(np.ascontiguousarray(self._fortran_whole()[z]), z)
        with self._reading():
            if z < self._next:
                self._fh.close()
                self._open()
            n = int(np.prod(self.shape[1:])) * self.dtype.itemsize
            while self._next <= z:
                data = self._read(n)
                self._next += 1
        lay = self._checked(np.frombuffer(data, self.dtype).reshape(self.shape[1:]), z)
        if len(self._kept) >= 2:
            self._kept.pop(min(self._kept))
        self._kept[z] = lay
        return lay

    def _checked(self, lay: np.ndarray, z: int) -> np.ndarray:
        """Layer ``z``, checked as ``Mixture`` checks the whole (finite and non-negative as float32)."""
        as_read = np.asarray(lay, np.float32)
        if not np.all(np.isfinite(as_read)) or np.any(as_read < 0):
            raise VolumeError(f"{self.path}: mixture must be finite and non-negative (layer {z})")
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
        with self._reading():
            self._fh.close()
            self._open()
        self._next = self.shape[0]  # the layer reader's position is lost: its next layer reopens the member
        flat = None if not self._fortran else self._fortran_whole().reshape(-1, n)  # a C-order copy
        for v0 in range(0, total, voxels):
            k = min(voxels, total - v0)
            if flat is not None:
                rows = flat[v0 : v0 + k].astype(np.float32, copy=False)
            else:
                with self._reading():
                    raw = np.frombuffer(self._read(k * n * self.dtype.itemsize), self.dtype)
                rows = raw.astype(np.float32, copy=False).reshape(k, n)
            if not np.all(np.isfinite(rows)) or np.any(rows < 0):
                raise VolumeError(f"{self.path}: mixture must be finite and non-negative")
            yield v0, rows

    def band_volume(self) -> BandMixture:
        """This volume for a renderer, in proportion to its band: a ``BandMixture`` (``model.banded``) whose band is
        the inside voxels whose mixture is not the core's, its volume's medium a placeholder that holds nothing per
        voxel (``InsideLabels`` of ink 0: a renderer takes the band's mixture from ``set_mixture``). The core is the
        mixture most inside voxels of the middle layer hold (a run's fixed core below its shell; any choice is
        exact, as every other voxel is in the band). Read a layer at a time: 8 B of index and 4N of mixture per band
        voxel, the inside mask's bits; the mixtures are those ``Volume.load`` holds, bit for bit. Only for a volume
        with an inside mask."""
        inside = self.inside
        if inside is None:  # a mask would change how a renderer walks it
            raise VolumeError(f"{self.path} has no inside mask: read it whole (Volume.load), not by a band")
        if not inside.any():
            raise VolumeError(f"{self.path}: the volume has no inside voxel")
        mask = PackedMask(inside)  # one bit per voxel, shared by the volume and its placeholder medium
        geometry = Volume(
            self.voxel_mm,
            InsideLabels(mask, 0, self.inks),
            g=self.g,
            ior=self.ior,
            inside=mask,
            normals=self.normals,
            boundary=self.boundary,
            origin_mm=self.origin_mm,
        )
        return band_mixture(geometry, self, most_common_row(self, inside))

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
