"""What the formats' checkers share: packages read back one layer at a time and their parts compared.

Each format's ``check`` reads its package layer by layer into a ``Scan`` (memory: a few layers, a (Y, X) top view
and the preview's slices) and raises ``PackageError`` (a one-line ``ValueError``) at the first disagreement between
its parts: every slice the pixel size the package declares (``read_image``), palette colours only (``decoder``),
layer numbers 0..N-1 without gaps and as many as declared (``layer_files``), per-material voxel counts equal to the
declared ones (``check_counts``) and a mesh's bounds against the printed voxels (``check_bounds``); ``about``
makes every error of a check one line naming the package. Labels are the ink indices (255 = empty) in the frames
the writers use: (Z, Y, X) with y = Y - 1 - image row.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass

import numpy as np

from ...images import ImageError, open_image
from ...io import write_png
from ...model import EMPTY
from .slices import pack_rgba


class PackageError(ValueError):
    """A package whose parts disagree (or that cannot be read); the message is one line."""


@contextmanager
def about(path) -> Iterator[None]:
    """A checker's errors naming the package: a ValueError raised in the block (a PackageError, or what an image
    decoder raises) as the one-line PackageError ``"{path}: {message}"`` unless it names ``path`` already, and
    memory running out as one line naming ``path``."""
    try:
        yield
    except ValueError as exc:
        if str(path) in str(exc) and not isinstance(exc, PackageError):
            raise
        raise PackageError(f"{path}: {' '.join(str(exc).split())}") from None
    except MemoryError:
        raise PackageError(f"{path}: too large to check in this machine's memory") from None


@dataclass
class PackageReport:
    """What a format's ``check`` found. ``kind``: the format's name; ``bounding_box``: (xmin, ymin, zmin, xmax,
    ymax, zmax) over (image column, image row, layer) of the printed voxels, max exclusive (``MeshBbx.ktn``'s
    layout); ``materials``: per material ``name``, ``color`` (RGBA or the 3MF display colour) and ``voxel_count``
    (3MF: the sum of its shares); ``source``: the file the package records it was made from (``{"source",
    "digest"}``) or None."""

    kind: str
    path: str
    layers: int
    width: int
    height: int
    dpi: tuple[float, float] | None
    layer_um: float | None
    materials: list
    bounding_box: list
    source: dict | None = None

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> PackageReport:
        return cls(**{**d, "dpi": None if d.get("dpi") is None else tuple(d["dpi"])})


#: the most pixels per slice a package may declare (a J750 tray at 600 x 300 DPI is 5.3e7): the per-pixel arrays
#: of a scan are allocated from the declared size before any slice is decoded
MAX_SLICE_PIXELS = 2**28


class Scan:
    """Per-layer accumulation of a package read back: ``counts`` per material, the printed voxels' box, ``top``
    (the topmost printed layer per image pixel) and ``top_label`` (its label), ``kept`` {layer: (Y, X) labels in
    image rows} for ``keep`` (layer indices, or a count of evenly spaced layers) and, with ``labels``, ``labels``
    (Z, Y, X) uint8 in the writers' frame."""

    def __init__(self, Z, Y, X, n, keep=(), labels=False):
        self.counts = np.zeros(n, np.float64)
        self.lo, self.hi = np.array([X, Y, Z]), np.zeros(3, np.int64)
        self.kept = {}
        if isinstance(keep, int):  # that many layers, evenly spaced from bottom to top
            keep = np.unique(np.linspace(0, Z - 1, keep).round().astype(int)) if keep > 0 else ()
        self.keep = {int(k) for k in keep}
        if X * Y > MAX_SLICE_PIXELS:
            raise PackageError(f"slices of {X} x {Y} px are more than the {MAX_SLICE_PIXELS} pixels inkopt reads")
        try:
            self.top = np.zeros((Y, X), np.uint16)
            self.top_label = np.full((Y, X), EMPTY, np.uint8)
            self.labels = np.empty((Z, Y, X), np.uint8) if labels else None
        except MemoryError:
            raise PackageError(f"{Z} layers of {X} x {Y} px do not fit in memory") from None

    def add(self, k: int, lab: np.ndarray) -> None:
        """``lab``: (Y, X) labels in image rows (row 0 = top of the image)."""
        occ = lab != EMPTY
        self.counts += np.bincount(lab[occ], minlength=len(self.counts))[: len(self.counts)]
        if occ.any():
            self.top[occ], self.top_label[occ] = k, lab[occ]
            cols, rows = np.flatnonzero(occ.any(0)), np.flatnonzero(occ.any(1))
            self.lo = np.minimum(self.lo, [cols[0], rows[0], k])
            self.hi = np.maximum(self.hi, [cols[-1] + 1, rows[-1] + 1, k + 1])
        if k in self.keep:
            self.kept[k] = lab
        if self.labels is not None:
            self.labels[k] = lab[::-1]

    def box(self) -> list:
        if self.hi[2] == 0:
            raise PackageError("nothing is printed: every voxel is empty")
        return [int(v) for v in (*self.lo, *self.hi)]


def decoder(colours, background):
    """A function (name, RGBA image array) -> (Y, X) labels; a foreign colour is a PackageError."""
    keys = np.asarray([pack_rgba(c) for c in colours] + [pack_rgba(background)], np.uint32)
    vals = np.asarray(list(range(len(colours))) + [EMPTY], np.uint8)
    order = np.argsort(keys)
    keys, vals = keys[order], vals[order]

    def decode(name: str, rgba: np.ndarray) -> np.ndarray:
        p = pack_rgba(rgba)
        pos = np.clip(np.searchsorted(keys, p), 0, len(keys) - 1)
        bad = keys[pos] != p
        if bad.any():
            r, c = (int(v) for v in np.argwhere(bad)[0])
            colour = [int(v) for v in rgba[r, c]]
            raise PackageError(f"{name}: pixel (row {r}, column {c}) has colour {colour}, not in the palette")
        return vals[pos]

    return decode


def read_image(data_or_path, name: str, size, mode="RGBA") -> np.ndarray:
    """A PNG (bytes or a path) as an array (converted to ``mode`` unless None), checked to be ``size`` (W, H) and to
    hold at most ``images.MAX_IMAGE_PIXELS`` pixels before its pixels are decoded (``images.open_image``)."""
    try:
        with open_image(data_or_path, name, decode=False) as im:
            w, h = im.size
        if (w, h) != tuple(size):
            raise PackageError(f"{name} is {w} x {h} px; the package declares {size[0]} x {size[1]}")
        with open_image(data_or_path, name) as im:
            return np.asarray(im.convert(mode) if mode and im.mode != mode else im)
    except ImageError as exc:
        raise PackageError(str(exc)) from None


def layer_files(names, pattern: str, declared: int, what: str) -> list[str]:
    """The layer files in order; gaps, a wrong start or a count other than ``declared`` are PackageErrors."""
    rx = re.compile(pattern)
    found = {}
    for n in names:
        m = rx.fullmatch(n)
        if m:
            found[int(m.group(1))] = n
    missing = [k for k in range(declared) if k not in found]
    if missing:
        raise PackageError(f"layer {missing[0]} is missing ({len(found)} layer images, {what} declares {declared})")
    if len(found) != declared:
        extra = sorted(set(found) - set(range(declared)))[0]
        raise PackageError(f"layer image {found[extra]} is beyond the {declared} layers {what} declares")
    return [found[k] for k in range(declared)]


def check_counts(names, declared, counts, what: str) -> None:
    for name, want, got in zip(names, declared, counts, strict=True):
        if int(want) != int(got):
            raise PackageError(f"{what} gives {name} {int(want)} voxels; the slices hold {int(got)}")


def check_bounds(lo_mm, hi_mm, box, pitch, block, what: str) -> None:
    """Mesh bounds (mm) against the voxel box converted by ``pitch`` (x, y, z mm per column/row/layer, y < 0 for
    GCVF's -row frame): within two outline blocks of ``block`` voxels, or one voxel without blocks."""
    want_lo = np.array(box[:3], float) * pitch
    want_hi = np.array(box[3:], float) * pitch
    want = np.sort(np.stack([want_lo, want_hi]), axis=0)
    block = np.asarray(block, float)
    tol = np.abs(pitch) * (2 * block if (block > 1).any() else block) + 1e-4
    got = np.stack([lo_mm, hi_mm])
    off = np.abs(got - want) > tol
    if off.any():
        i, j = np.argwhere(off)[0]
        raise PackageError(
            f"{what}'s {'min' if i == 0 else 'max'} {'xyz'[j]} is {got[i, j]:.4f} mm; the printed voxels' is "
            f"{want[i, j]:.4f} mm"
        )


def preview(report: PackageReport, scan: Scan, colours, out) -> None:
    """A PNG of the top view (each column's topmost printed voxel) and the kept slices, side by side, each row
    drawn twice as high when the grid's y pitch is twice its x pitch (so the object keeps its proportions)."""

    lut = np.zeros((256, 3), np.uint8)
    lut[:] = 235  # empty: light grey
    for i, c in enumerate(colours):
        lut[i] = c[:3]
    stretch = max(1, round(report.dpi[0] / report.dpi[1])) if report.dpi else 1
    panels = [scan.top_label] + [scan.kept[k] for k in sorted(scan.kept)]
    pics = [np.repeat(lut[p], stretch, axis=0) for p in panels]
    gap = np.full((pics[0].shape[0], 4, 3), 255, np.uint8)
    row = np.concatenate([x for p in pics for x in (p, gap)][:-1], axis=1)
    write_png(out, row)
