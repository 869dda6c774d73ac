"""3MF with the Volumetric extension (v0.8.0): the ink mixture of every voxel as a material composite.

``write_3mf`` writes one OPC zip (atomically: a temporary file beside it, then renamed), one layer at a time:

- ``3D/3dmodel.model`` (core namespace 2015/02, volumetric ``v`` = http://schemas.3mf.io/3dmanufacturing/volumetric/
  2022/01, listed in ``recommendedextensions``: the shape does not depend on it), resources in this order:
  ``<basematerials>`` with one ``<base>`` per ink (``name``: its printer material name, else the ink name;
  ``displaycolor``: its slice colour, ``export.ink_colours``); per group of four inks a ``<v:image3d>`` with one
  ``<v:imagestack>`` of Z sheets (rows = Y, columns = X of the grid) and a ``<v:functionfromimage3d>`` (filter
  nearest, tile style clamp, value scale 1); a ``<v:volumedata>`` with a ``<v:composite>`` over the base materials,
  one ``<v:materialmapping>`` per ink reading its stack's ``red``, ``green``, ``blue`` or ``alpha`` channel; and
  the object (named ``OBJECT_NAME`` and its outline block), a ``<mesh v:volumeid=...>``: the outline of the
  occupied voxels (``gcvf.block_outline``, in blocks above ``gcvf.OUTLINE_MAX_CELLS`` voxels) in mm with its
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

lib3mf 2.5.0 writes image stacks and volume data colour, but every method of its ``VolumeDataComposite`` throws
LIB3MF_ERROR_NOTIMPLEMENTED and its colour element lacks the required ``channel``, so this module writes the XML
itself; the tests validate every volumetric element against the spec's ``volumetric.xsd`` and open the file with
lib3mf as a reader check. No volumetric consumer (slicer or printer driver) has read these files here.
"""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np

from ..io import atomic_file, source_comment
from .export import check_job, ink_colours
from .gcvf import _block_any, block_outline, check_package_target, outline_factors

NS_CORE = "http://schemas.microsoft.com/3dmanufacturing/core/2015/02"
NS_V = "http://schemas.3mf.io/3dmanufacturing/volumetric/2022/01"
REL_MODEL = "http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"
REL_TEXTURE = "http://schemas.microsoft.com/3dmanufacturing/2013/01/3dtexture"
MODEL = "3D/3dmodel.model"
CHANNELS = ("red", "green", "blue", "alpha")
OBJECT_NAME = "inkopt print, outline block"  # + " fx fy fz" (voxels per outline block)
CONTENT_TYPES = (
    '<?xml version="1.0" encoding="UTF-8"?>\n'
    '<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types">'
    '<Default Extension="rels" ContentType="application/vnd.openxmlformats-package.relationships+xml"/>'
    '<Default Extension="model" ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/>'
    '<Default Extension="png" ContentType="image/png"/></Types>\n'
)


def sheet_path(group: int, k: int) -> str:
    """The part name of sheet ``k`` of ink group ``group``."""
    return f"/3D/volumetric/inks{group}/sheet{k:05d}.png"


def _fill_empty(shares: np.ndarray, occ: np.ndarray) -> np.ndarray:
    """(Y, X, N) shares with every empty voxel given its nearest occupied voxel's shares (``occ`` has one)."""
    if occ.all():
        return shares
    from scipy.ndimage import distance_transform_edt

    _, (iy, ix) = distance_transform_edt(~occ, return_indices=True)
    return shares[iy, ix]


def _put(zf, k: int, pngs: list[bytes]) -> None:
    for g, data in enumerate(pngs):
        zf.writestr(sheet_path(g, k)[1:], data, compress_type=zipfile.ZIP_STORED)


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


def _fmt(v: float) -> str:
    return np.format_float_positional(float(v), precision=9, trim="-")


def _model_xml(fh, names, colours, shape, voxel_mm, mesh, block) -> None:
    """Write 3D/3dmodel.model to the open binary ``fh`` (module docstring)."""
    Z, Y, X = shape
    n, groups = len(names), -(-len(names) // 4)
    scale = [1 / (X * voxel_mm[0]), 1 / (Y * voxel_mm[1]), 1 / (Z * voxel_mm[2])]
    transform = " ".join(_fmt(v) for v in (scale[0], 0, 0, 0, scale[1], 0, 0, 0, scale[2], 0, 0, 0))
    w = fh.write
    w(
        f'<?xml version="1.0" encoding="UTF-8"?>\n<model xmlns="{NS_CORE}" xmlns:v="{NS_V}" unit="millimeter" '
        f'xml:lang="en-US" recommendedextensions="v">\n<resources>\n<basematerials id="1">\n'.encode()
    )
    for name, c in zip(names, colours, strict=True):
        w(f'<base name="{_xml(name)}" displaycolor="#{c[0]:02X}{c[1]:02X}{c[2]:02X}"/>\n'.encode())
    w(b"</basematerials>\n")
    for g in range(groups):
        w(f'<v:image3d id="{2 + 2 * g}" name="inks{g}">\n'.encode())
        w(f'<v:imagestack rowcount="{Y}" columncount="{X}" sheetcount="{Z}">\n'.encode())
        w("".join(f'<v:imagesheet path="{sheet_path(g, k)}"/>\n' for k in range(Z)).encode())
        w(b"</v:imagestack>\n</v:image3d>\n")
        w(
            f'<v:functionfromimage3d id="{3 + 2 * g}" image3did="{2 + 2 * g}" filter="nearest" '
            f'tilestyleu="clamp" tilestylev="clamp" tilestylew="clamp"/>\n'.encode()
        )
    vol, obj = 2 + 2 * groups, 3 + 2 * groups
    w(f'<v:volumedata id="{vol}">\n<v:composite basematerialid="1">\n'.encode())
    for i in range(n):
        w(
            f'<v:materialmapping functionid="{3 + 2 * (i // 4)}" channel="{CHANNELS[i % 4]}" '
            f'transform="{transform}"/>\n'.encode()
        )
    w(b"</v:composite>\n</v:volumedata>\n")
    name = f"{OBJECT_NAME} {' '.join(map(str, block))}"
    w(f'<object id="{obj}" type="model" name="{name}">\n<mesh v:volumeid="{vol}">\n<vertices>\n'.encode())
    verts = np.asarray(mesh.vertices, np.float64)
    for a in range(0, len(verts), 1 << 16):
        w("".join(f'<vertex x="{x:.6f}" y="{y:.6f}" z="{z:.6f}"/>\n' for x, y, z in verts[a : a + (1 << 16)]).encode())
    w(b"</vertices>\n<triangles>\n")
    faces = np.asarray(mesh.faces, np.int64)
    for a in range(0, len(faces), 1 << 16):
        w("".join(f'<triangle v1="{i}" v2="{j}" v3="{k}"/>\n' for i, j, k in faces[a : a + (1 << 16)]).encode())
    w(b"</triangles>\n</mesh>\n</object>\n</resources>\n")
    w(f'<build>\n<item objectid="{obj}"/>\n</build>\n</model>\n'.encode())


def _xml(text: str) -> str:
    return str(text).replace("&", "&amp;").replace('"', "&quot;").replace("<", "&lt;").replace(">", "&gt;")


def _rels(targets) -> bytes:
    body = "".join(f'<Relationship Type="{t}" Target="{p}" Id="rel{i}"/>' for i, (t, p) in enumerate(targets, start=1))
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n<Relationships '
        f'xmlns="http://schemas.openxmlformats.org/package/2006/relationships">{body}</Relationships>\n'
    ).encode()


def write_3mf(
    layers, occupied, shape, voxel_mm, ink_names, path, *, materials=None, palette=None, source=None, digest=None
) -> dict:
    """Write the volumetric 3MF ``path`` (layout: module docstring); returns a summary dict.

    layers      callable k -> (Y, X, N) float shares of layer k (each occupied voxel's sum 1; label-y order)
    occupied    callable k -> (Y, X) bool: the voxels of layer k that are printed
    shape       (Z, Y, X) grid; voxel_mm (x, y, z) voxel size in mm; ink_names N names
    materials   {ink: material name} for the ``<base>`` names; palette: {ink: colour} for their display colours
    source, digest  the file the shares come from and its ``io.file_digest`` (archive comment)
    An empty grid is refused before anything is written; an existing ``path`` is replaced only if it is a 3MF.
    """
    Z, Y, X = (int(v) for v in shape)
    vp = np.asarray(voxel_mm, np.float64).reshape(-1)
    names = [str(n) for n in ink_names]
    over = {str(k).lower(): str(v) for k, v in (materials or {}).items()}
    unknown = sorted(set(over) - {n.lower() for n in names})
    if unknown:
        raise ValueError(f"material names: unknown ink '{unknown[0]}'; give INK=NAME for the inks {names}")
    base_names = [over.get(n.lower(), n) for n in names]
    colours = ink_colours(names, palette)
    groups = -(-len(names) // 4)
    path = Path(path)
    check_package_target(path, MODEL, "3MF file", ".3mf")
    fz, fy, fx = outline_factors((Z, Y, X), vp)
    coarse = np.zeros((-(-Z // fz), -(-Y // fy), -(-X // fx)), bool)
    counts = np.zeros(len(names), np.float64)
    with atomic_file(path) as fh, zipfile.ZipFile(fh, "w") as zf:
        for k in range(Z):  # first pass: which outline blocks hold printed voxels
            coarse[k // fz] |= _block_any(np.asarray(occupied(k), bool), fy, fx)
        if not coarse.any():
            raise ValueError("nothing to print: every voxel is empty")
        mesh = block_outline(coarse, vp, (fz, fy, fx))
        region = coarse  # the blocks inside the outline (grown as block_outline grows them)
        if (fz, fy, fx) != (1, 1, 1):
            from scipy.ndimage import binary_dilation

            region = binary_dilation(coarse, np.ones((3, 3, 3), bool))
        pending, last = [], None
        for k in range(Z):
            occ = np.asarray(occupied(k), bool)
            inside = np.repeat(np.repeat(region[k // fz], fy, 0), fx, 1)[:Y, :X]
            if not occ.any():  # takes the nearest printed layer's shares below (or else above) it
                if last is None:
                    pending.append((k, inside))
                else:
                    _put(zf, k, _sheets(np.where(inside[..., None], last, 0.0), groups))
                continue
            sh = np.asarray(layers(k), np.float32)
            counts += sh[occ].sum(0)
            last = _fill_empty(sh, occ) if (fz, fy, fx) != (1, 1, 1) else np.where(occ[..., None], sh, 0.0)
            for j, ins in pending:
                _put(zf, j, _sheets(np.where(ins[..., None], last, 0.0), groups))
            pending = []
            _put(zf, k, _sheets(np.where(inside[..., None], last, 0.0), groups))
        with zf.open(MODEL, "w", force_zip64=True) as mf:
            _model_xml(mf, base_names, colours, (Z, Y, X), vp, mesh, (fx, fy, fz))
        rels = [(REL_TEXTURE, sheet_path(g, k)) for g in range(groups) for k in range(Z)]
        zf.writestr("3D/_rels/3dmodel.model.rels", _rels(rels), compress_type=zipfile.ZIP_DEFLATED)
        zf.writestr("_rels/.rels", _rels([(REL_MODEL, "/" + MODEL)]), compress_type=zipfile.ZIP_DEFLATED)
        zf.writestr("[Content_Types].xml", CONTENT_TYPES, compress_type=zipfile.ZIP_DEFLATED)
        zf.comment = source_comment(source, digest)
    return {
        "path": str(path),
        "layer_count": Z,
        "image_size": {"width": X, "height": Y},
        "voxel_mm": [float(v) for v in vp],
        "materials": [
            {"ink": names[i], "material": base_names[i], "color": list(colours[i]), "voxel_count": float(counts[i])}
            for i in range(len(names))
        ],
        "image_stacks": groups,
        "mesh_triangles": len(mesh.faces),
        "outline_block": [fx, fy, fz],
        "bytes": path.stat().st_size,
    }


def write_3mf_labels(labels, voxel_mm_printer, ink_names, path, *, printer=None, materials=None, **kw) -> dict:
    """The quantized print as a volumetric 3MF: one ink per printer voxel as 0/1 shares (``write_3mf``).

    labels uint8 (Z, Y, X) (255 = empty; may be memory-mapped), checked as ``export.check_job`` checks a job
    (``printer``'s material limit and names, ``materials`` overriding them)."""
    job = check_job(labels, voxel_mm_printer, ink_names, None, printer, materials)
    names = {n: job.material(i) for i, n in enumerate(job.names) if job.material(i)}
    n = len(job.names)
    eye = np.vstack([np.eye(n, dtype=np.float32), np.zeros((256 - n, n), np.float32)])

    def layer(k):
        return eye[np.asarray(job.labels[k])]

    def occupied(k):
        return np.asarray(job.labels[k]) != 255

    return write_3mf(layer, occupied, job.labels.shape, job.vp, job.names, path, materials=names, **kw)


def write_3mf_mixture(src, path, *, materials=None, **kw) -> dict:
    """The continuous mixture as a volumetric 3MF (``write_3mf``): ``src`` has ``shape`` (Z, Y, X, N), ``[k]``
    (Y, X, N) float shares, ``inside`` ((Z, Y, X) bool or None: every voxel), ``voxel_mm`` and ``inks.names``
    (a ``model.mixturefile.MixtureSource``: the run's volume.npz read one layer at a time)."""
    Z, Y, X, _ = src.shape
    inside = src.inside

    def occupied(k):
        return np.ones((Y, X), bool) if inside is None else inside[k]

    return write_3mf(
        lambda k: src[k], occupied, (Z, Y, X), src.voxel_mm, src.inks.names, path, materials=materials, **kw
    )
