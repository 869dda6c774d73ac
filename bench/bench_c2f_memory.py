"""Peak memory of a coarse-to-fine mesh job cut to one iteration per stage: ``inkopt optimize MESH --height-mm H
--coarse-dpi 150 --iterations 1 --eval-spp 4`` in this process (``coarse.run_coarse_to_fine``: the coarse run, the
transfer, the fine run with its estimate, start figures, one iteration, checkpoint, volume, final figures and
pictures), so that its memory is the job's without the job's hours.

    python bench/bench_c2f_memory.py [HEIGHT_MM=40] [--mesh spot.obj] [--dir DIR] [--name NAME] [-- OPTIONS ...]

Peaks (the process's resident-set high-water mark, getrusage) as the runs record them: the coarse run's report
(``coarse/report.json``), the fine run's estimate (set-up, renderer and the estimate's calibration) and the fine
run's report (everything but writing report.json). ``OPTIONS`` after ``--`` replace the default
``--coarse-dpi 150 --iterations 1 --eval-spp 4`` (e.g. ``--init START.npz --iterations 1 --eval-spp 4``: the fine
stage alone, in a process of its own). Writes the entry NAME (default ``spot<H>``) of
bench/results/c2f_memory.json; run it alone on the machine (both cores, several minutes at 40 mm).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "bench"))

SPOT = ROOT.parent / "shared" / "data" / "spot" / "spot.obj"  # ../shared beside the repository
RESULTS_FILE = "c2f_memory.json"
DEFAULT_OPTIONS = ["--coarse-dpi", "150", "--iterations", "1", "--eval-spp", "4"]


def main(argv=None) -> dict:
    from common import RESULTS, machine, provenance, write

    from inkopt.cli import main as inkopt_main

    argv = sys.argv[1:] if argv is None else list(argv)
    extra = argv[argv.index("--") + 1 :] if "--" in argv else DEFAULT_OPTIONS
    argv = argv[: argv.index("--")] if "--" in argv else argv
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("height_mm", type=float, nargs="?", default=40.0)
    ap.add_argument("--mesh", default=str(SPOT))
    ap.add_argument("--dir", help="run directory (default: a temporary one, removed after)")
    ap.add_argument("--name")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(a.dir or Path(tmp) / "run")
        t = time.perf_counter()
        code = inkopt_main(["optimize", a.mesh, "--height-mm", f"{a.height_mm:g}", "--out", str(out), *extra])
        seconds = time.perf_counter() - t
        if code:
            raise SystemExit(f"inkopt optimize failed with exit status {code}")
        coarse_report = out / "coarse" / "report.json"  # none without --coarse-dpi (a one-stage run)
        coarse = json.loads(coarse_report.read_text()) if coarse_report.is_file() else {}
        fine = json.loads((out / "report.json").read_text())
    result = {
        "height_mm": a.height_mm,
        "mesh": Path(a.mesh).name,
        "optimize_options": extra,
        "peak_rss_gb_by_stage": {
            "coarse_run": coarse.get("peak_rss_gb"),
            "fine_estimate": fine["estimate"]["peak_gib"],
            "fine_run": fine["peak_rss_gb"],
        },
        "fine_free_voxels": fine["free_voxels"],
        "seconds": seconds,
        "machine": machine(),
        "note": "peaks: the process's resident-set high-water mark when the coarse report, the fine run's "
        "estimate (which adds 64 B per texel to it) and the fine report were made; wall time on a shared machine",
    }
    path = RESULTS / RESULTS_FILE
    data = json.loads(path.read_text()) if path.is_file() else {}
    data.setdefault("results", {})[a.name or f"spot{a.height_mm:g}"] = {**result, **provenance()}
    write(RESULTS_FILE, data)
    print(json.dumps(result["peak_rss_gb_by_stage"]))
    return result


if __name__ == "__main__":
    main()
