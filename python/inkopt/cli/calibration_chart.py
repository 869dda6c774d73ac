"""``inkopt calibration-chart --inks LIST --out DIR``: design a calibration chart for an ink set and write it as
CGATS.17 (DIR/chart.txt, measurement columns empty), as a printable job (DIR/job/, for ``inkopt quantize`` and
``export``) and as a picture (DIR/layout.png) (``inkopt.calibration``, docs/calibration.md)."""

from __future__ import annotations

from ..calibration.chart import design_chart
from ..calibration.job import write_chart
from ..printing.profiles import check_slots, printer_profile
from .common import add_inks_arg, rgb_inks


def _chart_cmd(args) -> int:
    inks = rgb_inks(args.inks, "calibration-chart")
    if args.printer is not None:
        prof = printer_profile(args.printer)
        check_slots(list(inks.names), prof.max_materials, prof.key)
    chart = design_chart(inks.names)
    header = {"ORIGINATOR": "inkopt calibration-chart", "DESCRIPTOR": f"calibration chart for {args.inks}"}
    if args.printer is not None:
        header["PRINTER"] = prof.key
    paths = write_chart(args.out, chart, inks, float(args.patch_mm), header)
    print(f"{len(chart)} patches of {', '.join(inks.names)}")
    print(f"wrote {paths['chart']} (fill in LAB_L LAB_A LAB_B, or spectral columns: a spectral fit), {paths['layout']}")
    job = paths["job"].parent
    print(
        f"print it: inkopt quantize {job} && inkopt export {job}" + (f" --printer {prof.key}" if args.printer else "")
    )
    return 0


def register_cli(sub) -> None:
    p = sub.add_parser(
        "calibration-chart",
        help="design a chart of patches for fitting the ink table to your printer (docs/calibration.md)",
        description="Write DIR/chart.txt (CGATS.17, measurement columns empty), DIR/job/ (printable with "
        "inkopt quantize and export) and DIR/layout.png (each patch's SAMPLE_ID where it is printed).",
    )
    add_inks_arg(p, required=True)
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--printer", help="printer profile: refuse an ink set it cannot hold")
    p.add_argument("--patch-mm", type=float, default=10.0, help="patch edge in mm (default 10)")
    p.set_defaults(func=_chart_cmd)
