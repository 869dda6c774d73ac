"""GrabCAD Voxel Print package (``.gcvf``): the file print labs load into GrabCAD Print for Stratasys voxel printing.

``write_gcvf`` writes one zip (atomically: a temporary file beside it, then renamed), streaming: one layer at a
time is encoded (``labels`` may be a memory-mapped label file), the z-buffer and the outline's occupancy are
accumulated on the way, and nothing but the current layers is held. The zip holds:

- ``layer_0.png`` ... ``layer_{Z-1}.png``: one opaque RGBA PNG per layer, slice 0 = bottom layer, numbered from 0
  without zero padding, every slice the same pixel size (the printer grid's X x Y), DPI in the pHYs chunk. Pixel
  orientation as in ``export.py`` (column 0 = smallest x, row 0 = largest y). Empty voxels are opaque black
  ``0 0 0 255`` (the background material of the configuration), so the black ink is drawn ``#282828`` by default;
  every other ink keeps its ``export.DEFAULT_PALETTE`` colour (cyan ``0 255 255 255`` ... as in the reference).
- ``ConfigFile.xml``: ``<GCVF>`` version 2 with ``<Resolution>`` (``XDpi``, ``YDpi``,
  ``SliceThicknessNanoMeter``), ``<SliceDimensions>`` (``SliceWidth``, ``SliceHeight``), ``<SliceRange>``
  (``StartIndex`` 0, ``NumberOfSlices``), ``BitDepth`` 4, ``MaxNumberOfColors`` (the printer's material slots),
  ``DataSemantics`` Materials, ``CreationMode`` MODEL_ONLY, ``ImageFilePrefix`` layer_ and ``<MaterialList>``:
  ``BackGroundMaterialRGBA`` and one ``<Material>`` (``Name``, ``RGBA`` as "r g b a", ``VoxelCount``) per ink
  used. ``Name`` is GrabCAD's short material code where the reference uses one (VeroCY-V, VeroMGT-V, VeroYL-V,
  VUltraWhite), else the printer profile's material name (``profiles.py``), else the ink name (a material the
  lab assigns by hand in GrabCAD Print).
- ``model.stl``: the outline of the print (every non-empty voxel), binary STL in mm in the slices' frame (origin
  at the corner of voxel (0, 0, 0), +x along image columns, +y towards row 0, +z up the stack), from marching
  cubes on the printer-grid occupancy at level 0.5, i.e. on the voxel faces. Grids above ``OUTLINE_MAX_CELLS``
  printer voxels (marching cubes on 10^9 voxels would need tens of GB) use blocks of fz x fy x fx printer voxels
  instead (``outline_factors``: the smallest near-cubic blocks that bring the grid under the limit; about
  0.1 mm for a 40 mm object): a block is occupied if any of its voxels is, so the outline encloses every printed
  voxel and lies within one block of them.
- ``zbuffer.png``: the z-buffer seen from above: a 16-bit grey PNG of the slices' pixel size and orientation whose
  value is 1 + the index of the topmost occupied layer in that column (0 = nothing printed there).

Source followed: a public GCVF builder, the Node script ``buildGCVF.js`` (its repository unknown to us), for the
zip layout at the root, ``ConfigFile.xml`` and every element, value and material code, the ``layer_N.png``
naming and the opaque-black background; and OpenVCAD's ``GCVFExporter`` (C++ API docs,
MacCurdyLab/OpenVCAD-Docs ``v2/_sources/cpp-api/libvcad-compilers-inkjet.rst.txt`` and
matterassembly.org/OpenVCAD-Docs/v2/cpp-api/libvcad-compilers-inkjet.html) for the package's parts (PNG stack,
z-buffer image, STL mesh, XML configuration, a bounding-box file, zipped) and its defaults 600 x 300 DPI and
27000 nm. Not confirmed: we have not seen OpenVCAD's exporter source (``gcvf_exporter.cpp``), so the names
``model.stl`` and ``zbuffer.png``, the z-buffer's encoding, what ``BitDepth`` means, and the bounding-box file
(not written: its format is not described anywhere we found) are our choices; nor have we loaded a package into
GrabCAD Print.
"""

from __future__ import annotations

import io
import os
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ..model import EMPTY
from .export import check_job, slice_image, slice_lut

CONFIG, STL, ZBUFFER, PREFIX = "ConfigFile.xml", "model.stl", "zbuffer.png", "layer_"
OUTLINE_MAX_CELLS = 2**24  # marching cubes on at most this many cells (float32: 64 MB)
BACKGROUND = (0, 0, 0, 255)
GCVF_PALETTE = {"black": "#282828"}  # the background is opaque black: move the black ink off it
# GrabCAD material codes used by the reference builder for the printer profiles' material names
GCVF_NAMES = {
    "VeroCyan-V": "VeroCY-V",
    "VeroMagenta-V": "VeroMGT-V",
    "VeroYellow-V": "VeroYL-V",
    "VeroUltraWhite": "VUltraWhite",
}


def _png(image, dpi) -> bytes:
    buf = io.BytesIO()
    image.save(buf, format="PNG", dpi=dpi, compress_level=1)
    return buf.getvalue()


def _check_target(path: Path) -> None:
    if path.is_dir():
        raise ValueError(f"{path} is a folder; give a .gcvf file name")
    if path.exists():
        try:
            with zipfile.ZipFile(path) as zf:
                ok = CONFIG in zf.namelist()
        except (OSError, zipfile.BadZipFile):
            ok = False
        if not ok:
            raise ValueError(f"{path} exists and is not a GCVF package; refusing to replace it")


def outline_mesh(occupied, voxel_mm_printer):
    """A watertight ``trimesh.Trimesh`` (mm, x y z) around the True voxels of ``occupied`` (Z, Y, X)."""
    import trimesh
    from skimage.measure import marching_cubes

    vp = np.asarray(voxel_mm_printer, np.float64)
    pad = np.pad(np.asarray(occupied, np.float32), 1)
    verts, faces, _, _ = marching_cubes(pad, level=0.5, spacing=(vp[2], vp[1], vp[0]))
    # padded index i sits at (i - 0.5) voxels; marching_cubes winds the faces for (z, y, x) with the normals into
    # the lower values, so swapping the axes to (x, y, z) turns them outwards
    return trimesh.Trimesh(verts[:, ::-1] - 0.5 * vp, faces, process=True)


def outline_factors(shape, voxel_mm_printer, max_cells: int | None = None) -> tuple[int, int, int]:
    """Block size (fz, fy, fx) in printer voxels for the outline of a (Z, Y, X) grid: (1, 1, 1) up to
    ``max_cells`` (default ``OUTLINE_MAX_CELLS``) voxels, else grown one step at a time along the axis whose
    block is thinnest in mm."""
    max_cells = OUTLINE_MAX_CELLS if max_cells is None else max_cells
    shape = np.asarray(shape, np.int64)
    size = np.asarray(voxel_mm_printer, np.float64)[::-1]  # (z, y, x) mm
    f = np.ones(3, np.int64)
    while np.prod(-(-shape // f)) > max_cells:
        grow = f < shape
        i = int(np.argmin(np.where(grow, size * f, np.inf)))
        f[i] += 1
    return tuple(int(v) for v in f)


def _block_any(occ, fy: int, fx: int) -> np.ndarray:
    """(Y, X) bool -> (ceil(Y / fy), ceil(X / fx)): True where any voxel of the block is."""
    if fy == fx == 1:
        return occ
    Y, X = occ.shape
    pad = np.pad(occ, ((0, -Y % fy), (0, -X % fx)))
    return pad.reshape(pad.shape[0] // fy, fy, pad.shape[1] // fx, fx).any(axis=(1, 3))


def _in_order(pool, fn, n: int, window: int):
    """fn(0), ..., fn(n - 1) computed in ``pool`` with at most ``window`` results pending, yielded in order."""
    pending: deque = deque()
    for k in range(n):
        pending.append(pool.submit(fn, k))
        if len(pending) >= window:
            yield pending.popleft().result()
    while pending:
        yield pending.popleft().result()


def config_xml(job, colours, bg, dpi_int, layer_nm) -> bytes:
    """``ConfigFile.xml`` of the reference builder for ``job`` (its used inks, counts and colours)."""
    root = ET.Element("GCVF")

    def add(parent, tag, text=None, **children):
        el = ET.SubElement(parent, tag)
        if text is not None:
            el.text = str(text)
        for k, v in children.items():
            ET.SubElement(el, k).text = str(v)
        return el

    Z, Y, X = job.labels.shape
    add(root, "Version", 2)
    add(root, "Resolution", XDpi=dpi_int[0], YDpi=dpi_int[1], SliceThicknessNanoMeter=layer_nm)
    add(root, "SliceDimensions", SliceWidth=X, SliceHeight=Y)
    add(root, "SliceRange", StartIndex=0, NumberOfSlices=Z)
    add(root, "BitDepth", 4)
    add(root, "MaxNumberOfColors", job.limit if job.limit is not None else max(6, len(job.used)))
    add(root, "DataSemantics", "Materials")
    add(root, "CreationMode", "MODEL_ONLY")
    add(root, "ImageFilePrefix", PREFIX)
    mats = add(root, "MaterialList", BackGroundMaterialRGBA=" ".join(map(str, bg)))
    for i in job.used:
        vendor = job.material(i)
        add(
            mats,
            "Material",
            Name=GCVF_NAMES.get(vendor, vendor or job.names[i]),
            RGBA=" ".join(map(str, colours[i])),
            VoxelCount=int(job.counts[i]),
        )
    ET.indent(root, space="    ")
    head = b'<?xml version="1.0" encoding="UTF-8"?>\n<!--  GCVF - GrabCad Voxel Print File  -  -->\n'
    return head + ET.tostring(root, encoding="utf-8") + b"\n"


def write_gcvf(labels, voxel_mm_printer, ink_names, path, printer="j750", palette=None, max_materials=None) -> dict:
    """Write the GrabCAD Voxel Print package ``path`` (layout: module docstring); returns a summary dict.

    labels, voxel_mm_printer, ink_names, palette, max_materials: as ``export.write_png_slices``; ``printer``: the
    profile whose material limit and names apply (default J750). A job using more inks than the printer holds,
    a grid whose DPI is not a whole number, or an empty job is refused before anything is written; an existing
    ``path`` is replaced only if it is a GCVF package.
    """
    job = check_job(labels, voxel_mm_printer, ink_names, max_materials, printer)
    if not job.used:
        raise ValueError("nothing to print: every voxel is empty")
    dpi_int = tuple(int(round(d)) for d in job.dpi)
    if not np.allclose(job.dpi, dpi_int, rtol=1e-4):
        raise ValueError(f"GCVF needs whole-number DPI; the grid is {job.dpi[0]:.3f} x {job.dpi[1]:.3f} DPI")
    layer_nm = int(round(job.vp[2] * 1e6))
    lut, colours, bg = slice_lut(job.names, {**GCVF_PALETTE, **(palette or {})}, BACKGROUND)
    path = Path(path)
    _check_target(path)

    from PIL import Image

    Z, Y, X = job.labels.shape
    fz, fy, fx = outline_factors((Z, Y, X), job.vp)
    coarse = np.zeros((-(-Z // fz), -(-Y // fy), -(-X // fx)), bool)
    top = np.zeros((Y, X), np.uint16)  # 1 + topmost occupied layer
    workers = min(8, os.cpu_count() or 1)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh, zipfile.ZipFile(fh, "w") as zf, ThreadPoolExecutor(workers) as pool:
            pngs = _in_order(pool, lambda k: _png(slice_image(lut, job.labels[k]), dpi_int), Z, 4 * workers)
            for k, data in enumerate(pngs):
                zf.writestr(f"{PREFIX}{k}.png", data, compress_type=zipfile.ZIP_STORED)
                occ = np.asarray(job.labels[k]) != EMPTY
                top[occ] = k + 1
                coarse[k // fz] |= _block_any(occ, fy, fx)
            zf.writestr(CONFIG, config_xml(job, colours, bg, dpi_int, layer_nm), compress_type=zipfile.ZIP_DEFLATED)
            zf.writestr(ZBUFFER, _png(Image.fromarray(top[::-1, :]), dpi_int), compress_type=zipfile.ZIP_STORED)
            mesh = outline_mesh(coarse, job.vp * np.array([fx, fy, fz]))
            zf.writestr(STL, mesh.export(file_type="stl"), compress_type=zipfile.ZIP_DEFLATED)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return {
        "path": str(path),
        "layer_count": Z,
        "image_size": {"width": X, "height": Y},
        "dpi": {"x": dpi_int[0], "y": dpi_int[1]},
        "layer_thickness_nm": layer_nm,
        "materials": [
            {
                "ink": job.names[i],
                "material": job.material(i),
                "color": list(colours[i]),
                "voxel_count": int(job.counts[i]),
            }
            for i in job.used
        ],
        "printer": job.profile.name if job.profile else None,
        "stl_triangles": len(mesh.faces),
        "outline_block": [fx, fy, fz],
        "bytes": path.stat().st_size,
    }
