"""``inkopt export DIR``: printer input from DIR/quantized.npz (docs/run-dir.md).

``--format png-slices`` (default): one RGBA PNG per layer plus manifest.json (``inkopt.printing.export``);
``--format gcvf``: the GrabCAD Voxel Print package, one zip (``inkopt.printing.gcvf``). A job using more inks
than ``--printer`` holds, or a quantized volume made from another volume.npz than the run's
(``RunDir.check_quantized_current``), is refused in one line before anything is written. The slice manifest records
``volume_digest`` and ``quantized_digest``, the files the slices were made from.
``--format 3mf`` is refused: lib3mf 2.5.0 cannot write volumetric composites (see ``inkopt.printing.export``).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..printing.export import write_png_slices
from ..printing.gcvf import write_gcvf
from ..printing.profiles import PRINTER_PROFILES, printer_profile, resolution_mismatch
from ..rundir import QUANTIZED_DIGEST, VOLUME_DIGEST, RunDir

FORMATS = ("png-slices", "gcvf", "3mf")
NO_3MF = (
    "3mf export is not available: lib3mf 2.5.0 cannot write volumetric composites "
    "(VolumeDataComposite is not implemented); use --format png-slices or gcvf"
)
DEFAULT_PRINTER = {"png-slices": "generic", "gcvf": "j750"}


def load_palette(text: str | None) -> dict | None:
    """A JSON object {ink name: "#rrggbb" | [r, g, b]} given inline or as a path to a .json file."""
    if text is None:
        return None
    path = Path(text)
    try:
        raw = path.read_text() if path.is_file() else text
        pal = json.loads(raw)
    except (OSError, ValueError) as exc:
        raise ValueError(f"--palette is neither a JSON object nor a readable JSON file ({exc})") from None
    if not isinstance(pal, dict):
        raise ValueError("--palette must be a JSON object {ink name: colour}")
    return pal


def _export_cmd(args) -> int:
    if args.format not in FORMATS:
        raise ValueError(f"unknown export format '{args.format}'; use one of {list(FORMATS)}")
    if args.format == "3mf":
        raise ValueError(NO_3MF)
    printer = str(args.printer or DEFAULT_PRINTER[args.format]).strip().lower()
    prof = printer_profile(printer)
    palette = load_palette(args.palette)
    d = RunDir(args.dir)
    q = d.load_quantized()
    d.check_quantized_current()
    if args.format == "gcvf":
        out = Path(args.out) if args.out else d.gcvf_path
        man = write_gcvf(q.labels, q.voxel_mm, q.inks.names, out, printer=printer, palette=palette)
        layers_um = man["layer_thickness_nm"] / 1000
    else:
        out = Path(args.out) if args.out else d.slices_path
        sources = {VOLUME_DIGEST: d.volume_digest(), QUANTIZED_DIGEST: d.quantized_digest()}
        man = write_png_slices(
            q.labels, q.voxel_mm, q.inks.names, out, palette=palette, printer=printer, sources=sources
        )
        layers_um = man["layer_thickness_um"]
    mats = [m for m in man["materials"] if m["voxel_count"] > 0]
    mismatch = resolution_mismatch(prof, q.voxel_mm)
    if mismatch:
        print(f"inkopt: warning: {mismatch}", file=sys.stderr)
    used = ", ".join(
        f"{m['ink']} {'#{:02X}{:02X}{:02X}'.format(*m['color'][:3])}" + (f" = {m['material']}" if m["material"] else "")
        for m in mats
    )
    print(
        f"{man['layer_count']} slices of {man['image_size']['width']} x {man['image_size']['height']} px "
        f"({man['dpi']['x']:.0f} x {man['dpi']['y']:.0f} DPI, {layers_um:.1f} um layers), "
        f"{len(mats)} materials: {used}"
    )
    print(f"wrote {out}")
    return 0


def register_cli(sub) -> None:
    p = sub.add_parser(
        "export",
        help="printer input from DIR/quantized.npz (PNG slices or a GCVF package)",
        description="Write printer input from a run's quantized volume: one RGBA PNG per layer "
        "(one colour per material) plus manifest.json, or a GrabCAD Voxel Print "
        "package (.gcvf).",
    )
    p.add_argument("dir", help="run directory holding quantized.npz")
    p.add_argument(
        "--format",
        default="png-slices",
        help="png-slices (default) or gcvf (GrabCAD Voxel Print zip); 3mf is not available",
    )
    p.add_argument("--out", help="output folder (default DIR/slices) or .gcvf file (default DIR/slices.gcvf)")
    p.add_argument(
        "--printer",
        default=None,
        help=f"printer profile: material slots per job and material names: {', '.join(PRINTER_PROFILES)} "
        "(default generic = no limit; j750 for gcvf)",
    )
    p.add_argument("--palette", help='ink colours as JSON, inline or a file: {"cyan": "#00FFFF", ...}')
    p.set_defaults(func=_export_cmd)
