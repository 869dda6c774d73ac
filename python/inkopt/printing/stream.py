"""Quantization of a run without the whole printer label volume (or the whole mixture) in memory.

``MixtureSource`` reads a mixture volume file (volume.npz) lazily: its small arrays (voxel size, ink table,
``g``, ``ior``, boundary, origin, the ``inside`` mask: 1 byte per optimisation voxel) at once, the ``mixture``
one (y, x, N) layer at a time by decompressing its zip member sequentially (layers are asked for in increasing
z; going back further than the two layers it keeps reopens the member), and the shading normals of the surface
voxels (small). Its format version is checked as ``Volume.load`` checks it (``model.volume.upgrade_volume``).

``quantize_run`` is ``inkopt quantize``: the labels go layer by layer from ``quantize.quantize`` into the run's
label file (``RunDir.quantized_writer``: quantized.npz + quantized_labels.npy, docs/run-dir.md), so memory holds
the inside mask, a few mixture layers and a few printer layers; a mesh's shading normals go to the printer grid
by ``quantize.upsample_normals`` (20 bytes per printer voxel inside a surface voxel). Labels and normals are
identical to ``quantize_volume``'s in memory.
"""

from __future__ import annotations

import time
import zipfile

import numpy as np

from ..model import InkTable, Quantization, SurfaceNormals, Volume
from ..model.inks import DEFAULT_G
from ..model.volume import upgrade_volume
from ..rundir import RunDir
from ..units import MM_PER_INCH
from .quantize import printer_grid, quantize, summary_lines, upsample_normals

HEAVY = ("mixture", "normals")  # members not loaded at once (dense normals: a pre-release layout, refused)


def _read_header(fh):
    major, _ = np.lib.format.read_magic(fh)
    read = np.lib.format.read_array_header_1_0 if major == 1 else np.lib.format.read_array_header_2_0
    return read(fh)


class MixtureSource:
    """A mixture volume file read lazily (module docstring). ``shape`` (z, y, x, N); ``[z]`` one layer
    (y, x, N); ``inside`` (z, y, x) bool or None; ``voxel_mm``, ``inks``, ``g``, ``ior``, ``boundary``,
    ``origin_mm``; ``normals`` (``SurfaceNormals`` or None)."""

    def __init__(self, path):
        self.path, self._zip = path, None
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
            raise ValueError(f"{path} is not a readable .npz volume file ({type(exc).__name__}: {exc})") from None
        try:
            small = upgrade_volume({**small, **dict.fromkeys(set(HEAVY) & set(names))}, path)
        except ValueError:
            self.close()
            raise
        if "mixture" not in names:
            self.close()
            form = "labels" if "labels" in names else "dense"
            raise ValueError(f"{path} holds a {form} volume; this step needs a mixture volume")
        self.g = float(small["g"]) if "g" in small else DEFAULT_G
        self.voxel_mm = np.asarray(small["voxel_mm"], np.float64).reshape(-1)
        self.inks = InkTable.from_arrays(small, self.g)
        self.ior = float(small["ior"]) if "ior" in small else 1.5
        self.boundary = str(small["boundary"]) if "boundary" in small else "box"
        self.origin_mm = small.get("origin_mm")
        self.inside = np.asarray(small["inside"], bool) if "inside" in small else None
        self._member = names["mixture"]
        self._open()
        if len(self.shape) != 4 or self.shape[3] != len(self.inks) or self._fortran:
            raise ValueError(f"{path}: mixture of shape {self.shape} does not fit {len(self.inks)} inks")
        self.normals = None
        try:
            if "normal_index" in small:
                self.normals = SurfaceNormals(self.shape[:3], small["normal_index"], small["normal_vectors"])
            if self.normals is not None and self.normals.shape != tuple(self.shape[:3]):
                raise ValueError(f"normals for a grid of {self.normals.shape}, the mixture is {self.shape[:3]}")
        except (KeyError, ValueError) as exc:
            self.close()
            raise ValueError(f"{path}: bad shading normals ({exc})") from None

    def _open(self) -> None:
        self._fh = self._zip.open(self._member)
        self.shape, self._fortran, self.dtype = _read_header(self._fh)
        self._next = 0
        self._kept: dict[int, np.ndarray] = {}

    def __getitem__(self, z: int) -> np.ndarray:
        z = int(z)
        if z in self._kept:
            return self._kept[z]
        if not 0 <= z < self.shape[0]:
            raise IndexError(f"layer {z} outside 0..{self.shape[0] - 1}")
        if z < self._next:
            self._fh.close()
            self._open()
        n = int(np.prod(self.shape[1:])) * self.dtype.itemsize
        while self._next <= z:
            data = self._fh.read(n)
            if len(data) != n:
                raise ValueError(f"{self.path}: the mixture ends after {self._next} layers")
            self._next += 1
        lay = np.frombuffer(data, self.dtype).reshape(self.shape[1:])
        if len(self._kept) >= 2:
            self._kept.pop(min(self._kept))
        self._kept[z] = lay
        return lay

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
        for handle in (getattr(self, "_fh", None), self._zip):
            if handle is not None:
                handle.close()


def quantize_run(d: RunDir, *, method: str, dpi, layer_um: float, seed: int, upsample: str) -> list[str]:
    """``inkopt quantize``: DIR/volume.npz -> DIR/quantized.npz + quantized_labels.npy (module docstring).
    Returns the summary lines (``quantize.summary_lines``)."""
    t0 = time.perf_counter()
    digest = d.volume_digest()  # recorded in quantized.npz: export and evaluate refuse it once volume.npz changes
    src = MixtureSource(d.volume_file())
    try:
        shape_p, vp = printer_grid(src.shape[:3], src.voxel_mm, dpi=tuple(dpi), layer_um=layer_um)
        quant = Quantization(method, int(seed), tuple(float(v) for v in MM_PER_INCH / vp), upsample)
        nrm = None if src.normals is None else upsample_normals(src.normals, shape_p, vp, src.voxel_mm)
        with d.quantized_writer(src.labels_meta(vp, quant), shape_p, normals=nrm, volume_digest=digest) as w:
            quantize(
                src,
                src.voxel_mm,
                method=method,
                dpi=tuple(dpi),
                layer_um=layer_um,
                inside=src.inside,
                seed=int(seed),
                upsample=upsample,
                out=w,
            )
        counts = w.counts
    finally:
        src.close()
    return summary_lines(shape_p, vp, src.inks.names, quant, counts, time.perf_counter() - t0)
