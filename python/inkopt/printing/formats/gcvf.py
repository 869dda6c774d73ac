"""GrabCAD Voxel Print package (``.gcvf``): the file print labs load into GrabCAD Print for Stratasys voxel printing.

``write_gcvf`` writes one zip (atomically: a temporary file beside it, then renamed), streaming: one layer at a
time is encoded (``labels`` may be a memory-mapped label file), the z-buffer, the bounding box and the outline's
occupancy are accumulated on the way, and nothing but the current layers is held. The zip holds, at its root:

- ``layer_0.png`` ... ``layer_{Z-1}.png``: one opaque RGBA PNG per layer, slice 0 = bottom layer, numbered from 0
  without zero padding, every slice the same pixel size (the printer grid's X x Y), DPI in the pHYs chunk. Pixel
  orientation as in ``png_slices.py`` (column 0 = smallest x, row 0 = largest y). Empty voxels are opaque black
  ``0 0 0 255`` (the background material of the configuration), so the black ink is drawn ``#282828`` by default;
  every other ink keeps its ``slices.DEFAULT_PALETTE`` colour (cyan ``0 255 255 255`` ... as in the builder).
- ``ConfigFile.xml``: ``<GCVF>`` version 2 with ``<Resolution>`` (``XDpi``, ``YDpi``,
  ``SliceThicknessNanoMeter``), ``<SliceDimensions>`` (``SliceWidth``, ``SliceHeight``), ``<SliceRange>``
  (``StartIndex`` 0, ``NumberOfSlices``), ``BitDepth`` 4, ``MaxNumberOfColors`` (the profile's ``gcvf_colors``: 6),
  ``DataSemantics`` Materials, ``CreationMode`` MODEL_ONLY, ``ImageFilePrefix`` layer_ and ``<MaterialList>``:
  ``BackGroundMaterialRGBA`` and one ``<Material>`` (``Name``, ``RGBA`` as "r g b a", ``VoxelCount``) per ink
  used. ``Name`` is the user's material name for the ink, else the printer profile's (``profiles.py``: GrabCAD's
  names, VeroCY-V ...), else the ink name (a material the lab assigns by hand in GrabCAD Print).
- ``MeshBbx.ktn``: 24 bytes, six little-endian float32 (xmin, ymin, zmin, xmax, ymax, zmax) in printer voxels over
  (image column, image row, layer) of the occupied voxels, max exclusive.
- ``Zbuffer.png``: a 16-bit grey PNG of the slices' pixel size and row order whose value is the index of the
  topmost occupied layer of that column, 0 where nothing is printed (no pHYs chunk).
- ``Mesh.stl``: binary STL in mm of the outline of the print (every non-empty voxel), outward normals, in the
  frame x = column x pitch_x, y = -row x pitch_y (origin at the image's top-left corner: the mesh lies in negative
  y), z = layer x layer thickness: the outline of ``outline.py`` (on the voxel faces; above
  ``outline.OUTLINE_MAX_CELLS`` printer voxels from grown blocks of voxels, enclosing every printed voxel). The
  80-byte header names the block (``BLOCK_TAG``), so that a reader knows how far the outline may stand off the
  voxels.
- The zip's archive comment (which no printer software reads) records the file the package was made from:
  ``{"inkopt": {"source": NAME, "digest": "sha256:..."}}`` (``io.source_comment``).

``check_gcvf`` refuses member names a printer's software would unpack outside its folder (``members``), reads
each member within a bound of its declared size, reads the package back one layer at a time and checks that its
parts agree (``inspection``): the slices against the configuration's palette, size, layer count and voxel counts,
and the z-buffer, ``MeshBbx.ktn`` and ``Mesh.stl`` (read a few thousand triangles at a time) against the slices'
printed voxels (the STL's bounds within two outline blocks, the block named in its header, else within one voxel).

Evidence. The zip layout, ``ConfigFile.xml`` (every element and value, the 6 colours, the material names of four
inks), ``layer_N.png`` and the opaque-black background are read from a public GCVF builder, ``buildGCVF.js``
(jackcrane/slice2vox, and its copy in jackcrane/pj-voxelprint-colorwheels-v3 ``4/``), which puts every file of a
``gcvf_includes/`` folder at the zip's root beside the slices. That repository holds two such folders
(``4/gcvf_includes``, ``4/wheel_gcvf_includes``, commit 07930c8a) with ``Mesh.stl``, ``Zbuffer.png`` and
``MeshBbx.ktn``; read byte by byte they give the names, the ktn layout (a 200 x 100 px, 100-layer job filled
everywhere: 0 0 0 200 100 100; a 1000 x 500 px job occupying columns 2-999 and rows 1-499: 2 1 0 1000 500 100), the
z-buffer (16-bit grey, no pHYs, 99 in every occupied column of a 100-layer job, 0 elsewhere) and the STL's frame
(binary, mm, x from 0 to 200 x 25.4/600, y from -100 x 25.4/300 to 0, z from 0 to 100 x 0.027, stored normals equal
to the outward winding normals, attribute 0); this module, given the two jobs' occupancy, writes a ``MeshBbx.ktn``
equal to theirs byte for byte and a ``Zbuffer.png`` equal pixel for pixel. OpenVCAD's ``GCVFExporter`` (C++ API
docs, matterassembly.org/OpenVCAD-Docs/v2/cpp-api/libvcad-compilers-inkjet.html) lists the same parts and the
defaults 600 x 300 DPI and 27000 nm. Where they disagree: the builder names white ``VUltraWhite`` and writes
``MaxNumberOfColors`` 6 always, OpenVCAD's examples name white ``VeroPureWht``; both are profile settings
(``profiles.py``) and material names can be set per ink. The STL of those packages is the design mesh, ours the
voxels' outline; what ``BitDepth`` 4 means is not documented anywhere we found (we copy it). No package written here
has been loaded into GrabCAD Print.
"""

from __future__ import annotations

import io
import os
import re
import xml.etree.ElementTree as ET
import zipfile
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ...io import atomic_file, read_source_comment, source_comment
from ...model import EMPTY
from ...units import MM_PER_INCH
from .archive import check_target, zip_holds
from .inspection import (
    PackageError,
    PackageReport,
    Scan,
    about,
    check_bounds,
    check_counts,
    decoder,
    layer_files,
)
from .job import InkCounts, PrintJob, tally
from .members import check_names, check_png_size, open_zip, raw_names, read_member, read_png, reading
from .outline import block_any, block_outline, coarse_grid, outline_factors
from .slices import rgba, slice_image, slice_lut, slices_line

if TYPE_CHECKING:
    from ...rundir import RunDir

CONFIG, STL, ZBUFFER, BBOX, PREFIX = "ConfigFile.xml", "Mesh.stl", "Zbuffer.png", "MeshBbx.ktn", "layer_"
BLOCK_TAG = "inkopt outline block"  # STL header: f"{BLOCK_TAG} fx fy fz" (printer voxels per outline block)
BACKGROUND = (0, 0, 0, 255)
GCVF_PALETTE = {"black": "#282828"}  # the background is opaque black: move the black ink off it
CONFIG_LIMIT = 16 * 2**20  # the most bytes a ConfigFile.xml holds (one <Material> per ink: a few KiB)
STL_RECORD = np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])


def stl_bytes(mesh, header: str) -> bytes:
    """Binary STL of ``mesh`` (trimesh) with an ASCII ``header`` and each face's outward normal."""
    tri = mesh.vertices[mesh.faces]
    rec = np.zeros(len(mesh.faces), STL_RECORD)
    rec["normal"], rec["vertices"] = mesh.face_normals, tri
    head = header.encode("ascii")[:80].ljust(80, b" ")
    return head + np.uint32(len(rec)).tobytes() + rec.tobytes()


def _png(image, dpi) -> bytes:
    buf = io.BytesIO()
    image.save(buf, format="PNG", dpi=dpi, compress_level=1)
    return buf.getvalue()


def _in_order(pool, fn, n: int, window: int):
    """fn(0), ..., fn(n - 1) computed in ``pool`` with at most ``window`` results pending, yielded in order."""
    pending: deque = deque()
    for k in range(n):
        pending.append(pool.submit(fn, k))
        if len(pending) >= window:
            yield pending.popleft().result()
    while pending:
        yield pending.popleft().result()


def config_xml(job: PrintJob, tallied: InkCounts, colours, bg, dpi_int, layer_nm) -> bytes:
    """``ConfigFile.xml`` of the reference builder for ``job`` (its used inks, counts and colours)."""
    root = ET.Element("GCVF")

    def add(parent, tag, text=None, **children):
        el = ET.SubElement(parent, tag)
        if text is not None:
            el.text = str(text)
        for k, v in children.items():
            ET.SubElement(el, k).text = str(v)
        return el

    Z, Y, X = job.voxels.shape
    add(root, "Version", 2)
    add(root, "Resolution", XDpi=dpi_int[0], YDpi=dpi_int[1], SliceThicknessNanoMeter=layer_nm)
    add(root, "SliceDimensions", SliceWidth=X, SliceHeight=Y)
    add(root, "SliceRange", StartIndex=0, NumberOfSlices=Z)
    add(root, "BitDepth", 4)
    cap = job.printer.gcvf_colors if job.printer is not None and job.printer.gcvf_colors else None
    add(root, "MaxNumberOfColors", cap or (job.limit if job.limit is not None else max(6, len(tallied.used))))
    add(root, "DataSemantics", "Materials")
    add(root, "CreationMode", "MODEL_ONLY")
    add(root, "ImageFilePrefix", PREFIX)
    mats = add(root, "MaterialList", BackGroundMaterialRGBA=" ".join(map(str, bg)))
    for i in tallied.used:
        name = job.inks[i]
        rgba = " ".join(map(str, colours[i]))
        add(mats, "Material", Name=job.material(name) or name, RGBA=rgba, VoxelCount=int(tallied.counts[i]))
    ET.indent(root, space="    ")
    head = b'<?xml version="1.0" encoding="UTF-8"?>\n<!--  GCVF - GrabCad Voxel Print File  -  -->\n'
    return head + ET.tostring(root, encoding="utf-8") + b"\n"


class _Occupancy:
    """What the slices' printed voxels give the other parts, accumulated one layer at a time: the topmost occupied
    layer per pixel (z-buffer), the occupied box and the outline's block occupancy."""

    def __init__(self, shape, factors):
        Z, Y, X = shape
        self.factors = factors
        self.coarse = coarse_grid(shape, factors)
        self.top = np.zeros((Y, X), np.uint16)  # index of the topmost occupied layer (0 also where nothing is)
        self.lo, self.hi = np.array([X, Y, Z]), np.zeros(3, np.int64)  # occupied box (x, label y, z), max excl.

    def add(self, k: int, occ: np.ndarray) -> None:
        fz, fy, fx = self.factors
        self.top[occ] = k
        self.coarse[k // fz] |= block_any(occ, fy, fx)
        if occ.any():
            cols, rows = np.flatnonzero(occ.any(0)), np.flatnonzero(occ.any(1))
            self.lo = np.minimum(self.lo, [cols[0], rows[0], k])
            self.hi = np.maximum(self.hi, [cols[-1] + 1, rows[-1] + 1, k + 1])

    def box(self, Y: int) -> list:
        """``MeshBbx.ktn``'s box: label y turned into image rows (row 0 = largest y)."""
        lo, hi = self.lo, self.hi
        return [lo[0], Y - hi[1], lo[2], hi[0], Y - lo[1], hi[2]]


def _write_layers(zf, job: PrintJob, lut, dpi_int) -> _Occupancy:
    """Every layer as ``layer_K.png``, encoded in threads, while their occupancy is accumulated."""
    labels = job.voxels.labels
    occupancy = _Occupancy(labels.shape, outline_factors(labels.shape, job.voxels.voxel_mm))
    workers = min(8, os.cpu_count() or 1)
    with ThreadPoolExecutor(workers) as pool:
        pngs = _in_order(pool, lambda k: _png(slice_image(lut, labels[k]), dpi_int), labels.shape[0], 4 * workers)
        for k, data in enumerate(pngs):
            zf.writestr(f"{PREFIX}{k}.png", data, compress_type=zipfile.ZIP_STORED)
            occupancy.add(k, np.asarray(labels[k]) != EMPTY)
    return occupancy


def _write_parts(zf, job: PrintJob, occupancy: _Occupancy) -> tuple[list, int]:
    """``Zbuffer.png``, ``MeshBbx.ktn`` and ``Mesh.stl``; returns the box and the STL's triangle count."""
    from PIL import Image

    Y = job.voxels.shape[1]
    zb = io.BytesIO()
    Image.fromarray(occupancy.top[::-1, :]).save(zb, format="PNG", compress_level=6)
    zf.writestr(ZBUFFER, zb.getvalue(), compress_type=zipfile.ZIP_STORED)
    box = occupancy.box(Y)
    zf.writestr(BBOX, np.asarray(box, "<f4").tobytes(), compress_type=zipfile.ZIP_STORED)
    fz, fy, fx = occupancy.factors
    vp = job.voxels.voxel_mm
    mesh = block_outline(occupancy.coarse, vp, (fz, fy, fx))
    mesh.apply_translation([0.0, -Y * vp[1], 0.0])  # origin at the image's top-left corner
    zf.writestr(STL, stl_bytes(mesh, f"{BLOCK_TAG} {fx} {fy} {fz}"), compress_type=zipfile.ZIP_DEFLATED)
    return box, len(mesh.faces)


def write_gcvf(job: PrintJob, path) -> dict:
    """Write ``job``'s labels as the GrabCAD Voxel Print package ``path`` (layout: module docstring); returns a
    summary dict. A job using more inks than the printer holds, a grid whose DPI is not a whole number, or an empty
    job is refused before anything is written; an existing ``path`` is replaced only if it is a GCVF package."""
    tallied = tally(job)
    if not tallied.used:
        raise ValueError("nothing to print: every voxel is empty")
    dpi = job.voxels.dpi
    dpi_int = tuple(int(round(d)) for d in dpi)
    if not np.allclose(dpi, dpi_int, rtol=1e-4):
        raise ValueError(f"GCVF needs whole-number DPI; the grid is {dpi[0]:.3f} x {dpi[1]:.3f} DPI")
    layer_nm = int(round(job.voxels.voxel_mm[2] * 1e6))
    lut, colours, bg = slice_lut(job.inks, {**GCVF_PALETTE, **(job.palette or {})}, BACKGROUND)
    path = Path(path)
    check_target(path, CONFIG, "GCVF package", Gcvf.suffix)
    with atomic_file(path) as fh, zipfile.ZipFile(fh, "w") as zf:
        occupancy = _write_layers(zf, job, lut, dpi_int)
        config = config_xml(job, tallied, colours, bg, dpi_int, layer_nm)
        zf.writestr(CONFIG, config, compress_type=zipfile.ZIP_DEFLATED)
        box, triangles = _write_parts(zf, job, occupancy)
        zf.comment = source_comment(job.provenance.source, job.provenance.digest)
        check_names(raw_names(zf))  # never put a package in place that would unpack outside its folder
    Z, Y, X = job.voxels.shape
    return {
        "path": str(path),
        "layer_count": Z,
        "image_size": {"width": X, "height": Y},
        "dpi": {"x": dpi_int[0], "y": dpi_int[1]},
        "layer_thickness_nm": layer_nm,
        "materials": [
            {
                "ink": job.inks[i],
                "material": job.material(job.inks[i]),
                "color": list(colours[i]),
                "voxel_count": int(tallied.counts[i]),
            }
            for i in tallied.used
        ],
        "printer": job.printer.name if job.printer else None,
        "bounding_box_voxels": [int(v) for v in box],
        "stl_triangles": triangles,
        "outline_block": list(occupancy.factors[::-1]),
        "bytes": path.stat().st_size,
    }


def stl_bounds(fh, size: int) -> tuple[np.ndarray, np.ndarray, tuple[int, int, int]]:
    """(min, max) of the vertices (mm) of the binary STL read from ``fh`` (``size`` bytes), a few thousand
    triangles at a time, and the outline block its header names ((1, 1, 1) if none)."""
    head = fh.read(84)
    if len(head) < 84:
        raise PackageError(f"{STL} is not a binary STL")
    n = int.from_bytes(head[80:84], "little")
    if size != 84 + 50 * n:
        raise PackageError(f"{STL} declares {n} triangles but holds {(size - 84) / 50:g}")
    if n == 0:
        raise PackageError(f"{STL} holds no triangles")
    lo, hi = np.full(3, np.inf, np.float32), np.full(3, -np.inf, np.float32)
    for k in range(0, n, 1 << 16):
        want = 50 * min(1 << 16, n - k)
        data = fh.read(want)
        v = np.frombuffer(data, STL_RECORD)["vertices"].reshape(-1, 3) if len(data) == want else None
        if v is None or not np.all(np.isfinite(v)):
            raise PackageError(f"{STL}: triangle {k} onwards is truncated or holds a non-finite vertex")
        lo, hi = np.minimum(lo, v.min(0)), np.maximum(hi, v.max(0))
    m = re.match(rf"{BLOCK_TAG} (\d+) (\d+) (\d+)", head[:80].decode("ascii", "replace"))
    block = tuple(int(g) for g in m.groups()) if m else (1, 1, 1)
    return lo, hi, block


@dataclass(frozen=True)
class _Config:
    """What ``ConfigFile.xml`` declares: slice size (W, H), layer count N, DPI, layer thickness (µm), the layer
    files' prefix, the background RGBA and per material its name, RGBA and voxel count."""

    W: int
    H: int
    N: int
    dpi: tuple[float, float]
    layer_um: float
    prefix: str
    background: tuple
    names: list
    rgba: list
    declared: list

    def __post_init__(self):
        for what, v in (("SliceWidth", self.W), ("SliceHeight", self.H), ("NumberOfSlices", self.N)):
            if not 1 <= v < 2**31:
                raise ValueError(f"{what} is {v}, not 1 .. 2^31 - 1")
        for what, v in (("XDpi", self.dpi[0]), ("YDpi", self.dpi[1]), ("SliceThicknessNanoMeter", self.layer_um)):
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{what} is {v}, not a positive number")
        if not 1 <= len(self.names) < EMPTY:
            raise ValueError(f"the MaterialList holds {len(self.names)} materials, not 1 .. {EMPTY - 1}")
        if min(self.declared) < 0:
            raise ValueError(f"a VoxelCount is {min(self.declared)}")


def _read_config(zf) -> _Config:
    try:
        root = ET.fromstring(read_member(zf, CONFIG, CONFIG_LIMIT))
        text = lambda el, tag: (el.findtext(tag) or "").strip()  # noqa: E731
        size = [int(text(root, t)) for t in ("SliceDimensions/SliceWidth", "SliceDimensions/SliceHeight")]
        res = [float(text(root, f"Resolution/{t}")) for t in ("XDpi", "YDpi", "SliceThicknessNanoMeter")]
        mats = root.findall("MaterialList/Material")
        bg = rgba(text(root, "MaterialList/BackGroundMaterialRGBA").split(), "BackGroundMaterialRGBA")
        cfg = _Config(
            *size,
            int(text(root, "SliceRange/NumberOfSlices")),
            tuple(res[:2]),
            res[2] / 1000,
            text(root, "ImageFilePrefix") or PREFIX,
            bg,
            [text(m, "Name") or f"material {i + 1}" for i, m in enumerate(mats)],
            [rgba(text(m, "RGBA").split(), f"material {i + 1}'s RGBA") for i, m in enumerate(mats)],
            [int(text(m, "VoxelCount")) for m in mats],
        )
        start = int(text(root, "SliceRange/StartIndex") or 0)
    except (ET.ParseError, ValueError, OverflowError) as exc:
        if isinstance(exc, PackageError):
            raise
        raise PackageError(f"{CONFIG} is incomplete or malformed ({type(exc).__name__}: {exc})") from None
    if start != 0:
        raise PackageError(f"{CONFIG}: StartIndex is {start}, not 0")
    return cfg


def _check_parts(zf, cfg: _Config, scan: Scan, box: list) -> None:
    """The z-buffer, ``MeshBbx.ktn`` and ``Mesh.stl`` (where present) against the slices' printed voxels."""
    names = set(zf.namelist())
    if ZBUFFER in names:
        zb = read_png(zf, ZBUFFER, (cfg.W, cfg.H), mode=None)
        if zb.ndim != 2:
            raise PackageError(f"{ZBUFFER} has {zb.shape[2]} channels; a z-buffer is one grey channel")
        bad = zb.astype(np.int64) != scan.top
        if bad.any():
            r, c = (int(v) for v in np.argwhere(bad)[0])
            raise PackageError(
                f"{ZBUFFER} at (row {r}, column {c}) is {zb[r, c]}; the topmost printed layer is {scan.top[r, c]}"
            )
    if BBOX in names:
        raw = read_member(zf, BBOX, 1024)
        ktn = np.frombuffer(raw, "<f4").tolist() if len(raw) == 24 else None
        if ktn != [float(v) for v in box]:
            raise PackageError(f"{BBOX} holds {ktn}; the printed voxels' box is {box}")
    if STL in names:
        info = zf.getinfo(STL)
        with reading(STL, info.file_size), zf.open(info) as fh:
            lo, hi, block = stl_bounds(fh, info.file_size)
        pitch = np.array([MM_PER_INCH / cfg.dpi[0], -MM_PER_INCH / cfg.dpi[1], cfg.layer_um / 1000])
        check_bounds(lo, hi, box, pitch, block, STL)


def check_gcvf(path: Path, keep_layers=(), labels: bool = False) -> tuple[PackageReport, Scan]:
    """Read the GCVF package ``path`` back and check that its member names are safe (``members``) and that its
    parts agree (module docstring); its report and scan (``inspection.Scan``). Errors name ``path``."""
    with about(path), open_zip(path) as zf:
        if CONFIG not in zf.namelist():
            raise PackageError(f"no {CONFIG} in the package (a GCVF holds its configuration there)")
        cfg = _read_config(zf)
        files = layer_files(zf.namelist(), re.escape(cfg.prefix) + r"(\d+)\.png", cfg.N, CONFIG)
        check_png_size(zf, files[0], (cfg.W, cfg.H))
        decode = decoder(cfg.rgba, cfg.background)
        scan = Scan(cfg.N, cfg.H, cfg.W, len(cfg.names), keep_layers, labels)
        for k, name in enumerate(files):
            scan.add(k, decode(name, read_png(zf, name, (cfg.W, cfg.H))))
        check_counts(cfg.names, cfg.declared, scan.counts, CONFIG)
        box = scan.box()
        _check_parts(zf, cfg, scan, box)
        source = read_source_comment(zf.comment)
    materials = [
        {"name": n, "color": list(c), "voxel_count": int(v)}
        for n, c, v in zip(cfg.names, cfg.rgba, scan.counts, strict=True)
    ]
    report = PackageReport(Gcvf.name, str(path), cfg.N, cfg.W, cfg.H, cfg.dpi, cfg.layer_um, materials, box, source)
    return report, scan


class Gcvf:
    """The GrabCAD Voxel Print package as a ``formats.Format``."""

    name = "gcvf"
    suffix = ".gcvf"
    default_printer = "j750"
    takes_mixture = False

    def write(self, job: PrintJob, path) -> dict:
        return write_gcvf(job, path)

    def recognises(self, path: Path) -> bool:
        return zip_holds(path, CONFIG)

    def check(self, path: Path, keep_layers=(), labels: bool = False) -> tuple[PackageReport, Scan]:
        return check_gcvf(path, keep_layers, labels)

    def run_output(self, run: RunDir, mixture: bool = False) -> Path:
        return run.gcvf_path

    def describe(self, summary: dict) -> str:
        return slices_line(summary, summary["layer_thickness_nm"] / 1000)
