"""GrabCAD Voxel Print package (``.gcvf``): the file print labs load into GrabCAD Print for Stratasys voxel printing.

``write_gcvf`` writes one zip (atomically: a temporary file beside it, then renamed), streaming: one layer at a
time is encoded (``labels`` may be a memory-mapped label file), the z-buffer, the bounding box and the outline's
occupancy are accumulated on the way, and nothing but the current layers is held. The zip holds, at its root:

- ``layer_0.png`` ... ``layer_{Z-1}.png``: one opaque RGBA PNG per layer, slice 0 = bottom layer, numbered from 0
  without zero padding, every slice the same pixel size (the printer grid's X x Y), DPI in the pHYs chunk. Pixel
  orientation as in ``export.py`` (column 0 = smallest x, row 0 = largest y). Empty voxels are opaque black
  ``0 0 0 255`` (the background material of the configuration), so the black ink is drawn ``#282828`` by default;
  every other ink keeps its ``export.DEFAULT_PALETTE`` colour (cyan ``0 255 255 255`` ... as in the builder).
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
  y), z = layer x layer thickness. It comes from marching cubes on the printer-grid occupancy at level 0.5: on
  the voxel faces, with the voxels' convex edges and corners cut (every voxel centre lies inside). Grids above
  ``OUTLINE_MAX_CELLS`` printer voxels (marching cubes on 10^9 voxels would need tens of GB) use blocks of
  fz x fy x fx printer voxels instead (``outline_factors``: the smallest near-cubic blocks that bring the grid
  under the limit; about 0.1 mm for a 40 mm object): a block is occupied if any of its voxels or of its 26
  neighbour blocks' voxels is (``block_outline``; without that margin the cut corners of a block would leave out
  voxel centres), so the outline encloses every printed voxel and lies within two blocks of them. The 80-byte
  header names the block (``BLOCK_TAG``), so that a reader knows how far the outline may stand off the voxels.
- The zip's archive comment (which no printer software reads) records the file the package was made from:
  ``{"inkopt": {"source": NAME, "digest": "sha256:..."}}`` (``io.source_comment``).

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
import xml.etree.ElementTree as ET
import zipfile
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ..io import atomic_file, source_comment
from ..model import EMPTY
from .export import check_job, slice_image, slice_lut

CONFIG, STL, ZBUFFER, BBOX, PREFIX = "ConfigFile.xml", "Mesh.stl", "Zbuffer.png", "MeshBbx.ktn", "layer_"
BLOCK_TAG = "inkopt outline block"  # STL header: f"{BLOCK_TAG} fx fy fz" (printer voxels per outline block)
OUTLINE_MAX_CELLS = 2**24  # marching cubes on at most this many cells (float32: 64 MB)
BACKGROUND = (0, 0, 0, 255)
GCVF_PALETTE = {"black": "#282828"}  # the background is opaque black: move the black ink off it
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


def check_package_target(path: Path, member: str = CONFIG, kind: str = "GCVF package", suffix: str = ".gcvf") -> None:
    """One-line ValueError unless ``path`` may be written: not a folder, and if it exists a package of this
    ``kind`` (a zip holding ``member``), which is replaced; any other file is refused, never overwritten."""
    if path.is_dir():
        raise ValueError(f"{path} is a folder; give a {suffix} file name")
    if path.exists():
        try:
            with zipfile.ZipFile(path) as zf:
                ok = member in zf.namelist()
        except (OSError, zipfile.BadZipFile):
            ok = False
        if not ok:
            raise ValueError(f"{path} exists and is not a {kind}; refusing to replace it")


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


def block_outline(coarse, voxel_mm_printer, factors):
    """The outline mesh of a (Z', Y', X') block occupancy with blocks of ``factors`` (fz, fy, fx) printer voxels
    of ``voxel_mm_printer`` (x, y, z) mm: blocks grown by one block in every direction unless they are single
    voxels (module docstring), then ``outline_mesh``."""
    fz, fy, fx = factors
    if (fz, fy, fx) != (1, 1, 1):
        from scipy.ndimage import binary_dilation

        coarse = binary_dilation(np.pad(coarse, 1), np.ones((3, 3, 3), bool))
        mesh = outline_mesh(coarse, np.asarray(voxel_mm_printer) * np.array([fx, fy, fz]))
        mesh.apply_translation(-np.asarray(voxel_mm_printer) * np.array([fx, fy, fz]))  # the pad's block
        return mesh
    return outline_mesh(coarse, voxel_mm_printer)


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
    cap = job.profile.gcvf_colors if job.profile is not None and job.profile.gcvf_colors else None
    add(root, "MaxNumberOfColors", cap or (job.limit if job.limit is not None else max(6, len(job.used))))
    add(root, "DataSemantics", "Materials")
    add(root, "CreationMode", "MODEL_ONLY")
    add(root, "ImageFilePrefix", PREFIX)
    mats = add(root, "MaterialList", BackGroundMaterialRGBA=" ".join(map(str, bg)))
    for i in job.used:
        add(
            mats,
            "Material",
            Name=job.material(i) or job.names[i],
            RGBA=" ".join(map(str, colours[i])),
            VoxelCount=int(job.counts[i]),
        )
    ET.indent(root, space="    ")
    head = b'<?xml version="1.0" encoding="UTF-8"?>\n<!--  GCVF - GrabCad Voxel Print File  -  -->\n'
    return head + ET.tostring(root, encoding="utf-8") + b"\n"


def write_gcvf(
    labels,
    voxel_mm_printer,
    ink_names,
    path,
    printer="j750",
    palette=None,
    max_materials=None,
    materials=None,
    source=None,
    digest=None,
) -> dict:
    """Write the GrabCAD Voxel Print package ``path`` (layout: module docstring); returns a summary dict.

    labels, voxel_mm_printer, ink_names, palette, max_materials, materials: as ``export.write_png_slices``;
    ``printer``: the profile whose material limit and names apply (default J750); ``source``, ``digest``: the
    file the labels come from and its ``io.file_digest``, recorded in the archive comment. A job using more inks
    than the printer holds, a grid whose DPI is not a whole number, or an empty job is refused before anything is
    written; an existing ``path`` is replaced only if it is a GCVF package.
    """
    job = check_job(labels, voxel_mm_printer, ink_names, max_materials, printer, materials)
    if not job.used:
        raise ValueError("nothing to print: every voxel is empty")
    dpi_int = tuple(int(round(d)) for d in job.dpi)
    if not np.allclose(job.dpi, dpi_int, rtol=1e-4):
        raise ValueError(f"GCVF needs whole-number DPI; the grid is {job.dpi[0]:.3f} x {job.dpi[1]:.3f} DPI")
    layer_nm = int(round(job.vp[2] * 1e6))
    lut, colours, bg = slice_lut(job.names, {**GCVF_PALETTE, **(palette or {})}, BACKGROUND)
    path = Path(path)
    check_package_target(path)

    from PIL import Image

    Z, Y, X = job.labels.shape
    fz, fy, fx = outline_factors((Z, Y, X), job.vp)
    coarse = np.zeros((-(-Z // fz), -(-Y // fy), -(-X // fx)), bool)
    top = np.zeros((Y, X), np.uint16)  # index of the topmost occupied layer (0 also where nothing is printed)
    lo, hi = np.array([X, Y, Z]), np.zeros(3, np.int64)  # occupied box (x, label y, z), max exclusive
    workers = min(8, os.cpu_count() or 1)
    with atomic_file(path) as fh, zipfile.ZipFile(fh, "w") as zf, ThreadPoolExecutor(workers) as pool:
        pngs = _in_order(pool, lambda k: _png(slice_image(lut, job.labels[k]), dpi_int), Z, 4 * workers)
        for k, data in enumerate(pngs):
            zf.writestr(f"{PREFIX}{k}.png", data, compress_type=zipfile.ZIP_STORED)
            occ = np.asarray(job.labels[k]) != EMPTY
            top[occ] = k
            coarse[k // fz] |= _block_any(occ, fy, fx)
            if occ.any():
                cols, rows = np.flatnonzero(occ.any(0)), np.flatnonzero(occ.any(1))
                lo = np.minimum(lo, [cols[0], rows[0], k])
                hi = np.maximum(hi, [cols[-1] + 1, rows[-1] + 1, k + 1])
        zf.writestr(CONFIG, config_xml(job, colours, bg, dpi_int, layer_nm), compress_type=zipfile.ZIP_DEFLATED)
        zb = io.BytesIO()
        Image.fromarray(top[::-1, :]).save(zb, format="PNG", compress_level=6)
        zf.writestr(ZBUFFER, zb.getvalue(), compress_type=zipfile.ZIP_STORED)
        box = [lo[0], Y - hi[1], lo[2], hi[0], Y - lo[1], hi[2]]  # label y -> image row (row 0 = largest y)
        zf.writestr(BBOX, np.asarray(box, "<f4").tobytes(), compress_type=zipfile.ZIP_STORED)
        mesh = block_outline(coarse, job.vp, (fz, fy, fx))
        mesh.apply_translation([0.0, -Y * job.vp[1], 0.0])  # origin at the image's top-left corner
        stl = stl_bytes(mesh, f"{BLOCK_TAG} {fx} {fy} {fz}")
        zf.writestr(STL, stl, compress_type=zipfile.ZIP_DEFLATED)
        zf.comment = source_comment(source, digest)
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
        "bounding_box_voxels": [int(v) for v in box],
        "stl_triangles": len(mesh.faces),
        "outline_block": [fx, fy, fz],
        "bytes": path.stat().st_size,
    }
