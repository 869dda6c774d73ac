"""The voxel volume: geometry plus one medium in one of three explicit forms, and its ``.npz`` file.

Conventions (docs/conventions.md): arrays are (z, y, x[, c]); ``voxel_mm``, ``origin_mm`` and normals are
(x, y, z); coefficients in mm^-1; z = 0 is the bottom layer.

Medium forms (``model.media``; exactly one per volume, ``Volume.medium``):

- ``Dense``:   ``sigma_s``, ``sigma_a`` float32 (z, y, x, 3), mm^-1
- ``Mixture``: ``mixture`` float32 (z, y, x, N), rows summing to 1, plus the ink table
- ``Labels``:  ``labels`` uint8 (z, y, x), ink index per voxel (``EMPTY`` = 255 = no ink), plus the ink table

The volume file (``.npz``) stores the medium's arrays under those names; the ink table as ``ink_names`` (N,) str,
``ink_sigma_s``/``ink_sigma_a`` float32 (N, 3) mm^-1. Always: ``voxel_mm`` (3,) float (x, y, z). Optional:
``g`` (default 0.4), ``ior`` (default 1.5), ``inside`` bool (z, y, x) (default: the whole box), outward shading
normals of the surface voxels as ``normal_index`` (K,) int64 linear indices and ``normal_vectors`` (K, 3) float32
(x, y, z) (``model.normals.SurfaceNormals``), ``boundary`` ("box" or "periodic-xy"), ``origin_mm`` (3,) (x, y, z
of voxel (0, 0, 0)'s low corner; meshes), and for quantized volumes the ``Quantization`` record ``method``,
``seed``, ``dpi`` (3,) (x, y, z), ``upsample``, ``ink_order``. Instead of ``labels`` a file may name
``labels_file`` (a .npy beside it, ``model.labelfile``; shape ``labels_shape``): the labels are then memory-mapped
read-only. Every file carries ``format_version`` int64 (``VOLUME_FORMAT``); :func:`upgrade_volume` reads the older
versions users may hold.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from ..io import FORMAT_KEY, FormatError, Streamed, load_npz, save_npz, upgrade_format
from .inks import DEFAULT_G, InkTable, mix
from .labelfile import load_label_file
from .mask import PackedMask
from .media import EMPTY, Band, Dense, InsideLabels, Labels, Medium, Mixture, NonEmpty, Quantization, VolumeError
from .normals import SurfaceNormals

BOUNDARIES = ("box", "periodic-xy")
# Memory the renderer may use for one volume; a volume above this is refused (bytes).
MAX_VOLUME_BYTES = int(os.environ.get("INKOPT_MAX_VOLUME_BYTES", 16 * 2**30))
#: the most voxels one grid may have (the renderer indexes voxels with 32-bit integers)
MAX_GRID_VOXELS = 2**31


def check_grid_budget(what: str, size_mm, dpi: float, bytes_per_voxel: float, smaller: str) -> None:
    """One-line VolumeError, before anything is built, for an object of ``size_mm`` (x, y, z) whose grid at ``dpi``
    has more than ``MAX_GRID_VOXELS`` voxels or needs more than ``MAX_VOLUME_BYTES`` (INKOPT_MAX_VOLUME_BYTES) at
    ``bytes_per_voxel`` (a lower bound of the memory per grid voxel). It names ``what``, the grid, the memory, the
    ``dpi`` that would fit and ``smaller`` (the parameter that makes the object smaller)."""
    size = np.asarray(size_mm, np.float64)
    n = np.maximum(np.ceil(size / (25.4 / dpi)), 1)
    voxels, need = float(np.prod(n)), float(np.prod(n)) * bytes_per_voxel
    limit = min(MAX_VOLUME_BYTES, MAX_GRID_VOXELS * bytes_per_voxel)
    if need <= limit:
        return
    fit = dpi * (limit / need) ** (1 / 3) * 0.95
    raise VolumeError(
        f"{what}: {size[0]:.0f} x {size[1]:.0f} x {size[2]:.0f} mm at {dpi:g} DPI is a grid of "
        f"{int(n[0])} x {int(n[1])} x {int(n[2])} voxels ({voxels:.2g}), which needs at least "
        f"{need / 2**30:.0f} GiB (limit {limit / 2**30:.0f} GiB, INKOPT_MAX_VOLUME_BYTES and 2^31 voxels); use "
        f"`dpi` {np.floor(fit):.0f} or less, or a smaller `{smaller}`"
    )


#: the format version volume files are written in (``format_version``; ``upgrade_volume`` reads older ones)
VOLUME_FORMAT = 1


# ----------------------------------------------------------------------------------------- the volume
@dataclass
class Volume:
    """A voxel medium on a grid: geometry plus one medium (``Dense``, ``Mixture`` or ``Labels``). Build it from a
    medium, ``Volume(voxel_mm, Mixture(m, inks), ...)``, or with the classmethods :meth:`from_coefficients`,
    :meth:`from_mixture` and :meth:`from_labels`; the medium's arrays read back as ``sigma_s``, ``sigma_a``,
    ``mixture``, ``labels`` and ``inks`` (None where the medium has no such array)."""

    voxel_mm: np.ndarray
    medium: Medium
    g: float = DEFAULT_G
    ior: float = 1.5
    #: the inside voxels (``PackedMask``, a bit per grid voxel; a (z, y, x) bool array given is packed)
    inside: PackedMask | None = None
    #: shading normals of the surface voxels (``SurfaceNormals``; a dense (z, y, x, 3) array is converted)
    normals: SurfaceNormals | None = None
    boundary: str = "box"
    origin_mm: np.ndarray | None = None
    quantization: Quantization | None = None
    #: the object as a band and one core mixture (``media.Band``; needs ``inside`` and an ink table): the renderer
    #: stores only the band's coefficients and renders every other inside voxel with the core's mixture
    band: Band | None = None

    def __post_init__(self):
        self.voxel_mm = np.asarray(self.voxel_mm, dtype=np.float64).reshape(-1)
        if not isinstance(self.medium, (Dense, Mixture, Labels)):
            raise VolumeError(f"a volume's medium is a Dense, Mixture or Labels, not {type(self.medium).__name__}")
        if self.origin_mm is not None:
            self.origin_mm = np.asarray(self.origin_mm, np.float64).reshape(3)
        self.validate()

    @classmethod
    def from_coefficients(cls, voxel_mm, sigma_s: np.ndarray, sigma_a: np.ndarray, **geometry) -> Volume:
        """A dense volume: ``sigma_s``, ``sigma_a`` (z, y, x, 3) float32 mm^-1; ``geometry``: the other fields."""
        return cls(voxel_mm, Dense(sigma_s, sigma_a), **geometry)

    @classmethod
    def from_mixture(cls, voxel_mm, mixture: np.ndarray, inks: InkTable, **geometry) -> Volume:
        """A mixture volume: ink shares ``mixture`` (z, y, x, N) float32 of ``inks``."""
        return cls(voxel_mm, Mixture(mixture, inks), **geometry)

    @classmethod
    def from_labels(cls, voxel_mm, labels: np.ndarray, inks: InkTable, **geometry) -> Volume:
        """A labels volume: one ink index of ``inks`` per voxel, ``labels`` (z, y, x) uint8 (``EMPTY``: none)."""
        return cls(voxel_mm, Labels(labels, inks), **geometry)

    @property
    def sigma_s(self) -> np.ndarray | None:
        return getattr(self.medium, "sigma_s", None)

    @property
    def sigma_a(self) -> np.ndarray | None:
        return getattr(self.medium, "sigma_a", None)

    @property
    def mixture(self) -> np.ndarray | None:
        return getattr(self.medium, "mixture", None)

    @property
    def labels(self) -> np.ndarray | None:
        return getattr(self.medium, "labels", None)

    @property
    def inks(self) -> InkTable | None:
        return getattr(self.medium, "inks", None)

    @property
    def form(self) -> str:
        """ "dense", "mixture" or "labels"."""
        return self.medium.form

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(int(s) for s in self.medium.shape)

    def validate(self) -> None:
        if self.voxel_mm.shape != (3,) or not np.all(np.isfinite(self.voxel_mm)) or np.any(self.voxel_mm <= 0):
            raise VolumeError(f"voxel_mm must be 3 positive finite sizes (x, y, z) in mm, got {self.voxel_mm}")
        if self.boundary not in BOUNDARIES:
            raise VolumeError(f"unknown boundary '{self.boundary}'; use one of {list(BOUNDARIES)}")
        if not -1 < self.g < 1:
            raise VolumeError(f"g must lie in (-1, 1), got {self.g}")
        if not (np.isfinite(self.ior) and self.ior > 0):
            raise VolumeError(f"ior must be positive, got {self.ior}")
        if self.origin_mm is not None and not np.all(np.isfinite(self.origin_mm)):
            raise VolumeError(f"origin_mm must be finite (x, y, z) in mm, got {self.origin_mm}")
        shp = self.shape
        if min(shp) < 1:
            raise VolumeError(f"volume shape {shp} is empty")
        if self.inside is not None:
            shape = tuple(self.inside.shape) if isinstance(self.inside, PackedMask) else np.shape(self.inside)
            if shape != shp:
                raise VolumeError(f"inside mask shape {shape} differs from volume shape {shp}")
            if not isinstance(self.inside, PackedMask):  # kept as bits (1 bit per grid voxel)
                self.inside = PackedMask(self.inside)
        if self.normals is not None:
            try:
                if not isinstance(self.normals, SurfaceNormals):
                    self.normals = SurfaceNormals.from_dense(self.normals)
            except ValueError as exc:
                raise VolumeError(str(exc)) from None
            if self.normals.shape != shp:
                raise VolumeError(f"normals are for a grid of shape {self.normals.shape}, the volume is {shp}")
        if self.band is not None:
            if self.inside is None or self.inks is None:
                raise VolumeError("a volume with a band needs an inside mask and an ink table")
            self.band.check(self.inside, len(self.inks))
        need = self.render_bytes()
        if need > MAX_VOLUME_BYTES:
            raise VolumeError(
                f"volume {' x '.join(str(int(v)) for v in shp)} (z, y, x) needs {need / 2**30:.1f} GiB to render, "
                f"more than the {MAX_VOLUME_BYTES / 2**30:.1f} GiB allowed (INKOPT_MAX_VOLUME_BYTES); use a coarser "
                f"grid (`dpi`) or a smaller object"
            )

    def render_bytes(self) -> int:
        """Memory the renderer needs for this medium (bytes): labels 1 per voxel; coefficients 24 per voxel
        (sigma_t, albedo f32 x 3 channels), or with an inside mask 4 per voxel (slot) + 24 per inside voxel, or with
        a band 24 per band voxel and ~16 per grid row; the mask and its safe distances 2 per voxel; 20 per shading
        normal."""
        n = int(np.prod(self.shape, dtype=np.int64))
        if self.band is not None:
            need = 24 * len(self.band.index) + 16 * (n // self.shape[2])
        elif self.form == "labels":
            need = n
        elif self.inside is not None:
            need = 4 * n + 24 * self.inside.count
        else:
            need = 24 * n
        need += 2 * n if self.inside is not None else 0
        return need + (20 * len(self.normals.index) if self.normals is not None else 0)

    # ----------------------------------------------------------------- conversions
    def coefficients(self) -> tuple[np.ndarray, np.ndarray]:
        """(sigma_s, sigma_a), each (z, y, x, 3) float32 mm^-1."""
        med = self.medium
        if isinstance(med, Dense):
            return med.sigma_s, med.sigma_a
        if isinstance(med, Mixture):
            return mix(med.mixture, med.inks)
        s = np.zeros(self.shape + (3,), np.float32)
        a = np.zeros_like(s)
        for k in range(len(med.inks)):
            sel = np.asarray(med.labels) == k  # a layered label file decoded
            s[sel] = med.inks.sigma_s[k]
            a[sel] = med.inks.sigma_a[k]
        return s, a

    def coefficients_at(self, index: np.ndarray, chunk: int = 1 << 20) -> tuple[np.ndarray, np.ndarray]:
        """(sigma_s, sigma_a) of the voxels ``index`` ((K,) flat (z, y, x) indices), each (K, 3) float32 mm^-1,
        computed ``chunk`` voxels at a time (no grid-sized temporary)."""
        index = np.asarray(index, np.int64)
        s = np.empty((len(index), 3), np.float32)
        a = np.empty_like(s)
        med = self.medium
        for lo in range(0, len(index), chunk):
            ix = index[lo : lo + chunk]
            if isinstance(med, Dense):
                s[lo : lo + chunk] = med.sigma_s.reshape(-1, 3)[ix]
                a[lo : lo + chunk] = med.sigma_a.reshape(-1, 3)[ix]
            elif isinstance(med, Mixture):
                s[lo : lo + chunk], a[lo : lo + chunk] = mix(med.mixture.reshape(-1, len(med.inks))[ix], med.inks)
            else:
                lab = med.labels_at(ix)
                full = lab != EMPTY
                s[lo : lo + chunk] = np.where(full[:, None], med.inks.sigma_s[np.where(full, lab, 0)], 0)
                a[lo : lo + chunk] = np.where(full[:, None], med.inks.sigma_a[np.where(full, lab, 0)], 0)
        return s, a

    def inside_mask(self) -> np.ndarray:
        """(z, y, x) bool: the inside voxels (the mask's dense bytes, a new array; a labels volume without one, its
        labels other than ``EMPTY``; else every voxel)."""
        if self.inside is not None:
            return self.inside.dense()
        if isinstance(self.medium, Labels):
            return np.asarray(self.medium.labels) != EMPTY
        return np.ones(self.shape, bool)

    def inside_planes(self):
        """The inside mask read by z-planes (``mask[z]``, ``mask[z0:z1]``: bool, new arrays; no grid-sized array): its
        bits, a labels volume's labels other than ``EMPTY`` (``NonEmpty``), or None: every voxel."""
        if self.inside is not None or isinstance(self.medium, InsideLabels):  # an InsideLabels' mask
            return self.inside if self.inside is not None else self.medium.inside
        return NonEmpty(self.medium.labels) if isinstance(self.medium, Labels) else None

    def with_medium(self, medium: Medium, **changes) -> Volume:
        """The same geometry with another medium (and any other field ``changes``); no band unless ``changes``
        gives one (another medium need not hold the band's core)."""
        return replace(self, medium=medium, **{"band": None, **changes})

    def with_mixture(self, mixture: np.ndarray) -> Volume:
        """The same geometry and inks with another mixture (z, y, x, N)."""
        return self.with_medium(Mixture(mixture, self.inks))

    def require_mixture(self, what: str = "this step") -> Mixture:
        if not isinstance(self.medium, Mixture):
            raise VolumeError(f"{what} needs a mixture volume, got a {self.form} volume")
        return self.medium

    # ----------------------------------------------------------------- files
    def to_arrays(self) -> dict:
        return {**self.geometry_arrays(), **self.medium.arrays()}

    def save_with_mixture(self, path: str | Path, mixture_slabs, inks: InkTable, compressed: bool = True) -> None:
        """Save this geometry as a mixture volume whose (z, y, x, N) float32 mixture is given as slabs of layers
        (``mixture_slabs``: an iterable of (k, y, x, N) arrays in z order), written one at a time, so the whole
        grid's mixture is never in memory; the file reads back as ``self.with_mixture(whole).save(path)``'s does,
        and each slab is checked like a ``Mixture``'s (finite, non-negative). ``compressed`` False: stored as is
        (larger, written and read without zlib's time)."""
        shape = self.shape + (len(inks),)

        def checked():
            for part in mixture_slabs:
                if not np.all(np.isfinite(part)) or np.any(part < 0):
                    raise VolumeError("mixture must be finite and non-negative")
                yield part

        arrays = {**self.geometry_arrays(), "mixture": Streamed(shape, np.float32, checked()), **inks.to_arrays()}
        save_npz(path, arrays, compressed=compressed)

    def geometry_arrays(self) -> dict:
        """Everything ``to_arrays`` writes but the medium's own arrays."""
        out = {
            FORMAT_KEY: np.int64(VOLUME_FORMAT),
            "voxel_mm": self.voxel_mm,
            "g": np.float64(self.g),
            "ior": np.float64(self.ior),
            "boundary": np.array(self.boundary),
        }
        if self.inside is not None:
            out["inside"] = self.inside.dense()
        if self.normals is not None:
            out["normal_index"], out["normal_vectors"] = self.normals.index, self.normals.vectors
        if self.origin_mm is not None:
            out["origin_mm"] = self.origin_mm
        if self.quantization is not None:
            out.update(self.quantization.arrays())
        return out

    def save(self, path: str | Path) -> None:
        save_npz(path, self.to_arrays())

    @classmethod
    def load(cls, path: str | Path) -> Volume:
        """A volume file (module docstring), brought to the current format version (``upgrade_volume``)."""
        try:
            data = load_npz(path, "volume file")
        except ValueError as exc:
            raise VolumeError(str(exc)) from None
        return cls.from_arrays(upgrade_volume(data, path), path)

    @classmethod
    def from_arrays(cls, data: dict, path: str | Path, layered: bool = False) -> Volume:
        """The volume of a volume file's arrays ``data`` (current format version) from ``path`` (named in errors;
        locates a ``labels_file``, with ``layered`` a layered one read a layer at a time). Arrays that make no
        volume (missing, of the wrong dtype or shape, non-finite) are a one-line VolumeError naming ``path``."""
        try:
            return cls._from_arrays(data, path, layered)
        except (TypeError, ValueError, KeyError, IndexError, OverflowError) as exc:
            raise naming_file(exc, path) from None

    @classmethod
    def _from_arrays(cls, data: dict, path: str | Path, layered: bool = False) -> Volume:
        if "voxel_mm" not in data:
            raise VolumeError(f"{path}: missing array 'voxel_mm' (3 voxel sizes x, y, z in mm)")
        check_kinds(data, path)
        g = float(data["g"]) if "g" in data else DEFAULT_G
        inks = None
        if "ink_names" in data:
            try:
                inks = InkTable.from_arrays(data, g)
            except (KeyError, ValueError) as exc:
                raise VolumeError(f"{path}: bad ink table: {exc}") from None
        labels = data.get("labels")
        if labels is None and "labels_file" in data:  # labels in a sibling .npy (quantized.npz, docs/run-dir.md)
            name = str(data["labels_file"])
            if Path(name).name != name:
                raise VolumeError(f"{path}: labels_file must be a file name beside it, got '{name}'")
            try:
                labels = load_label_file(Path(path).parent / name, data.get("labels_shape"), layered=layered)
            except ValueError as exc:
                raise VolumeError(str(exc)) from None
        vol = cls(
            data["voxel_mm"],
            _medium_of(data.get("sigma_s"), data.get("sigma_a"), data.get("mixture"), labels, inks),
            g=g,
            ior=float(data["ior"]) if "ior" in data else 1.5,
            inside=data.get("inside"),
            boundary=str(data["boundary"]) if "boundary" in data else "box",
            origin_mm=data.get("origin_mm"),
            quantization=Quantization.from_arrays(data),
        )
        if "normal_index" in data:
            try:
                vol.normals = file_normals(vol.shape, data)
            except (KeyError, ValueError) as exc:
                raise VolumeError(f"{path}: bad normals: {exc}") from None
            vol.validate()
        return vol


#: the dtype kinds (``numpy.dtype.kind``) each array of a volume file may have, and what they are called
ARRAY_KINDS = {
    **dict.fromkeys(
        ("voxel_mm", "g", "ior", "origin_mm", "sigma_s", "sigma_a", "mixture", "ink_sigma_s", "ink_sigma_a", "dpi")
        + ("normal_vectors",),
        ("fiu", "numbers"),
    ),
    **dict.fromkeys(("normal_index", "seed", "labels_shape", "label_counts"), ("iu", "integers")),
    **dict.fromkeys(("ink_names", "boundary", "method", "upsample", "ink_order", "labels_file"), ("U", "text")),
    "inside": ("biu", "a mask"),
    "labels": ("u", "uint8 labels"),
}


def check_kinds(data: dict, path) -> None:
    """One-line VolumeError naming ``path`` for an array of a volume file's ``data`` whose dtype is not what the
    file stores there (``ARRAY_KINDS``: complex voxel sizes, text coefficients, fractional indices, ...)."""
    for key, (kinds, what) in ARRAY_KINDS.items():
        if data.get(key) is not None and np.asarray(data[key]).dtype.kind not in kinds:
            raise VolumeError(f"{path}: array '{key}' is {np.asarray(data[key]).dtype}; a volume file holds {what}")


def file_normals(shape, data: dict) -> SurfaceNormals:
    """The shading normals of a file's arrays ``normal_index`` and ``normal_vectors`` for a grid of ``shape``;
    vectors that are not finite (as float32) are a ValueError."""
    with np.errstate(over="ignore", invalid="ignore"):
        normals = SurfaceNormals(shape, data["normal_index"], data["normal_vectors"])
    if not np.all(np.isfinite(normals.vectors)):
        raise ValueError("normals: vectors must be finite")
    return normals


def naming_file(exc: Exception, path, error: type[ParameterError] = VolumeError) -> Exception:
    """``exc``, raised reading the file ``path``, as a one-line ``error`` that names it (a ParameterError naming
    it already is kept)."""
    if isinstance(exc, ParameterError) and str(path) in str(exc):
        return exc
    text = exc.template if isinstance(exc, ParameterError) else f"malformed arrays ({type(exc).__name__}: {exc})"
    return error(f"{path}: {' '.join(text.split())}")


def upgrade_volume(data: dict, where, quantized: bool = False) -> dict:
    """A volume file's arrays (or, for a lazy reader, its small arrays plus the names of the others as keys)
    brought to ``VOLUME_FORMAT``; ``quantized``: the file is a run's quantized.npz. Version 0 (files without
    ``format_version``) reads as version 1, except the pre-release layouts, refused in one line
    (``FormatError``): dense shading normals (``normals`` (z, y, x, 3)) and a quantized.npz holding its labels."""
    kind = "quantized volume" if quantized else "volume file"
    again = (
        f"run 'inkopt quantize {Path(where).parent}' again"
        if quantized
        else "write it again with this inkopt (e.g. rerun the optimisation)"
    )

    def from_0(d: dict) -> dict:
        if "normals" in d:
            raise FormatError(f"{where} stores dense shading normals, a pre-release layout; {again}")
        if quantized and "labels" in d:
            raise FormatError(
                f"{where} holds its labels inside (a pre-release layout, now {Path(where).parent}/"
                f"quantized_labels.npy); {again}"
            )
        return d

    return upgrade_format(data, kind=kind, where=where, current=VOLUME_FORMAT, upgrades={0: from_0})


def _medium_of(sigma_s, sigma_a, mixture, labels, inks) -> Medium:
    """The medium a volume file's arrays hold (exactly one form); one-line VolumeError otherwise."""
    given = [sigma_s is not None or sigma_a is not None, mixture is not None, labels is not None]
    if sum(given) != 1:
        raise VolumeError("volume needs exactly one of: sigma_s+sigma_a, mixture, labels")
    if given[0]:
        if sigma_s is None or sigma_a is None:
            raise VolumeError("dense volume needs both sigma_s and sigma_a")
        return Dense(sigma_s, sigma_a)
    form = "mixture" if given[1] else "labels"
    if inks is None:
        raise VolumeError(f"a {form} volume needs an ink table (ink_names, ink_sigma_s, ink_sigma_a)")
    return Mixture(mixture, inks) if given[1] else Labels(labels, inks)
