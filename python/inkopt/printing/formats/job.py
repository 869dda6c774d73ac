"""A printer job as every output format takes it (``PrintJob``), checked when it is made.

- ``LabelVoxels``: one ink per printer voxel (quantized.npz's labels, possibly memory-mapped) with the voxel size
  and the ink names; ``MixtureVoxels``: the continuous mixture (volume.npz read one layer at a time). Both give a
  layer's ink shares and printed voxels (``shares(k)``, ``occupied(k)``), which is all a 3MF needs.
- ``PrintJob``: the voxels, the printer profile (material slots, material names), the user's material names and
  slice palette, and the files the voxels were made from (``Provenance``).
- ``tally``: the labels' voxel counts per ink in one pass over the layers, refusing labels beyond the ink names and a
  job using more inks than the printer holds (``profiles.check_slots``) before anything is written.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ...errors import ParameterError
from ...model import EMPTY
from ...model.inks import ink_name_problem
from ...model.labelfile import LabelLayers
from ...units import MM_PER_INCH
from ..profiles import PrinterProfile, check_slots, material_name

if TYPE_CHECKING:
    from ...model.mixturefile import MixtureSource


# The voxels' own checks (labels, voxel_mm, inks) are plain ValueErrors: those come from files (quantized.npz,
# volume.npz), not from the command line's flags, so they are not rendered as flags.
def _voxel_mm(voxel_mm) -> np.ndarray:
    vp = np.asarray(voxel_mm, np.float64).reshape(-1)
    if vp.shape != (3,) or not np.all(np.isfinite(vp)) or np.any(vp <= 0):
        raise ValueError(f"voxel_mm must be 3 positive sizes (x, y, z) in mm, got {vp}")
    return vp


@dataclass(frozen=True)
class LabelVoxels:
    """One ink per printer voxel. ``labels`` uint8 (Z, Y, X), 255 = empty: an array (may be memory-mapped) or a
    label file's layers (``model.labelfile.LabelLayers``); formats read one layer at a time. ``voxel_mm`` (x, y, z)
    float64 mm of a printer voxel (DPI = 25.4 / size, layer thickness = z); ``inks`` the ink names, label i ->
    ``inks[i]``."""

    labels: np.ndarray
    voxel_mm: np.ndarray
    inks: tuple[str, ...]

    def __post_init__(self):
        labels = self.labels if isinstance(self.labels, LabelLayers) else np.asarray(self.labels)
        if labels.ndim != 3 or labels.dtype != np.uint8 or min(labels.shape) < 1:
            raise ValueError(f"labels must be a non-empty uint8 (Z, Y, X) array, got {labels.dtype} {labels.shape}")
        names = tuple(str(n) for n in self.inks)
        if not names or len(set(names)) != len(names) or len(names) >= EMPTY:
            raise ValueError(f"inks must be 1..{EMPTY - 1} unique names, got {list(names)}")
        for name in names:  # they name materials in the packages' XML
            if problem := ink_name_problem(name):
                raise ValueError(f"ink name {name!r} {problem}")
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "voxel_mm", _voxel_mm(self.voxel_mm))
        object.__setattr__(self, "inks", names)

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(int(v) for v in self.labels.shape)

    @property
    def dpi(self) -> tuple[float, float]:
        """(x, y) dots per inch of the printer grid."""
        return MM_PER_INCH / self.voxel_mm[0], MM_PER_INCH / self.voxel_mm[1]

    def shares(self, k: int) -> np.ndarray:
        """(Y, X, N) float32 shares of layer ``k``: 1 for each voxel's ink, 0 elsewhere (and in empty voxels)."""
        n = len(self.inks)
        eye = np.vstack([np.eye(n, dtype=np.float32), np.zeros((256 - n, n), np.float32)])
        return eye[np.asarray(self.labels[k])]

    def occupied(self, k: int) -> np.ndarray:
        """(Y, X) bool: the printed voxels of layer ``k``."""
        return np.asarray(self.labels[k]) != EMPTY


@dataclass(frozen=True)
class MixtureVoxels:
    """The continuous mixture of ``source`` (a ``model.mixturefile.MixtureSource``, read one layer at a time; the
    caller closes it): every ink may take a share in any voxel, every inside voxel is printed."""

    source: MixtureSource

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(int(v) for v in self.source.shape[:3])

    @property
    def voxel_mm(self) -> np.ndarray:
        return _voxel_mm(self.source.voxel_mm)

    @property
    def inks(self) -> tuple[str, ...]:
        return tuple(str(n) for n in self.source.inks.names)

    def shares(self, k: int) -> np.ndarray:
        """(Y, X, N) shares of layer ``k`` in the file's dtype."""
        return self.source[k]

    def occupied(self, k: int) -> np.ndarray:
        inside = self.source.inside
        return np.ones(self.shape[1:], bool) if inside is None else inside[k]


@dataclass(frozen=True)
class Provenance:
    """The files a job was made from: ``source`` (a file name) and ``digest`` (its ``io.file_digest``), which
    packages record in their archive comment and a slice manifest as ``quantized_digest``; ``volume_digest``: the
    run's volume.npz the labels were quantized from (slice manifests record it)."""

    source: str | None = None
    digest: str | None = None
    volume_digest: str | None = None


@dataclass(frozen=True)
class PrintJob:
    """One printer job for every format (``formats.Format.write``).

    voxels         ``LabelVoxels`` (every format) or ``MixtureVoxels`` (formats that take a mixture: 3MF)
    printer        the ``PrinterProfile`` whose material slots and material names apply, or None (no limit, no
                   names)
    max_materials  a material limit overriding the printer's (None: the printer's)
    materials      {ink name: material name} overriding the printer's names (ink names case-insensitive)
    palette        {ink name: "#rrggbb" | (r, g, b)} overriding ``slices.DEFAULT_PALETTE`` (slice and display
                   colours)
    provenance     the files the voxels were made from
    """

    voxels: LabelVoxels | MixtureVoxels
    printer: PrinterProfile | None = None
    max_materials: int | None = None
    materials: Mapping[str, str] = field(default_factory=dict)
    palette: Mapping | None = None
    provenance: Provenance = field(default_factory=Provenance)

    def __post_init__(self):
        if self.max_materials is not None and int(self.max_materials) < 1:
            raise ParameterError(f"`max_materials` must be at least 1, got {self.max_materials}")
        names = self.voxels.inks
        overrides = {str(k).strip().lower(): str(v).strip() for k, v in (self.materials or {}).items()}
        unknown = sorted(set(overrides) - {n.lower() for n in names})
        control = [v for v in overrides.values() if any(ord(c) < 32 or ord(c) == 127 for c in v)]
        if unknown or control or not all(overrides.values()):
            what = f"unknown ink '{unknown[0]}'" if unknown else "an empty name"
            what = f"{control[0]!r}, a name with a control character" if control and not unknown else what
            raise ParameterError(f"`materials` names {what}; the inks are {list(names)}")
        object.__setattr__(self, "materials", overrides)

    @property
    def inks(self) -> tuple[str, ...]:
        return self.voxels.inks

    @property
    def limit(self) -> int | None:
        """The most materials the job may use: ``max_materials``, else the printer's, else None (no limit)."""
        if self.max_materials is not None:
            return int(self.max_materials)
        return self.printer.max_materials if self.printer is not None else None

    def material(self, ink: str) -> str | None:
        """The printer's material name for ``ink``: the user's, else the profile's, else None."""
        return self.materials.get(ink.lower()) or material_name(self.printer, ink)

    def check_slots(self, used) -> None:
        """``profiles.check_slots`` for the inks ``used`` (names) against the job's limit."""
        check_slots(list(used), self.limit, self.printer.name if self.printer is not None else None)


@dataclass(frozen=True)
class InkCounts:
    """A label job's ``counts`` (256,) int64 voxels per label (255 = empty) and ``used``: the indices of the
    inks with voxels."""

    counts: np.ndarray
    used: tuple[int, ...]


def tally(job: PrintJob) -> InkCounts:
    """Count a label job's voxels per ink, one layer at a time; labels beyond the ink names, and more inks used
    than the printer holds, are one-line errors."""
    voxels = job.voxels
    if not isinstance(voxels, LabelVoxels):
        raise TypeError("this format writes one ink per voxel: give LabelVoxels, not a mixture")
    names = voxels.inks
    counts = np.zeros(256, np.int64)
    for k in range(voxels.shape[0]):
        counts += np.bincount(voxels.labels[k].ravel(), minlength=256)
    bad = np.flatnonzero(counts[len(names) : EMPTY])
    if bad.size:
        raise ValueError(f"labels use ink {len(names) + int(bad[0])} but only {len(names)} ink names are given")
    used = tuple(i for i in range(len(names)) if counts[i] > 0)
    job.check_slots(names[i] for i in used)
    return InkCounts(counts, used)
