"""``inkopt report RUN``: the soft-proof page of a run (``inkopt.proof``). An existing file at the output is replaced
only if it is an earlier page (``proof.proof_target``); writing into the run folder holds its lock."""

from __future__ import annotations

from ..proof.budget import DEFAULT_MAX_MB
from .common import stderr_log


def _report(args) -> int:
    from ..proof import ProofOptions, write_proof
    from ..rundir import RunDir

    options = ProofOptions(max_mb=args.max_mb)
    with RunDir(args.run).lock_for(args.out, stderr_log):
        p = write_proof(args.run, args.out, options)
    print(f"wrote {p.path}: {p.bytes / 1e6:.1f} MB, {', '.join(p.results)}{_pictures(p)}, in {p.seconds:.1f} s")
    return 0


def _pictures(p) -> str:
    """What the line says of the pictures: downsampled, and how the size budget reduced them."""
    if not p.reduced:
        return " (textures downsampled)" if p.downsampled else ""
    if p.atlas:
        how = f"{p.atlas}² atlas, {p.pixels_per_texel:.2f} pixels per texel, JPEG quality {p.quality}"
    else:
        how = f"faces: one texel of every {p.step} along each side"
    return f" (pictures reduced to stay within --max-mb {p.max_mb:g}: {how}{', downsampled' if p.downsampled else ''})"


def register_cli(sub) -> None:
    p = sub.add_parser(
        "report",
        help="write RUN/report.html: a self-contained soft-proof page with a 3D view (meshes) or the faces (slabs)",
    )
    p.add_argument("run", help="run directory")
    p.add_argument("--out", help="output file (default RUN/report.html)")
    p.add_argument(
        "--max-mb",
        type=float,
        default=DEFAULT_MAX_MB,
        metavar="MB",
        help=f"the page's size budget in MB (10^6 bytes; default {DEFAULT_MAX_MB:g}): larger pages get smaller "
        "pictures (fewer pixels per texel, lower JPEG quality), never fewer results or lights",
    )
    p.set_defaults(func=_report)
