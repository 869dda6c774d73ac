"""``inkopt export DIR``: printer input from DIR/quantized.npz (docs/run-dir.md).

``--format`` names one of ``inkopt.printing.formats.FORMATS``: ``png-slices`` (default), one RGBA PNG per layer plus
manifest.json; ``gcvf``, the GrabCAD Voxel Print package, one zip; ``3mf``, a 3MF with the Volumetric extension of
the continuous mixture (DIR/volume.npz, read one layer at a time), or with ``--labels`` of the quantized print. A
job using more inks than ``--printer`` holds is refused in one line before anything is written. GCVF and 3MF
record the digest of the file they are made from (quantized.npz, or volume.npz for the continuous 3MF) in their
zip comment (``inkopt inspect --run`` checks it). A quantized volume made from another volume.npz than the run's
(``RunDir.check_quantized_current``) is refused in one line before anything is written; the slice manifest
records ``volume_digest`` and ``quantized_digest``. An existing output is replaced only if it is a package of the
same format (``io.check_output``); writing into the run folder holds its lock (``RunDir.lock``).
"""

from __future__ import annotations

import json
import sys
from functools import partial
from pathlib import Path

from ..errors import ParameterError
from ..io import file_digest
from ..model.mixturefile import MixtureSource
from ..printing.formats import FORMATS, Format, format_named
from ..printing.formats.job import LabelVoxels, MixtureVoxels, PrintJob, Provenance
from ..printing.profiles import PRINTER_PROFILES, printer_profile, resolution_mismatch
from ..rundir import RunDir
from .common import stderr_log


def parse_materials(items) -> dict | None:
    """``--material INK=NAME`` (repeatable) -> {ink: material name}."""
    if not items:
        return None
    out = {}
    for item in items:
        ink, sep, name = str(item).partition("=")
        if not sep or not ink.strip() or not name.strip():
            raise ParameterError(f"`material` takes INK=NAME (e.g. white=VeroPureWht), got '{item}'")
        out[ink.strip()] = name.strip()
    return out


def load_palette(text: str | None) -> dict | None:
    """A JSON object {ink name: "#rrggbb" | [r, g, b]} given inline or as a path to a .json file."""
    if text is None:
        return None
    path = Path(text)
    try:
        raw = path.read_text() if path.is_file() else text
        pal = json.loads(raw)
    except (OSError, ValueError) as exc:
        raise ParameterError(f"`palette` is neither a JSON object nor a readable JSON file ({exc})") from None
    if not isinstance(pal, dict):
        raise ParameterError("`palette` must be a JSON object {ink name: colour}")
    return pal


def _write_mixture(fmt: Format, d: RunDir, out: Path, make_job) -> dict:
    """The run's continuous mixture (volume.npz, read one layer at a time) in ``fmt``; ``make_job(voxels,
    provenance=...)`` gives the ``PrintJob``."""
    with MixtureSource(d.volume_file()) as src:
        job = make_job(MixtureVoxels(src), provenance=Provenance(d.volume_path.name, file_digest(d.volume_path)))
        return fmt.write(job, out)


def _write_labels(fmt: Format, d: RunDir, out: Path, make_job) -> dict:
    """The run's quantized print (quantized.npz, checked to be current) in ``fmt``; warns when its grid is not
    what the job's printer prints."""
    q = d.quantized_layers()
    d.check_quantized_current()
    provenance = Provenance(d.quantized_path.name, file_digest(d.quantized_path), d.volume_digest())
    job = make_job(LabelVoxels(q.labels, q.voxel_mm, q.inks.names), provenance=provenance)
    summary = fmt.write(job, out)
    if mismatch := resolution_mismatch(job.printer, q.voxel_mm):
        print(f"inkopt: warning: {mismatch}", file=sys.stderr)
    return summary


def _export_cmd(args) -> int:
    fmt = format_named(args.format)
    if args.labels and not fmt.takes_mixture:
        mixtures = " or ".join(f.name for f in FORMATS.values() if f.takes_mixture)
        raise ParameterError(f"`labels` goes with `format` {mixtures} (the other formats always hold the labels)")
    make_job = partial(
        PrintJob,
        printer=printer_profile(args.printer or fmt.default_printer),
        palette=load_palette(args.palette),
        materials=parse_materials(args.material) or {},
    )
    d = RunDir(args.dir)
    mixture = fmt.takes_mixture and not args.labels
    out = Path(args.out) if args.out else fmt.run_output(d, mixture)
    with d.lock_for(out, stderr_log):  # an output in the run folder: one job at a time writes there
        summary = (_write_mixture if mixture else _write_labels)(fmt, d, out, make_job)
    print(fmt.describe(summary))
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
