"""``inkopt report RUN``: the soft-proof page of a run (``inkopt.proof``). An existing file at the output is replaced
only if it is an earlier page (``proof.proof_target``); writing into the run folder holds its lock."""

from __future__ import annotations

from .common import stderr_log


def _report(args) -> int:
    from ..proof import write_proof
    from ..rundir import RunDir

    with RunDir(args.run).lock_for(args.out, stderr_log):
        p = write_proof(args.run, args.out)
    note = " (textures downsampled)" if p.downsampled else ""
    print(f"wrote {p.path}: {p.bytes / 1e6:.1f} MB, {', '.join(p.results)}{note}, in {p.seconds:.1f} s")
    return 0


def register_cli(sub) -> None:
    p = sub.add_parser(
        "report",
        help="write RUN/report.html: a self-contained soft-proof page with a 3D view (meshes) or the faces (slabs)",
    )
    p.add_argument("run", help="run directory")
    p.add_argument("--out", help="output file (default RUN/report.html)")
    p.set_defaults(func=_report)
