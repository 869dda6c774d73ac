"""3MF with the Volumetric extension (v0.8.0): the ink mixture of every voxel as a material composite.

``write_3mf`` writes a job's voxels (labels as 0/1 shares, or a mixture) as one OPC zip (atomically: a temporary
file beside it, then renamed), one layer at a time:

- ``3D/3dmodel.model`` (core namespace 2015/02, volumetric ``v`` = http://schemas.3mf.io/3dmanufacturing/volumetric/
  2022/01, listed in ``recommendedextensions``: the shape does not depend on it), resources in this order:
  ``<basematerials>`` with one ``<base>`` per ink (``name``: its printer material name, else the ink name;
  ``displaycolor``: its slice colour, ``slices.ink_colours``); per group of four inks a ``<v:image3d>`` with one
  ``<v:imagestack>`` of Z sheets (rows = Y, columns = X of the grid) and a ``<v:functionfromimage3d>`` (filter
  nearest, tile style clamp, value scale 1); a ``<v:volumedata>`` with a ``<v:composite>`` over the base materials,
  one ``<v:materialmapping>`` per ink reading its stack's ``red``, ``green``, ``blue`` or ``alpha`` channel; and
  the object (named ``OBJECT_NAME`` and its outline block), a ``<mesh v:volumeid=...>``: the outline of the
  occupied voxels (``outline.block_outline``, in blocks above ``outline.OUTLINE_MAX_CELLS`` voxels) in mm with its
  origin at the grid's corner (x along columns, y along the grid's y, z up). Every mapping's ``transform`` is
  the object-to-UVW scale diag(1 / (X dx), 1 / (Y dy), 1 / (Z dz)).
- ``3D/volumetric/inksG/sheetNNNNN.png``: 8-bit RGBA PNGs, sheet k = layer k (bottom first), row 0 = largest y (the
  spec puts row 0 at v = 1), column 0 = smallest x; channel c of group G holds ink 4 G + c's share x 255 (rounded),
  so the composite's ratio value_i / sum reproduces the mixture to 1/255. Empty voxels are 0 in every channel,
  except inside the blocks of a block outline (the outline encloses them, and the spec forbids a zero sum inside
  the clipping surface): they take the shares of the nearest printed voxel in their layer, or of the nearest
  printed layer. The voxels with shares are then the voxels a consumer prints (the outline's margin included).
  Reading the shares twice (a first pass for the outline) keeps memory to a few layers.
- the OPC parts ``[Content_Types].xml``, ``_rels/.rels`` and ``3D/_rels/3dmodel.model.rels`` (one 3D-texture
  relationship per sheet), and the zip's archive comment: the source file's digest (``io.source_comment``).

``check_3mf`` refuses unsafe member names and image sheets the package does not hold (``members``), checks
every number of the model it uses (counts, the mappings' transform, vertices) and reads the file back one sheet
at a time: the voxels with a non-zero share sum are the printed ones,
their sums must be 1 to within the 8-bit rounding of the sheets, and the mesh's bounds must agree with them as a
GCVF's STL's do (``inspection``).

lib3mf 2.5.0 writes image stacks and volume data colour, but every method of its ``VolumeDataComposite`` throws
LIB3MF_ERROR_NOTIMPLEMENTED and its colour element lacks the required ``channel``, so this module writes the XML
itself; the tests validate every volumetric element against the spec's ``volumetric.xsd`` and open the file with
lib3mf as a reader check. No volumetric consumer (slicer or printer driver) has read these files here.
"""

from __future__ import annotations

import io
import math
import re
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ...io import atomic_file, read_source_comment, source_comment
from ...model import EMPTY
from ...units import MM_PER_INCH
from .archive import check_target, zip_holds
from .inspection import PackageError, PackageReport, Scan, about, check_bounds
from .job import LabelVoxels, PrintJob, tally
from .members import check_names, check_png_size, name_problem, open_zip, raw_names, read_png, reading
from .outline import block_any, block_outline, coarse_grid, grown, outline_factors
from .slices import ink_colours
from .threemf_xml import CHANNELS, MODEL, NS_CORE, model_xml, sheet_path, write_opc

if TYPE_CHECKING:
    from ...rundir import RunDir


def _fill_empty(shares: np.ndarray, occ: np.ndarray) -> np.ndarray:
    """(Y, X, N) shares with every empty voxel given its nearest occupied voxel's shares (``occ`` has one)."""
    if occ.all():
        return shares
    from scipy.ndimage import distance_transform_edt

    _, (iy, ix) = distance_transform_edt(~occ, return_indices=True)
    return shares[iy, ix]


def _sheets(shares: np.ndarray, groups: int) -> list[bytes]:
    """(Y, X, N) shares in [0, 1] -> one RGBA PNG per group of four inks (row 0 = largest y)."""
    from PIL import Image

    Y, X, N = shares.shape
    q = np.clip(np.rint(np.asarray(shares, np.float32) * 255), 0, 255).astype(np.uint8)[::-1]
    out = []
    for g in range(groups):
        rgba = np.zeros((Y, X, 4), np.uint8)
        part = q[:, :, 4 * g : 4 * g + 4]
        rgba[:, :, : part.shape[2]] = part
        buf = io.BytesIO()
        Image.fromarray(rgba, "RGBA").save(buf, format="PNG", compress_level=1)
        out.append(buf.getvalue())
    return out


def _put(zf, k: int, shares: np.ndarray, inside: np.ndarray, groups: int) -> None:
    """Sheet ``k`` of every group: ``shares`` where ``inside``, 0 elsewhere."""
    for g, data in enumerate(_sheets(np.where(inside[..., None], shares, 0.0), groups)):
        zf.writestr(sheet_path(g, k)[1:], data, compress_type=zipfile.ZIP_STORED)


def _write_sheets(zf, voxels, region, factors, groups: int) -> np.ndarray:
    """Every layer's sheets (module docstring): the shares inside ``region`` (the outline's blocks), an empty layer
    taking the nearest printed layer's below (or else above) it. Returns the shares' sums over the printed voxels."""
    fz, fy, fx = factors
    Z, Y, X = voxels.shape
    counts = np.zeros(len(voxels.inks), np.float64)
    pending, last = [], None
    for k in range(Z):
        occ = np.asarray(voxels.occupied(k), bool)
        inside = np.repeat(np.repeat(region[k // fz], fy, 0), fx, 1)[:Y, :X]
        if not occ.any():
            if last is None:
                pending.append((k, inside))
            else:
                _put(zf, k, last, inside, groups)
            continue
        sh = np.asarray(voxels.shares(k), np.float32)
        counts += sh[occ].sum(0)
        last = _fill_empty(sh, occ) if factors != (1, 1, 1) else np.where(occ[..., None], sh, 0.0)
        for j, ins in pending:
            _put(zf, j, last, ins, groups)
        pending = []
        _put(zf, k, last, inside, groups)
    return counts


def write_3mf(job: PrintJob, path) -> dict:
    """Write ``job``'s voxels as the volumetric 3MF ``path`` (layout: module docstring); returns a summary dict.

    Labels (``LabelVoxels``) are written as 0/1 shares and checked as every label job is (``job.tally``); a
    mixture (``MixtureVoxels``) may put every ink anywhere, so the job loads them all. The ``<base>`` names are the
    inks' material names (``PrintJob.material``), else the ink names; their display colours the slice colours of
    ``job.palette``. An empty grid is refused before anything is written; an existing ``path`` is replaced only if
    it is a 3MF."""
    voxels = job.voxels
    labels = isinstance(voxels, LabelVoxels)
    if labels:
        tally(job)
    else:
        job.check_slots(voxels.inks)
    shape, vp, names = voxels.shape, voxels.voxel_mm, list(voxels.inks)
    base_names = [job.material(n) or n for n in names]
    colours = ink_colours(names, job.palette)
    groups = -(-len(names) // 4)
    path = Path(path)
    check_target(path, MODEL, "3MF file", ThreeMF.suffix)
    factors = outline_factors(shape, vp)
    with atomic_file(path) as fh, zipfile.ZipFile(fh, "w") as zf:
        coarse = coarse_grid(shape, factors)
        for k in range(shape[0]):  # first pass: which outline blocks hold printed voxels
            coarse[k // factors[0]] |= block_any(np.asarray(voxels.occupied(k), bool), *factors[1:])
        if not coarse.any():
            raise ValueError("nothing to print: every voxel is empty")
        mesh = block_outline(coarse, vp, factors)
        region = coarse if factors == (1, 1, 1) else grown(coarse)  # the blocks inside the outline
        counts = _write_sheets(zf, voxels, region, factors, groups)
        with zf.open(MODEL, "w", force_zip64=True) as mf:
            model_xml(mf, base_names, colours, shape, vp, mesh, factors[::-1])
        write_opc(zf, groups, shape[0])
        zf.comment = source_comment(job.provenance.source, job.provenance.digest)
        check_names(raw_names(zf))  # never put a package in place that would unpack outside its folder
    return {
        "path": str(path),
        "layer_count": shape[0],
        "image_size": {"width": shape[2], "height": shape[1]},
        "voxel_mm": [float(v) for v in vp],
        "materials": [
            {"ink": names[i], "material": base_names[i], "color": list(colours[i]), "voxel_count": float(counts[i])}
            for i in range(len(names))
        ],
        "image_stacks": groups,
        "mesh_triangles": len(mesh.faces),
        "outline_block": list(factors[::-1]),
        "content": "labels" if labels else "mixture",
        "bytes": path.stat().st_size,
    }


def _number(el, attr: str, kind=float):
    """Attribute ``attr`` of ``el`` as a finite ``kind`` (float, or int for counts of at least 1)."""
    raw = el.get(attr)
    try:
        v = kind(raw)
    except (TypeError, ValueError, OverflowError):
        v = None
    if v is None or (kind is int and not 1 <= v < 2**31) or not math.isfinite(v):
        what = "a finite number" if kind is float else "a count 1 .. 2^31 - 1"
        shown = raw if raw is None or len(raw) <= 40 else raw[:37] + "..."
        raise PackageError(f"{MODEL}: <{el.tag.rsplit('}', 1)[-1]}> has {attr}={shown!r}, not {what}")
    return v


def _resource(res: dict, tag: str, el, stack):
    """Record the resource ``el`` (its ``tag`` without the namespace) in ``res``; the image stack last read."""
    if tag == "base":
        res["base"].append((el.get("name"), el.get("displaycolor")))
    elif tag == "imagestack":
        stack = {k: _number(el, k, int) for k in ("rowcount", "columncount", "sheetcount")}
        stack["sheets"] = [s.get("path") for s in el]
    elif tag == "image3d":
        res["stacks"][el.get("id")], stack = stack, None
    elif tag == "functionfromimage3d":
        res["functions"][el.get("id")] = el.get("image3did")
    elif tag == "materialmapping":
        res["mappings"].append((el.get("functionid"), el.get("channel"), el.get("transform")))
    elif tag == "object":
        res["object_name"] = el.get("name") or ""
    return stack


_MESH_LISTS = {f"{{{NS_CORE}}}vertices", f"{{{NS_CORE}}}triangles"}


def _bounds(lo: np.ndarray, hi: np.ndarray, points: list) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) widened by ``points`` ((x, y, z) lists)."""
    if not points:
        return lo, hi
    p = np.asarray(points)
    if not np.all(np.isfinite(p)):
        raise PackageError(f"{MODEL}: a vertex has a coordinate that is not a finite number")
    return np.minimum(lo, p.min(0)), np.maximum(hi, p.max(0))


def _mesh_bounds(fh) -> tuple[dict, np.ndarray, np.ndarray]:
    """Stream 3dmodel.model: the resources (without the mesh, whose vertices and triangles are dropped in batches
    as they are read: memory for a few thousand, not the whole mesh) as a small tree and the mesh's bounds."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    res: dict = {"base": [], "stacks": {}, "functions": {}, "mappings": [], "object_name": ""}
    stack, parent, points = None, None, []
    try:
        for event, el in ET.iterparse(fh, events=("start", "end")):
            if event == "start":
                parent = el if el.tag in _MESH_LISTS else parent
                continue
            tag = el.tag.rsplit("}", 1)[-1]
            if tag == "vertex":
                try:
                    points.append([float(el.get("x")), float(el.get("y")), float(el.get("z"))])
                except (TypeError, ValueError):
                    [_number(el, a) for a in "xyz"]  # the one-line error naming the attribute
                if len(points) >= 1 << 16:
                    lo, hi, points = *_bounds(lo, hi, points), []
            elif tag != "triangle":
                stack = _resource(res, tag, el, stack)
            if parent is not None and len(parent) >= 1 << 12:
                del parent[:]  # the parsed events keep their own elements
    except ET.ParseError as exc:
        raise PackageError(f"{MODEL} is not well-formed XML ({exc})") from None
    lo, hi = _bounds(lo, hi, points)
    if not np.all(np.isfinite(lo)):
        raise PackageError(f"{MODEL}: the mesh has no vertices")
    return res, lo, hi


def _stacks(res: dict) -> tuple[list, int, int, int]:
    """Each mapping's image stack and their common (H, W, N); stacks of other sizes are a PackageError."""
    maps, n = res["mappings"], len(res["base"])
    if not 1 <= n < EMPTY or len(maps) != n:
        raise PackageError(f"the composite has {len(maps)} material mappings for {n} base materials (1 .. 254)")
    stacks = []
    for f, channel, _ in maps:
        st = res["stacks"].get(res["functions"].get(f))
        if st is None:
            raise PackageError(f"{MODEL}: the material mapping of function {f!r} reads no image stack")
        if channel not in CHANNELS:
            raise PackageError(f"{MODEL}: a material mapping reads channel {channel!r}, not one of {list(CHANNELS)}")
        stacks.append(st)
    H, W, N = (stacks[0][k] for k in ("rowcount", "columncount", "sheetcount"))
    for st in stacks:
        if (st["rowcount"], st["columncount"], st["sheetcount"], len(st["sheets"])) != (H, W, N, N):
            raise PackageError(
                f"image stacks differ in size or sheet count: {st['columncount']} x {st['rowcount']} x "
                f"{st['sheetcount']} ({len(st['sheets'])} sheets) vs {W} x {H} x {N}"
            )
    return stacks, H, W, N


def _voxel_mm(transform, W: int, H: int, N: int) -> np.ndarray:
    """(x, y, z) mm of a voxel from a mapping's object-to-UVW ``transform`` (12 numbers, a positive diagonal)."""
    try:
        t = np.array([float(v) for v in str(transform).split()])
    except ValueError:
        t = np.zeros(0)
    vox = 1 / (t[[0, 4, 8]] * [W, H, N]) if t.shape == (12,) and np.all(t[[0, 4, 8]] > 0) else np.zeros(3)
    if not (np.all(np.isfinite(vox)) and np.all(vox > 0)):
        raise PackageError(f"{MODEL}: the material mapping's transform {transform!r} is not a positive scale")
    return vox


def _sheet_member(zf, path) -> str:
    """The zip member of an image sheet's part name ``path`` ("/3D/..."), which the package must hold."""
    name = str(path)[1:] if str(path).startswith("/") else str(path)
    problem = name_problem(name) if path is not None else "is missing"
    if not problem:
        try:
            zf.getinfo(name)  # a dict look-up: a package holds thousands of sheets
        except KeyError:
            problem = "is not in the package"
    if problem:
        raise PackageError(f"{MODEL}: image sheet {path!r} {problem}")
    return name


def _read_shares(zf, k: int, stacks, maps, W: int, H: int) -> np.ndarray:
    """(H, W, n) float32 shares of sheet ``k`` in image rows; share sums other than 0 or 1 are a PackageError."""
    n = len(maps)
    sheets = {}
    sh = np.empty((H, W, n), np.float32)
    for i, (st, (_, ch, _)) in enumerate(zip(stacks, maps, strict=True)):
        p = st["sheets"][k]
        if p not in sheets:
            name = _sheet_member(zf, p)
            sheets[p] = read_png(zf, name, (W, H), label=p).astype(np.float32) / 255
        sh[:, :, i] = sheets[p][:, :, CHANNELS.index(ch)]
    total = sh.sum(2)
    off = (total > 0) & (np.abs(total - 1) > n * 0.5 / 255 + 1e-6)
    if off.any():
        r, c = (int(v) for v in np.argwhere(off)[0])
        raise PackageError(f"sheet {k}: the shares at (row {r}, column {c}) sum to {total[r, c]:.4f}, not 1")
    return sh


def _read_model(zf) -> tuple[dict, np.ndarray, np.ndarray]:
    if MODEL not in zf.namelist():
        raise PackageError(f"no {MODEL} in the package (a 3MF holds its model there)")
    info = zf.getinfo(MODEL)
    with reading(MODEL, info.file_size), zf.open(info) as fh:
        return _mesh_bounds(fh)


def check_3mf(path: Path, keep_layers=(), labels: bool = False) -> tuple[PackageReport, Scan]:
    """Read the volumetric 3MF ``path`` back and check its member names (``members``) and its parts (module
    docstring); its report and scan, whose labels are each printed voxel's largest share. Errors name ``path``."""
    with about(path), open_zip(path) as zf:
        res, lo, hi = _read_model(zf)
        stacks, H, W, N = _stacks(res)
        maps, n = res["mappings"], len(res["base"])
        vox = _voxel_mm(maps[0][2], W, H, N)
        check_png_size(zf, _sheet_member(zf, stacks[0]["sheets"][0]), (W, H))
        scan = Scan(N, H, W, n, keep_layers, labels)
        shares = np.zeros(n, np.float64)
        for k in range(N):
            sh = _read_shares(zf, k, stacks, maps, W, H)
            occ = sh.sum(2) > 0
            shares += sh[occ].sum(0)
            scan.add(k, np.where(occ, np.argmax(sh, 2), EMPTY).astype(np.uint8))
        box = scan.box()
        m = re.search(r"block (\d+) (\d+) (\d+)", res["object_name"])
        block = tuple(int(g) for g in m.groups()) if m else (1, 1, 1)
        # the mesh's y runs up the grid: image row r covers y from (H - r - 1) to (H - r) voxels
        ybox = [box[0], H - box[4], box[2], box[3], H - box[1], box[5]]
        check_bounds(lo, hi, ybox, vox, block, "the 3MF mesh")
        source = read_source_comment(zf.comment)
    materials = [
        {"name": b[0], "color": b[1], "voxel_count": float(v)} for b, v in zip(res["base"], shares, strict=True)
    ]
    dpi = (float(MM_PER_INCH / vox[0]), float(MM_PER_INCH / vox[1]))
    report = PackageReport(ThreeMF.name, str(path), N, W, H, dpi, float(vox[2] * 1000), materials, box, source)
    return report, scan


class ThreeMF:
    """The 3MF with the Volumetric extension as a ``formats.Format``: of a mixture or of labels."""

    name = "3mf"
    suffix = ".3mf"
    default_printer = "generic"
    takes_mixture = True

    def write(self, job: PrintJob, path) -> dict:
        return write_3mf(job, path)

    def recognises(self, path: Path) -> bool:  # a 3MF holds its model there, whatever the file is called
        return zip_holds(path, MODEL)

    def check(self, path: Path, keep_layers=(), labels: bool = False) -> tuple[PackageReport, Scan]:
        return check_3mf(path, keep_layers, labels)

    def run_output(self, run: RunDir, mixture: bool = False) -> Path:
        return run.threemf_path(labels=not mixture)

    def describe(self, summary: dict) -> str:
        used = ", ".join(f"{m['ink']} = {m['material']}" for m in summary["materials"] if m["voxel_count"] > 0)
        size = summary["image_size"]
        return (
            f"{summary['layer_count']} sheets of {size['width']} x {size['height']} voxels "
            f"({' x '.join(f'{v * 1000:.1f}' for v in summary['voxel_mm'])} um), {summary['image_stacks']} image "
            f"stacks, {summary['mesh_triangles']} outline triangles; {summary['content']} of {used}"
        )
