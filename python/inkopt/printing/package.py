"""Printer packages read back and checked: a ``.gcvf``, a PNG-slice folder with its manifest, or a volumetric ``.3mf``.

``inspect_package`` reads one layer at a time (memory: a few layers, a (Y, X) top view and the preview's slices)
and checks that the parts agree, raising ``PackageError`` (a one-line ``ValueError``) at the first disagreement:
every slice the pixel size the package declares, palette colours only (GCVF, slices), layer numbers 0..N-1
without gaps and as many as declared, per-material voxel counts equal to the declared ones, and for GCVF the
z-buffer (topmost layer index per column, 0 where empty), ``MeshBbx.ktn`` and ``Mesh.stl`` against the slices'
occupied voxels (the STL's bounds within two outline blocks, the block named in its header by
``gcvf.BLOCK_TAG``, else within one voxel). For a 3MF the voxels with a non-zero share sum are the printed ones;
their sums must be 1 to within the 8-bit rounding of the sheets, and the mesh's bounds must agree with them as
the STL's do. Labels are the ink
indices (255 = empty) in the frames the writers use: (Z, Y, X) with y = Y - 1 - image row.
"""

from __future__ import annotations

import io
import json
import re
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..io import read_source_comment, write_png
from ..model import EMPTY
from ..units import MM_PER_INCH
from . import gcvf, threemf
from .export import FORMAT as SLICES_FORMAT


class PackageError(ValueError):
    """A package whose parts disagree (or that cannot be read); the message is one line."""


@dataclass
class PackageReport:
    """What ``inspect_package`` found. ``bounding_box``: (xmin, ymin, zmin, xmax, ymax, zmax) over (image column,
    image row, layer) of the printed voxels, max exclusive (``MeshBbx.ktn``'s layout); ``materials``: per material
    ``name``, ``color`` (RGBA or the 3MF display colour) and ``voxel_count`` (3MF: the sum of its shares);
    ``source``: the file the package records it was made from (``{"source", "digest"}``) or None."""

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


class _Scan:
    """Per-layer accumulation: counts, box, topmost layer and its label, kept slices (``keep``: indices)."""

    def __init__(self, Z, Y, X, n, keep=(), labels=False):
        self.counts = np.zeros(n, np.float64)
        self.lo, self.hi = np.array([X, Y, Z]), np.zeros(3, np.int64)
        self.top = np.zeros((Y, X), np.uint16)
        self.top_label = np.full((Y, X), EMPTY, np.uint8)
        self.kept = {}
        if isinstance(keep, int):  # that many layers, evenly spaced from bottom to top
            keep = np.unique(np.linspace(0, Z - 1, keep).round().astype(int)) if keep > 0 else ()
        self.keep = {int(k) for k in keep}
        self.labels = np.empty((Z, Y, X), np.uint8) if labels else None

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


def _pack(rgba) -> np.ndarray:
    c = np.asarray(rgba, np.uint32)
    return (c[..., 0] << 24) | (c[..., 1] << 16) | (c[..., 2] << 8) | c[..., 3]


def _decoder(colours, background):
    """A function (name, RGBA image array) -> (Y, X) labels; a foreign colour is a PackageError."""
    keys = np.asarray([_pack(c) for c in colours] + [_pack(background)], np.uint32)
    vals = np.asarray(list(range(len(colours))) + [EMPTY], np.uint8)
    order = np.argsort(keys)
    keys, vals = keys[order], vals[order]

    def decode(name: str, rgba: np.ndarray) -> np.ndarray:
        p = _pack(rgba)
        pos = np.clip(np.searchsorted(keys, p), 0, len(keys) - 1)
        bad = keys[pos] != p
        if bad.any():
            r, c = (int(v) for v in np.argwhere(bad)[0])
            colour = [int(v) for v in rgba[r, c]]
            raise PackageError(f"{name}: pixel (row {r}, column {c}) has colour {colour}, not in the palette")
        return vals[pos]

    return decode


def _image(data_or_path, name: str, size, mode="RGBA") -> np.ndarray:
    from PIL import Image

    try:
        with Image.open(io.BytesIO(data_or_path) if isinstance(data_or_path, bytes) else data_or_path) as im:
            arr = np.asarray(im.convert(mode) if mode and im.mode != mode else im)
    except OSError as exc:
        raise PackageError(f"{name}: not a readable PNG ({exc})") from None
    if (arr.shape[1], arr.shape[0]) != tuple(size):
        raise PackageError(f"{name} is {arr.shape[1]} x {arr.shape[0]} px; the package declares {size[0]} x {size[1]}")
    return arr


def _layer_numbers(names, pattern: str, declared: int, what: str) -> list[str]:
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


def _check_counts(names, declared, counts, what: str) -> None:
    for name, want, got in zip(names, declared, counts, strict=True):
        if int(want) != int(got):
            raise PackageError(f"{what} gives {name} {int(want)} voxels; the slices hold {int(got)}")


def _check_bounds(lo_mm, hi_mm, box, pitch, block, what: str) -> None:
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


def stl_bounds(data: bytes) -> tuple[np.ndarray, np.ndarray, tuple[int, int, int]]:
    """(min, max) of a binary STL's vertices (mm) and the outline block its header names ((1, 1, 1) if none)."""
    if len(data) < 84:
        raise PackageError("Mesh.stl is not a binary STL")
    n = int(np.frombuffer(data[80:84], "<u4")[0])
    if len(data) != 84 + 50 * n:
        raise PackageError(f"Mesh.stl declares {n} triangles but holds {(len(data) - 84) / 50:g}")
    v = np.frombuffer(data, gcvf.STL_RECORD, count=n, offset=84)["vertices"].reshape(-1, 3)
    m = re.match(rf"{gcvf.BLOCK_TAG} (\d+) (\d+) (\d+)", data[:80].decode("ascii", "replace"))
    block = tuple(int(g) for g in m.groups()) if m else (1, 1, 1)
    return v.min(0), v.max(0), block


def _gcvf(path: Path, scan_args) -> tuple[PackageReport, _Scan]:
    try:
        zf = zipfile.ZipFile(path)
    except (OSError, zipfile.BadZipFile) as exc:
        raise PackageError(f"{path} is not a zip ({exc})") from None
    with zf:
        names = set(zf.namelist())
        if gcvf.CONFIG not in names:
            raise PackageError(f"{path} has no {gcvf.CONFIG}")
        try:
            root = ET.fromstring(zf.read(gcvf.CONFIG))
            num = lambda tag: int(root.findtext(tag))  # noqa: E731
            W, H, N = (
                num("SliceDimensions/SliceWidth"),
                num("SliceDimensions/SliceHeight"),
                num("SliceRange/NumberOfSlices"),
            )
            dpi = (float(root.findtext("Resolution/XDpi")), float(root.findtext("Resolution/YDpi")))
            layer_um = num("Resolution/SliceThicknessNanoMeter") / 1000
            mats = root.findall("MaterialList/Material")
            rgba = [[int(v) for v in m.findtext("RGBA").split()] for m in mats]
            declared = [int(m.findtext("VoxelCount")) for m in mats]
            mnames = [m.findtext("Name") for m in mats]
            bg = [int(v) for v in root.findtext("MaterialList/BackGroundMaterialRGBA").split()]
        except (ET.ParseError, TypeError, ValueError, AttributeError) as exc:
            raise PackageError(f"{gcvf.CONFIG} is incomplete or malformed ({type(exc).__name__}: {exc})") from None
        start = root.findtext("SliceRange/StartIndex")
        if start is not None and int(start) != 0:
            raise PackageError(f"{gcvf.CONFIG}: StartIndex is {start}, not 0")
        prefix = root.findtext("ImageFilePrefix") or gcvf.PREFIX
        files = _layer_numbers(names, re.escape(prefix) + r"(\d+)\.png", N, gcvf.CONFIG)
        decode = _decoder(rgba, bg)
        scan = _Scan(N, H, W, len(mats), *scan_args)
        for k, name in enumerate(files):
            scan.add(k, decode(name, _image(zf.read(name), name, (W, H))))
        _check_counts(mnames, declared, scan.counts, gcvf.CONFIG)
        box = scan.box()
        if gcvf.ZBUFFER in names:
            zb = _image(zf.read(gcvf.ZBUFFER), gcvf.ZBUFFER, (W, H), mode=None).astype(np.int64)
            bad = zb != scan.top
            if bad.any():
                r, c = (int(v) for v in np.argwhere(bad)[0])
                raise PackageError(
                    f"{gcvf.ZBUFFER} at (row {r}, column {c}) is {zb[r, c]}; "
                    f"the topmost printed layer is {scan.top[r, c]}"
                )
        if gcvf.BBOX in names:
            raw = zf.read(gcvf.BBOX)
            ktn = np.frombuffer(raw, "<f4").tolist() if len(raw) == 24 else None
            if ktn != [float(v) for v in box]:
                raise PackageError(f"{gcvf.BBOX} holds {ktn}; the printed voxels' box is {box}")
        if gcvf.STL in names:
            lo, hi, block = stl_bounds(zf.read(gcvf.STL))
            pitch = np.array([MM_PER_INCH / dpi[0], -MM_PER_INCH / dpi[1], layer_um / 1000])
            _check_bounds(lo, hi, box, pitch, block, gcvf.STL)
        source = read_source_comment(zf.comment)
    materials = [
        {"name": n, "color": c, "voxel_count": int(v)} for n, c, v in zip(mnames, rgba, scan.counts, strict=True)
    ]
    return PackageReport("gcvf", str(path), N, W, H, dpi, layer_um, materials, box, source), scan


def _slices(path: Path, scan_args) -> tuple[PackageReport, _Scan]:
    try:
        man = json.loads((path / "manifest.json").read_text())
        if man.get("format") != SLICES_FORMAT:
            raise ValueError(f"format is not {SLICES_FORMAT}")
        N, W, H = man["layer_count"], man["image_size"]["width"], man["image_size"]["height"]
        mats = man["materials"]
        dpi, layer_um = (man["dpi"]["x"], man["dpi"]["y"]), man["layer_thickness_um"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise PackageError(f"{path}/manifest.json is missing or malformed ({type(exc).__name__}: {exc})") from None
    files = _layer_numbers([p.name for p in path.iterdir()], r"slice_(\d+)\.png", N, "manifest.json")
    decode = _decoder([m["color"] for m in mats], man["background"])
    scan = _Scan(N, H, W, len(mats), *scan_args)
    for k, name in enumerate(files):
        scan.add(k, decode(name, _image(path / name, name, (W, H))))
    _check_counts([m["ink"] for m in mats], [m["voxel_count"] for m in mats], scan.counts, "manifest.json")
    materials = [
        {"name": m.get("material") or m["ink"], "ink": m["ink"], "color": m["color"], "voxel_count": int(v)}
        for m, v in zip(mats, scan.counts, strict=True)
    ]
    # the manifest records the quantized file the slices were made from (``quantized_digest``)
    digest = man.get("quantized_digest")
    source = {"source": "quantized.npz", "digest": digest} if digest else None
    return PackageReport("png-slices", str(path), N, W, H, dpi, layer_um, materials, scan.box(), source), scan


def _mesh_bounds(fh) -> tuple[dict, np.ndarray, np.ndarray]:
    """Stream 3dmodel.model: the resources (without the mesh) as a small tree and the mesh's bounds."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    res: dict = {"base": [], "stacks": {}, "functions": {}, "mappings": [], "object_name": ""}
    stack = None
    for _, el in ET.iterparse(fh, events=("end",)):
        tag = el.tag.rsplit("}", 1)[-1]
        if tag == "vertex":
            p = np.array([float(el.get(a)) for a in "xyz"])
            lo, hi = np.minimum(lo, p), np.maximum(hi, p)
        elif tag == "base":
            res["base"].append((el.get("name"), el.get("displaycolor")))
        elif tag == "imagestack":
            stack = {k: int(el.get(k)) for k in ("rowcount", "columncount", "sheetcount")}
            stack["sheets"] = [s.get("path") for s in el]
        elif tag == "image3d":
            res["stacks"][el.get("id")] = stack
        elif tag == "functionfromimage3d":
            res["functions"][el.get("id")] = el.get("image3did")
        elif tag == "materialmapping":
            res["mappings"].append((el.get("functionid"), el.get("channel"), el.get("transform")))
        elif tag == "object":
            res["object_name"] = el.get("name") or ""
        if tag in ("vertex", "triangle"):
            el.clear()
    return res, lo, hi


def _threemf(path: Path, scan_args) -> tuple[PackageReport, _Scan]:
    try:
        zf = zipfile.ZipFile(path)
        with zf.open(threemf.MODEL) as fh:
            res, lo, hi = _mesh_bounds(fh)
    except (OSError, KeyError, zipfile.BadZipFile, ET.ParseError) as exc:
        raise PackageError(f"{path} is not a readable 3MF ({type(exc).__name__}: {exc})") from None
    with zf:
        maps, n = res["mappings"], len(res["base"])
        if not maps or len(maps) != n:
            raise PackageError(f"the composite has {len(maps)} material mappings for {n} base materials")
        stacks = [res["stacks"][res["functions"][f]] for f, _, _ in maps]
        H, W, N = (stacks[0][k] for k in ("rowcount", "columncount", "sheetcount"))
        for st in stacks:
            if (st["rowcount"], st["columncount"], st["sheetcount"], len(st["sheets"])) != (H, W, N, N):
                raise PackageError(f"image stacks differ in size or sheet count: {st} vs {W} x {H} x {N}")
        scale = [float(v) for v in maps[0][2].split()]
        vox = 1 / (np.array([scale[0], scale[4], scale[8]]) * [W, H, N])
        scan = _Scan(N, H, W, n, *scan_args)
        shares = np.zeros(n, np.float64)
        tol = n * 0.5 / 255 + 1e-6
        for k in range(N):
            sheets = {}
            sh = np.empty((H, W, n), np.float32)
            for i, (st, (_, ch, _)) in enumerate(zip(stacks, maps, strict=True)):
                p = st["sheets"][k]
                if p not in sheets:
                    sheets[p] = _image(zf.read(p.lstrip("/")), p, (W, H)).astype(np.float32) / 255
                sh[:, :, i] = sheets[p][:, :, threemf.CHANNELS.index(ch)]
            total = sh.sum(2)
            occ = total > 0
            off = occ & (np.abs(total - 1) > tol)
            if off.any():
                r, c = (int(v) for v in np.argwhere(off)[0])
                raise PackageError(f"sheet {k}: the shares at (row {r}, column {c}) sum to {total[r, c]:.4f}, not 1")
            shares += sh[occ].sum(0)
            lab = np.where(occ, np.argmax(sh, 2), EMPTY).astype(np.uint8)
            scan.add(k, lab)
        box = scan.box()
        m = re.search(r"block (\d+) (\d+) (\d+)", res["object_name"])
        block = tuple(int(g) for g in m.groups()) if m else (1, 1, 1)
        # the mesh's y runs up the grid: image row r covers y from (H - r - 1) to (H - r) voxels
        ybox = [box[0], H - box[4], box[2], box[3], H - box[1], box[5]]
        _check_bounds(lo, hi, ybox, vox, block, "the 3MF mesh")
        source = read_source_comment(zf.comment)
    materials = [
        {"name": b[0], "color": b[1], "voxel_count": float(v)} for b, v in zip(res["base"], shares, strict=True)
    ]
    dpi = (float(MM_PER_INCH / vox[0]), float(MM_PER_INCH / vox[1]))
    return PackageReport("3mf", str(path), N, W, H, dpi, float(vox[2] * 1000), materials, box, source), scan


def inspect_package(path, *, keep_layers=(), labels: bool = False):
    """Read and check the package ``path`` (module docstring). Returns ``(PackageReport, scan)``; ``scan`` holds
    ``top`` / ``top_label`` ((Y, X) in image rows), ``kept`` {layer: (Y, X) labels in image rows} for
    ``keep_layers`` (layer indices, or a count of evenly spaced layers) and, with ``labels``, ``labels``
    (Z, Y, X) uint8 in the writers' frame (3MF: each printed voxel's largest share)."""
    path = Path(path)
    args = (keep_layers, labels)
    if path.is_dir():
        return _slices(path, args)
    if not path.is_file():
        raise PackageError(f"{path} does not exist")
    try:  # a 3MF holds its model at 3D/3dmodel.model, whatever the file is called
        with zipfile.ZipFile(path) as zf:
            is_3mf = "3D/3dmodel.model" in zf.namelist()
    except (OSError, zipfile.BadZipFile):
        raise PackageError(f"{path} is not a zip (a GCVF or 3MF package) nor a slice folder") from None
    return _threemf(path, args) if is_3mf else _gcvf(path, args)


def preview(report: PackageReport, scan: _Scan, colours, out) -> None:
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
