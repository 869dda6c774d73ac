"""``inkopt export DIR``: printer input from DIR/quantized.npz (docs/run-dir.md).

``--format png-slices`` (the only format): one RGBA PNG per layer plus manifest.json (``inkopt.export``).
``--format 3mf`` is refused: lib3mf 2.5.0 cannot write volumetric composites (see ``inkopt.export``).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from .cli_quantize import run_dir
from .export import PRINTER_PROFILES, write_png_slices
from .volume import Volume

FORMATS = ("png-slices", "3mf")
NO_3MF = ("3mf export is not available: lib3mf 2.5.0 cannot write volumetric composites "
          "(VolumeDataComposite is not implemented); use --format png-slices")


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


def load_quantized(d: Path) -> Volume:
    path = d / "quantized.npz"
    if not path.is_file():
        raise ValueError(f"{path} does not exist (run 'inkopt quantize {d}' first)")
    vol = Volume.load(path)
    if vol.form != "labels":
        raise ValueError(f"{path} holds a {vol.form} volume, not printer labels")
    return vol


def _export_cmd(args) -> int:
    if args.format not in FORMATS:
        raise ValueError(f"unknown export format '{args.format}'; use one of {list(FORMATS)}")
    if args.format == "3mf":
        raise ValueError(NO_3MF)
    printer = str(args.printer).strip().lower()
    if printer not in PRINTER_PROFILES:
        raise ValueError(f"unknown printer '{args.printer}'; use one of {list(PRINTER_PROFILES)}")
    palette = load_palette(args.palette)
    d = run_dir(args.dir)
    q = load_quantized(d)
    out = Path(args.out) if args.out else d / "slices"
    man = write_png_slices(q.labels, q.voxel_mm, q.inks.names, out, palette=palette, max_materials=printer)
    prof = PRINTER_PROFILES[printer]
    if "dpi" in prof:
        vp = q.voxel_mm
        dpi = 25.4 / vp[:2]
        if not np.allclose(dpi, prof["dpi"], rtol=1e-3) or not any(
                abs(vp[2] * 1000 - t) < 0.05 for t in prof.get("layer_um", (vp[2] * 1000,))):
            print(f"inkopt: warning: the slices are {dpi[0]:.0f} x {dpi[1]:.0f} DPI with {vp[2] * 1000:.1f} um "
                  f"layers; {prof['name']} prints {prof['dpi'][0]} x {prof['dpi'][1]} DPI with "
                  f"{' or '.join(f'{t:g}' for t in prof['layer_um'])} um layers", file=sys.stderr)
    used = ", ".join(f"{m['ink']} {m['hex']}" for m in man["materials"] if m["voxel_count"] > 0)
    print(f"{man['layer_count']} slices of {man['image_size']['width']} x {man['image_size']['height']} px "
          f"({man['dpi']['x']:.0f} x {man['dpi']['y']:.0f} DPI, {man['layer_thickness_um']:.1f} um layers), "
          f"{man['materials_used']} materials: {used}")
    print(f"wrote {out}")
    return 0


def register_cli(sub) -> None:
    p = sub.add_parser("export", help="printer input from DIR/quantized.npz (PNG slice stack)",
                       description="Write printer input from a run's quantized volume: one RGBA PNG per layer "
                                   "(one colour per material) plus manifest.json.")
    p.add_argument("dir", help="run directory holding quantized.npz")
    p.add_argument("--format", default="png-slices", help="png-slices (default); 3mf is not available")
    p.add_argument("--out", help="output folder (default DIR/slices)")
    p.add_argument("--printer", default="generic",
                   help=f"printer profile limiting the materials per job: {', '.join(PRINTER_PROFILES)} "
                        "(default generic = no limit)")
    p.add_argument("--palette", help='ink colours as JSON, inline or a file: {"cyan": "#00FFFF", ...}')
    p.set_defaults(func=_export_cmd)
