"""GrabCAD Voxel Print package (``.gcvf``): the file print labs load into GrabCAD Print for Stratasys voxel printing.

``write_gcvf`` writes one zip (atomically, through ``inkopt.io.atomic_write_bytes``) holding:

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
  cubes on the printer-grid occupancy at level 0.5, i.e. on the voxel faces.
- ``zbuffer.png``: the z-buffer seen from above: a 16-bit grey PNG of the slices' pixel size and orientation whose
  value is 1 + the index of the topmost occupied layer in that column (0 = nothing printed there).

Source followed: the public GCVF builder ``buildGCVF.js`` (a Node script found in the code index; its repository
is not named there) for the zip layout at the root, ``ConfigFile.xml`` and every element, value and material
code, the ``layer_N.png`` naming and the opaque-black background; and OpenVCAD's ``GCVFExporter`` (C++ API
docs, MacCurdyLab/OpenVCAD-Docs ``v2/_sources/cpp-api/libvcad-compilers-inkjet.rst.txt`` and
matterassembly.org/OpenVCAD-Docs/v2/cpp-api/libvcad-compilers-inkjet.html) for the package's parts (PNG stack,
z-buffer image, STL mesh, XML configuration, a bounding-box file, zipped) and its defaults 600 x 300 DPI and
27000 nm. Not confirmed: OpenVCAD's exporter source (``gcvf_exporter.cpp``) is not in the public index we could
search, so the names ``model.stl`` and ``zbuffer.png``, the z-buffer's encoding, what ``BitDepth`` means, and
the bounding-box file (not written: its format is not described anywhere we found) are our choices; nor have we
loaded a package into GrabCAD Print.
"""
from __future__ import annotations

import io
import os
import zipfile
import xml.etree.ElementTree as ET
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ..io import atomic_write_bytes
from ..model import EMPTY
from .export import check_job, slice_image, slice_lut

CONFIG, STL, ZBUFFER, PREFIX = "ConfigFile.xml", "model.stl", "zbuffer.png", "layer_"
BACKGROUND = (0, 0, 0, 255)
GCVF_PALETTE = {"black": "#282828"}  # the background is opaque black: move the black ink off it
# GrabCAD material codes used by the reference builder for the printer profiles' material names
GCVF_NAMES = {"VeroCyan-V": "VeroCY-V", "VeroMagenta-V": "VeroMGT-V", "VeroYellow-V": "VeroYL-V",
              "VeroUltraWhite": "VUltraWhite"}


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


def zbuffer(occupied) -> np.ndarray:
    """(Y, X) uint16: 1 + the topmost occupied layer of each column (0 = empty), row 0 = largest y."""
    occ = np.asarray(occupied, bool)
    top = occ.shape[0] - np.argmax(occ[::-1], axis=0)
    return np.where(occ.any(axis=0), top, 0).astype(np.uint16)[::-1, :]


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
        add(mats, "Material", Name=GCVF_NAMES.get(vendor, vendor or job.names[i]),
            RGBA=" ".join(map(str, colours[i])), VoxelCount=int(job.counts[i]))
    ET.indent(root, space="    ")
    head = b'<?xml version="1.0" encoding="UTF-8"?>\n<!--  GCVF - GrabCad Voxel Print File  -  -->\n'
    return head + ET.tostring(root, encoding="utf-8") + b"\n"


def write_gcvf(labels, voxel_mm_printer, ink_names, path, printer="j750", palette=None,
               max_materials=None) -> dict:
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

    occupied = job.labels != EMPTY
    Z, Y, X = job.labels.shape
    with ThreadPoolExecutor(max_workers=min(8, os.cpu_count() or 1)) as pool:
        pngs = list(pool.map(lambda k: _png(slice_image(lut, job.labels[k]), dpi_int), range(Z)))
    from PIL import Image

    mesh = outline_mesh(occupied, job.vp)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for k, data in enumerate(pngs):
            zf.writestr(f"{PREFIX}{k}.png", data, compress_type=zipfile.ZIP_STORED)
        zf.writestr(CONFIG, config_xml(job, colours, bg, dpi_int, layer_nm), compress_type=zipfile.ZIP_DEFLATED)
        zf.writestr(ZBUFFER, _png(Image.fromarray(zbuffer(occupied)), dpi_int), compress_type=zipfile.ZIP_STORED)
        zf.writestr(STL, mesh.export(file_type="stl"), compress_type=zipfile.ZIP_DEFLATED)
    atomic_write_bytes(path, buf.getvalue())
    return {"path": str(path), "layer_count": Z, "image_size": {"width": X, "height": Y},
            "dpi": {"x": dpi_int[0], "y": dpi_int[1]}, "layer_thickness_nm": layer_nm,
            "materials": [{"ink": job.names[i], "material": job.material(i), "color": list(colours[i]),
                           "voxel_count": int(job.counts[i])} for i in job.used],
            "printer": job.profile["name"] if job.profile else None, "stl_triangles": len(mesh.faces),
            "bytes": len(buf.getvalue())}
