"""The XML parts of the volumetric 3MF that ``threemf.py`` writes (its layout: that module's docstring): the model
(base materials, image stacks, the composite's mappings, the outline mesh), the OPC relationships and content types.
"""

from __future__ import annotations

import zipfile

import numpy as np

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


def _fmt(v: float) -> str:
    return np.format_float_positional(float(v), precision=9, trim="-")


def _xml(text: str) -> str:
    return str(text).replace("&", "&amp;").replace('"', "&quot;").replace("<", "&lt;").replace(">", "&gt;")


def _resources_xml(w, names, colours, shape, voxel_mm) -> tuple[int, int]:
    """The base materials, image stacks, functions and volume data; returns the (volume, object) ids."""
    Z, Y, X = shape
    groups = -(-len(names) // 4)
    scale = [1 / (X * voxel_mm[0]), 1 / (Y * voxel_mm[1]), 1 / (Z * voxel_mm[2])]
    transform = " ".join(_fmt(v) for v in (scale[0], 0, 0, 0, scale[1], 0, 0, 0, scale[2], 0, 0, 0))
    w(b'<basematerials id="1">\n')
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
    vol = 2 + 2 * groups
    w(f'<v:volumedata id="{vol}">\n<v:composite basematerialid="1">\n'.encode())
    for i in range(len(names)):
        w(
            f'<v:materialmapping functionid="{3 + 2 * (i // 4)}" channel="{CHANNELS[i % 4]}" '
            f'transform="{transform}"/>\n'.encode()
        )
    w(b"</v:composite>\n</v:volumedata>\n")
    return vol, vol + 1


def model_xml(fh, names, colours, shape, voxel_mm, mesh, block) -> None:
    """Write 3D/3dmodel.model to the open binary ``fh`` (module docstring)."""
    w = fh.write
    w(
        f'<?xml version="1.0" encoding="UTF-8"?>\n<model xmlns="{NS_CORE}" xmlns:v="{NS_V}" unit="millimeter" '
        f'xml:lang="en-US" recommendedextensions="v">\n<resources>\n'.encode()
    )
    vol, obj = _resources_xml(w, names, colours, shape, voxel_mm)
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


def _rels(targets) -> bytes:
    body = "".join(f'<Relationship Type="{t}" Target="{p}" Id="rel{i}"/>' for i, (t, p) in enumerate(targets, start=1))
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n<Relationships '
        f'xmlns="http://schemas.openxmlformats.org/package/2006/relationships">{body}</Relationships>\n'
    ).encode()


def write_opc(zf, groups: int, Z: int) -> None:
    """The OPC parts: the model's relationships (one per sheet), the package's and the content types."""
    rels = [(REL_TEXTURE, sheet_path(g, k)) for g in range(groups) for k in range(Z)]
    zf.writestr("3D/_rels/3dmodel.model.rels", _rels(rels), compress_type=zipfile.ZIP_DEFLATED)
    zf.writestr("_rels/.rels", _rels([(REL_MODEL, "/" + MODEL)]), compress_type=zipfile.ZIP_DEFLATED)
    zf.writestr("[Content_Types].xml", CONTENT_TYPES, compress_type=zipfile.ZIP_DEFLATED)
