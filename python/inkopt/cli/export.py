"""``inkopt export DIR``: printer input from DIR/quantized.npz (docs/run-dir.md).

``--format png-slices`` (default): one RGBA PNG per layer plus manifest.json (``inkopt.printing.export``);
``--format gcvf``: the GrabCAD Voxel Print package, one zip (``inkopt.printing.gcvf``); ``--format 3mf``: a 3MF
with the Volumetric extension (``inkopt.printing.threemf``) of the continuous mixture (DIR/volume.npz, read one
layer at a time), or with ``--labels`` of the quantized print. A job using more inks than ``--printer`` holds is
refused in one line before anything is written. GCVF and 3MF record the digest of the file they are made from
(quantized.npz, or volume.npz for the continuous 3MF) in their zip comment (``inkopt inspect --run`` checks it).
A quantized volume made from another volume.npz than the run's (``RunDir.check_quantized_current``) is refused
in one line before anything is written; the slice manifest records ``volume_digest`` and ``quantized_digest``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..io import file_digest
from ..model.mixturefile import MixtureSource
from ..printing.export import write_png_slices
from ..printing.gcvf import write_gcvf
from ..printing.profiles import PRINTER_PROFILES, printer_profile, resolution_mismatch, too_many_inks
from ..printing.threemf import write_3mf_labels, write_3mf_mixture
from ..rundir import QUANTIZED_DIGEST, VOLUME_DIGEST, RunDir

FORMATS = ("png-slices", "gcvf", "3mf")
DEFAULT_PRINTER = {"png-slices": "generic", "gcvf": "j750", "3mf": "generic"}


def parse_materials(items) -> dict | None:
    """``--material INK=NAME`` (repeatable) -> {ink: material name}."""
    if not items:
        return None
    out = {}
    for item in items:
        ink, sep, name = str(item).partition("=")
        if not sep or not ink.strip() or not name.strip():
            raise ValueError(f"--material takes INK=NAME (e.g. white=VeroPureWht), got '{item}'")
        out[ink.strip()] = name.strip()
    return out


def _export_3mf(args, d: RunDir, printer: str, palette, materials) -> int:
    if args.labels:
        out = Path(args.out) if args.out else d.threemf_path(labels=True)
        q = d.load_quantized()
        d.check_quantized_current()
        digest = file_digest(d.quantized_path)
        man = write_3mf_labels(
            q.labels, q.voxel_mm, q.inks.names, out, printer=printer, materials=materials, palette=palette,
            source=d.quantized_path.name, digest=digest,
        )  # fmt: skip
        if mismatch := resolution_mismatch(printer_profile(printer), q.voxel_mm):
            print(f"inkopt: warning: {mismatch}", file=sys.stderr)
    else:
        out = Path(args.out) if args.out else d.threemf_path()
        src = MixtureSource(d.volume_file())
        try:
            # every ink of the table may take a share anywhere in a continuous mixture: the job loads them all
            prof = printer_profile(printer)
            if refusal := too_many_inks(list(src.inks.names), prof.max_materials, prof.name):
                raise ValueError(refusal)
            names = {n: printer_profile(printer).material(n) for n in src.inks.names}
            names = {k: v for k, v in names.items() if v} | (materials or {})
            digest = file_digest(d.volume_path)
            man = write_3mf_mixture(
                src, out, materials=names, palette=palette, source=d.volume_path.name, digest=digest
            )
        finally:
            src.close()
    used = ", ".join(f"{m['ink']} = {m['material']}" for m in man["materials"] if m["voxel_count"] > 0)
    print(
        f"{man['layer_count']} sheets of {man['image_size']['width']} x {man['image_size']['height']} voxels "
        f"({' x '.join(f'{v * 1000:.1f}' for v in man['voxel_mm'])} um), {man['image_stacks']} image stacks, "
        f"{man['mesh_triangles']} outline triangles; {'labels' if args.labels else 'mixture'} of {used}"
    )
    print(f"wrote {out}")
    return 0


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
    if args.labels and args.format != "3mf":
        raise ValueError("--labels goes with --format 3mf (slices and GCVF packages always hold the labels)")
    printer = str(args.printer or DEFAULT_PRINTER[args.format]).strip().lower()
    prof = printer_profile(printer)
    palette = load_palette(args.palette)
    materials = parse_materials(args.material)
    d = RunDir(args.dir)
    if args.format == "3mf":
        return _export_3mf(args, d, printer, palette, materials)
    q = d.load_quantized()
    d.check_quantized_current()
    if args.format == "gcvf":
        out = Path(args.out) if args.out else d.gcvf_path
        man = write_gcvf(
            q.labels, q.voxel_mm, q.inks.names, out, printer=printer, palette=palette, materials=materials,
            source=d.quantized_path.name, digest=file_digest(d.quantized_path),
        )  # fmt: skip
        layers_um = man["layer_thickness_nm"] / 1000
    else:
        out = Path(args.out) if args.out else d.slices_path
        sources = {VOLUME_DIGEST: d.volume_digest(), QUANTIZED_DIGEST: d.quantized_digest()}
        man = write_png_slices(
            q.labels,
            q.voxel_mm,
            q.inks.names,
            out,
            palette=palette,
            printer=printer,
            materials=materials,
            sources=sources,
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
        help="printer input: PNG slices, a GCVF package or a volumetric 3MF",
        description="Write printer input from a run's quantized volume: one RGBA PNG per layer "
        "(one colour per material) plus manifest.json, or a GrabCAD Voxel Print "
        "package (.gcvf); or a 3MF (Volumetric extension) of the continuous mixture or, with --labels, the "
        "quantized print.",
    )
    p.add_argument("dir", help="run directory holding quantized.npz")
    p.add_argument(
        "--format",
        default="png-slices",
        help="png-slices (default), gcvf (GrabCAD Voxel Print zip) or 3mf (3MF Volumetric: DIR/mixture.3mf)",
    )
    p.add_argument("--labels", action="store_true", help="3mf: the quantized print (DIR/quantized.3mf)")
    p.add_argument(
        "--out",
        help="output folder (default DIR/slices) or file (default DIR/slices.gcvf, DIR/mixture.3mf, with --labels "
        "DIR/quantized.3mf)",
    )
    p.add_argument(
        "--material",
        action="append",
        metavar="INK=NAME",
        help="the printer's material name for an ink, overriding the profile's (repeatable), e.g. white=VeroPureWht",
    )
    p.add_argument(
        "--printer",
        default=None,
        help=f"printer profile: material slots per job and material names: {', '.join(PRINTER_PROFILES)} "
        "(default generic = no limit; j750 for gcvf)",
    )
    p.add_argument("--palette", help='ink colours as JSON, inline or a file: {"cyan": "#00FFFF", ...}')
    p.set_defaults(func=_export_cmd)
