"""The three forms of a volume's medium (``Dense`` coefficients, an ink ``Mixture``, ink ``Labels``), an object's
``Band`` (the voxels near its surface that may differ from its one core mixture) and the quantization settings of a
labels volume; ``Volume`` (``model.volume``) holds one medium on its grid, and a band where it has one.

Conventions (docs/conventions.md): arrays are (z, y, x[, c]); coefficients in mm^-1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from .inks import InkTable
from .labelfile import LabelLayers
from .mask import PackedMask

EMPTY = 255  # the label of a voxel without ink


class VolumeError(ParameterError):
    """A volume that cannot be rendered or held; the message is one line naming the problem (and the parameters
    that would change it, in backticks: ``errors.ParameterError``)."""


# ----------------------------------------------------------------------------------------- medium forms
@dataclass
class Dense:
    """Per-voxel coefficients (z, y, x, 3) float32 mm^-1."""

    sigma_s: np.ndarray
    sigma_a: np.ndarray
    form = "dense"

    def __post_init__(self):
        for key in ("sigma_s", "sigma_a"):
            arr = np.ascontiguousarray(getattr(self, key), dtype=np.float32)
            if arr.ndim != 4 or arr.shape[3] != 3:
                raise VolumeError(f"{key} must have shape (z, y, x, 3), got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise VolumeError(f"{key} contains NaN or infinite values")
            if np.any(arr < 0):
                raise VolumeError(f"{key} contains negative coefficients")
            setattr(self, key, arr)
        if self.sigma_s.shape != self.sigma_a.shape:
            raise VolumeError(f"sigma_s {self.sigma_s.shape} and sigma_a {self.sigma_a.shape} differ in shape")

    @property
    def shape(self):
        return self.sigma_s.shape[:3]

    def arrays(self) -> dict:
        return {"sigma_s": self.sigma_s, "sigma_a": self.sigma_a}


@dataclass
class Mixture:
    """Per-voxel ink shares (z, y, x, N) float32 of the ink table ``inks``."""

    mixture: np.ndarray
    inks: InkTable
    form = "mixture"

    def __post_init__(self):
        m = np.ascontiguousarray(self.mixture, dtype=np.float32)
        if m.ndim != 4 or m.shape[3] != len(self.inks):
            raise VolumeError(f"mixture must have shape (z, y, x, {len(self.inks)}), got {m.shape}")
        step = max(1, 2**22 // max(1, m[0].size))  # checked in slabs of layers: bounded temporaries
        for z in range(0, m.shape[0], step):
            part = m[z : z + step]
            if not np.all(np.isfinite(part)) or np.any(part < 0):
                raise VolumeError("mixture must be finite and non-negative")
        self.mixture = m

    @property
    def shape(self):
        return self.mixture.shape[:3]

    def arrays(self) -> dict:
        return {"mixture": self.mixture, **self.inks.to_arrays()}


@dataclass
class Labels:
    """One ink index per voxel (z, y, x) uint8 of the ink table ``inks``; ``EMPTY`` = no ink."""

    labels: np.ndarray
    inks: InkTable
    form = "labels"

    def __post_init__(self):
        # a read-only memory map (a label file) stays one; a layered label file (``labelfile.LabelLayers``) stays
        # read a layer at a time
        lab = self.labels if isinstance(self.labels, LabelLayers) else np.ascontiguousarray(self.labels)
        if lab.dtype != np.uint8 or lab.ndim != 3:
            raise VolumeError(f"labels must be uint8 (z, y, x), got {lab.dtype} {lab.shape}")
        # checked in slabs of layers (bounded temporaries); a layered file a layer at a time, as it is decoded
        step = 1 if isinstance(lab, LabelLayers) else max(1, 2**24 // max(1, lab[0].size))
        for z in range(0, lab.shape[0], step):
            used = lab[z : z + step][lab[z : z + step] != EMPTY]
            if used.size and int(used.max()) >= len(self.inks):
                raise VolumeError(f"labels use ink {int(used.max())} but the ink table has {len(self.inks)}")
        self.labels = lab

    @property
    def shape(self):
        return self.labels.shape

    def labels_at(self, index: np.ndarray) -> np.ndarray:
        """(K,) uint8 labels of the voxels ``index`` ((K,) int64 flat (z, y, x) indices)."""
        if not isinstance(self.labels, LabelLayers):
            return self.labels.reshape(-1)[index]
        index = np.asarray(index, np.int64)
        plane = int(np.prod(self.shape[1:]))
        out = np.empty(len(index), np.uint8)
        z = index // plane
        for k in np.unique(z):  # each layer decoded once
            at = z == k
            out[at] = self.labels[int(k)].reshape(-1)[index[at] - k * plane]
        return out

    def arrays(self) -> dict:
        return {"labels": self.labels, **self.inks.to_arrays()}


class NonEmpty:
    """The inside mask of a label grid (its labels other than ``EMPTY``) read by z-planes, as ``PackedMask`` is:
    ``mask[z]`` (y, x) bool, ``mask[z0:z1]`` (k, y, x) bool, new arrays made from those planes of the labels only
    (a layered label file is never decoded whole)."""

    def __init__(self, labels):
        self.labels = labels
        self.shape = tuple(int(s) for s in labels.shape)

    def __getitem__(self, key) -> np.ndarray:
        if isinstance(key, (int, np.integer)) or (isinstance(key, slice) and key.step in (None, 1)):
            return np.asarray(self.labels[key]) != EMPTY
        raise IndexError("a label grid's mask is read by a z-plane or a slice of them")


class InsideLabels(Labels):
    """``Labels`` of one ink ``label`` on every voxel of ``inside`` (a ``PackedMask``, kept by reference; a (z, y, x)
    bool array is packed) and ``EMPTY`` elsewhere, with no label array of its own: an object's base medium (white
    inside) costs nothing per voxel. ``labels`` makes the dense (z, y, x) uint8 array when asked (1 byte per voxel,
    not kept)."""

    def __init__(self, inside, label: int, inks: InkTable):
        self.inside = _packed(inside)
        self.label = int(label)
        self.inks = inks
        if not 0 <= self.label < len(inks):
            raise VolumeError(f"label {self.label} is not an ink of the table's {len(inks)}")

    @property
    def labels(self) -> np.ndarray:
        return np.where(self.inside.dense(), np.uint8(self.label), np.uint8(EMPTY))

    @property
    def shape(self):
        return self.inside.shape

    def labels_at(self, index: np.ndarray) -> np.ndarray:
        return np.where(self.inside.at(index), np.uint8(self.label), np.uint8(EMPTY))

    def __repr__(self) -> str:
        return f"InsideLabels(ink {self.label} on {self.inside.shape} inside, {len(self.inks)} inks)"


Medium = Dense | Mixture | Labels


def _packed(inside) -> PackedMask:
    """``inside`` as a ``PackedMask`` (itself if it is one; a (z, y, x) bool array is packed)."""
    if isinstance(inside, PackedMask):
        return inside
    inside = np.asarray(inside, bool)
    if inside.ndim != 3:
        raise VolumeError(f"an inside mask must be (z, y, x), got shape {inside.shape}")
    return PackedMask(inside)


@dataclass(frozen=True)
class Band:
    """An object as a band and a core: the inside voxels ``index`` ((K,) int64, strictly increasing flat (z, y, x)
    indices: the optimiser's free voxels and the fixed ones whose shares are not the core's) may hold any mixture;
    every other inside voxel holds ``core`` ((N,) float32 ink shares). The renderer then stores coefficients only
    for the band (``_core.Medium.band``: 24 bytes per band voxel) and one pair per channel for the core."""

    index: np.ndarray
    core: np.ndarray

    def __post_init__(self):
        index = np.ascontiguousarray(self.index, np.int64).reshape(-1)
        if len(index) > 1 and np.any(np.diff(index) <= 0):
            raise VolumeError("a band's index must be strictly increasing voxel indices")
        object.__setattr__(self, "index", index)
        object.__setattr__(self, "core", np.ascontiguousarray(self.core, np.float32).reshape(-1))

    @classmethod
    def of_fixed(cls, inside, fixed) -> Band:
        """The band of an object whose inside voxels (``inside``) are free or hold fixed shares ``fixed``
        (``model.fixed.FixedShares``: ``held`` in every voxel that is not free, except its indexed rows): the
        inside voxels that are free or indexed, and ``held`` as the core (a (z, y, x) bool ``inside`` is packed)."""
        mask, inside = fixed.mask, _packed(inside)
        step = mask.STEP  # voxels at a time: no grid-sized temporary
        free = np.concatenate(
            [np.flatnonzero(mask.range(a, a + step) & inside.range(a, a + step)) + a for a in range(0, mask.size, step)]
            or [np.empty(0, np.int64)]
        )
        rows = fixed.index[inside.at(fixed.index)]
        return cls(np.union1d(free, rows) if len(rows) else free, fixed.held)

    def check(self, inside, n_inks: int) -> None:
        """One-line VolumeError unless the band lies inside ``inside`` and ``core`` has ``n_inks`` finite
        non-negative shares (a (z, y, x) bool ``inside`` is packed)."""
        inside = _packed(inside)
        if len(self.core) != n_inks or not np.all(np.isfinite(self.core)) or np.any(self.core < 0):
            raise VolumeError(f"a band's core must be {n_inks} finite non-negative ink shares, got {self.core}")
        n = inside.size
        if len(self.index) and (self.index[0] < 0 or self.index[-1] >= n or not inside.at(self.index).all()):
            raise VolumeError("a band's voxels must lie inside the object")


@dataclass(frozen=True)
class Quantization:
    """The settings of a quantization (``inkopt.printing.quantize``): the one form they travel in, from the command
    line to the dither, and, kept in a labels volume, the record of how it was made.

    method     the dither's name (``printing.dithers.DITHERS``: "count-adaptive", blue noise where the mixture is
               smooth and its counts diffused where it changes from voxel to voxel, nearest upsampling only;
               "blue-noise", "blue-noise-columns", "count-diffusion", "random", "error-diffusion")
    seed       the dither's random state (``numpy.random.default_rng(seed)``)
    dpi        printer resolution (x, y) or (x, y, z) dots per inch; None: 600 x 300 (``units.PRINTER_DPI``). A record
               holds (x, y, z), the printer voxels' own (``printing.quantize.record``); an old file may hold None
    upsample   "nearest" or "linear" (``printing.grid.UPSAMPLERS``)
    ink_order  the order of the inks' bands where the dither orders them (blue noise, either kind): "lightness"
               (lightest first, ``dither.lightness_order``), "tint-first" (the second lightest before the lightest,
               ``printing.dithers``) or "index" (the ink set's order; files that do not say were made so)
    layer_um   layer thickness in µm where ``dpi`` has no z entry; None: 27 (``units.PRINTER_LAYER_UM``). Not
               recorded: a record's ``dpi`` holds z
    refine     iterations of the refinement on the printed prediction before the dither (``printing.refine``: the
               run's loss taken on the quantized labels' render; 0: none). A run's quantization does them
               (``printing.stream.quantize_run``: they need the run's scene); ``quantize`` dithers the mixture it
               is given and ignores it
    compensate whether the dither is given each ink's share pre-compensated for the halftone's package effect
               (``printing.compensate``: measured once per ink set and printer grid, then cached); files that do
               not say were made without
    ``printing.quantize.check_quantization`` checks them; a labels volume file stores a record's ``arrays``."""

    method: str = "count-adaptive"
    seed: int = 0
    dpi: tuple[float, ...] | None = None
    upsample: str = "nearest"
    ink_order: str = "lightness"
    layer_um: float | None = None
    refine: int = 0
    compensate: bool = False

    def __post_init__(self):
        if self.dpi is not None:  # a tuple (lists and arrays compare and hash as settings do)
            object.__setattr__(self, "dpi", tuple(None if v is None else float(v) for v in self.dpi))

    def arrays(self) -> dict:
        out = {"method": np.array(self.method), "seed": np.int64(self.seed), "upsample": np.array(self.upsample)}
        out["ink_order"] = np.array(self.ink_order)
        if self.dpi is not None:
            out["dpi"] = np.asarray(self.dpi, np.float64)
        if self.refine:
            out["refine"] = np.int64(self.refine)
        if self.compensate:
            out["compensate"] = np.bool_(True)
        return out

    def to_json(self) -> dict:
        """The recorded settings as JSON values (``method``, ``seed``, ``dpi`` list or None, ``upsample``,
        ``ink_order``, and ``refine`` and ``compensate`` where they are not 0 / false): what evaluation.json says of
        its labels volume."""
        dpi = None if self.dpi is None else list(self.dpi)
        refined = {"refine": self.refine} if self.refine else {}
        refined.update({"compensate": True} if self.compensate else {})
        return {
            "method": self.method,
            "seed": self.seed,
            "dpi": dpi,
            "upsample": self.upsample,
            "ink_order": self.ink_order,
            **refined,
        }

    @classmethod
    def from_arrays(cls, data) -> Quantization | None:
        if "method" not in data:
            return None
        return cls(
            str(data["method"]),
            int(data["seed"]) if "seed" in data else 0,
            tuple(float(v) for v in np.asarray(data["dpi"]).reshape(-1)) if "dpi" in data else None,
            str(data["upsample"]) if "upsample" in data else "nearest",
            str(data["ink_order"]) if "ink_order" in data else "index",
            refine=int(data["refine"]) if "refine" in data else 0,
            compensate=bool(data["compensate"]) if "compensate" in data else False,
        )
