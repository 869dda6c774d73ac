"""``inkopt inspect PACKAGE``: a .gcvf, a PNG-slice folder or a .3mf read back and checked
(``inkopt.printing.formats``): layers, slice size, DPI and layer thickness, materials with voxel counts and the
bounding box, or one line naming the first disagreement between its parts (exit 2). ``--run DIR`` also refuses
a package whose recorded source digest is not that of the run's current file; ``--preview OUT.png`` draws the
top view and a few slices; ``--json`` prints the report as JSON.
"""

from __future__ import annotations

import json
from pathlib import Path

from ..io import file_digest
from ..printing.formats import inspect_package
from ..printing.formats.inspection import PackageError, preview
from ..printing.formats.slices import rgba
from ..rundir import RunDir

PREVIEW_SLICES = 4


def _colour(c) -> tuple[int, int, int]:
    """A material's preview colour: its RGBA numbers or "#RRGGBB" (a 3MF's display colour), grey if it is
    neither (a display colour is not checked: no part depends on it)."""
    try:
        return rgba(c, "colour")[:3]
    except (ValueError, TypeError):
        return (128, 128, 128)


def _check_run(report, run: str) -> None:
    d = RunDir(run)
    src = report.source
    if src is None:
        raise PackageError(f"{report.path} records no source file; it cannot be checked against {run}")
    sources = {d.quantized_path.name: d.quantized_path, d.volume_path.name: d.volume_path}
    current = sources.get(Path(str(src["source"])).name)
    if current is None or not current.is_file():
        raise PackageError(f"{report.path} was made from {src['source']}, which {run} does not hold")
    if file_digest(current) != src["digest"]:
        raise PackageError(f"{report.path} is stale: {current} changed since it was written; export it again")
    if current == d.quantized_path:
        d.check_quantized_current()  # the quantized print itself must still be the run's current result


def _inspect_cmd(args) -> int:
    report, scan = inspect_package(args.package, keep_layers=PREVIEW_SLICES if args.preview else ())
    if args.run:
        _check_run(report, args.run)
    if args.preview:
        preview(report, scan, [_colour(m["color"]) for m in report.materials], args.preview)
    if args.json:
        print(json.dumps(report.to_json(), indent=1))
        return 0
    b = report.bounding_box
    dpi = f"{report.dpi[0]:.0f} x {report.dpi[1]:.0f} DPI, " if report.dpi else ""
    print(
        f"{report.kind} {report.path}: {report.layers} layers of {report.width} x {report.height} px "
        f"({dpi}{report.layer_um:.1f} um layers)"
    )
    for m in report.materials:
        print(f"  {m['name']}: {m['voxel_count']:.0f} voxels")
    print(f"bounding box (column, row, layer): {b[:3]} .. {b[3:]} (max exclusive); the parts agree")
    if report.source:
        print(f"made from {report.source['source']} {report.source['digest']}")
    if args.preview:
        print(f"wrote {args.preview}")
    return 0


def register_cli(sub) -> None:
    p = sub.add_parser(
        "inspect",
        help="read a printer package back (.gcvf, slice folder, .3mf) and check that its parts agree",
        description="Read a GCVF package, a PNG-slice folder or a volumetric 3MF back and check that its parts "
        "agree; one line naming the first disagreement (exit 2) otherwise.",
    )
    p.add_argument("package", help="a .gcvf, a slice folder (with manifest.json) or a .3mf")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument("--preview", metavar="OUT.png", help="draw the top view and a few slices")
    p.add_argument("--run", metavar="DIR", help="refuse the package if it was not made from DIR's current files")
    p.set_defaults(func=_inspect_cmd)
