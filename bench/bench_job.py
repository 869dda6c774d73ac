"""The whole job as a lab runs it: ``inkopt optimize MESH --height-mm H --out RUN`` with the defaults (and any extra
options), then ``inkopt quantize RUN`` and ``inkopt export RUN --format gcvf``, each its own process; prints and
records each stage's wall time and peak memory (``os.wait4``'s rusage of that process) and the job's total.

    .venv/bin/python bench/bench_job.py [HEIGHT_MM=40] [--mesh spot.obj] [--dir bench-out/job40] [--name NAME]
        [-- OPTIMIZE OPTIONS ...]

Options after ``--`` go to ``inkopt optimize`` (e.g. ``-- --time-budget 25m``). The job's quality is the run's own
report (report.json: the result's noise-corrected ΔE76, ΔE2000, SSIM and why the run stopped) and, with
``--check-spp N``, the result rendered again after the job at N samples per texel (``result_check``: a short
budget leaves the run's own figures few samples); the printed result against the baselines is ``inkopt evaluate
RUN`` (not part of the job). ``--check-only``: the job is done (its entry and run directory exist): add the
check. Writes the entry NAME (default ``spot{H}``) of bench/results/job.json with the load average before and
after: the wall times are the machine's as it was.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from common import RESULTS, SPOT, machine, provenance, write

RESULTS_FILE = "job.json"


def stage(args: list[str], log: Path) -> dict:
    """Run ``python -m inkopt.cli ARGS`` (stdout and stderr to ``log``): wall seconds, peak RSS (GiB)."""
    t = time.perf_counter()
    with open(log, "ab") as f:
        f.write(f"$ inkopt {' '.join(args)}\n".encode())
        f.flush()
        proc = subprocess.Popen([sys.executable, "-m", "inkopt.cli", *args], stdout=f, stderr=f)
        _, status, usage = os.wait4(proc.pid, 0)
    seconds = time.perf_counter() - t
    code = os.waitstatus_to_exitcode(status)
    if code:
        raise SystemExit(f"inkopt {' '.join(args)} failed with exit status {code}; see {log}")
    return {"seconds": seconds, "peak_rss_gb": usage.ru_maxrss / 2**20, "cpu_seconds": usage.ru_utime + usage.ru_stime}


def check(a, run: Path, extra: list[str]) -> dict:
    """The job's result re-rendered at ``--check-spp`` (default 256 with ``--check-only``), on its scene built
    again as ``inkopt optimize`` built it (the mesh, its height and ``--dpi`` if the options give one)."""
    from result_check import result_check

    from inkopt.model import InkTable
    from inkopt.optim import OptimizeConfig
    from inkopt.scenes import build_scene
    from inkopt.scenes.spec import MeshSpec

    dpi = float(extra[extra.index("--dpi") + 1]) if "--dpi" in extra else MeshSpec(a.mesh).dpi
    scene = build_scene(MeshSpec(a.mesh, height_mm=a.height_mm, dpi=dpi), InkTable.parse("vero-cmykw"))
    return result_check(scene, OptimizeConfig(), run, a.check_spp or 256)


def main() -> int:
    argv = sys.argv[1:]
    extra = argv[argv.index("--") + 1 :] if "--" in argv else []
    argv = argv[: argv.index("--")] if "--" in argv else argv
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("height_mm", type=float, nargs="?", default=40.0)
    ap.add_argument("--mesh", default=str(SPOT))
    ap.add_argument("--dir")
    ap.add_argument("--name")
    ap.add_argument("--check-spp", type=int, default=0, help="render the result again at N spp after the job")
    ap.add_argument("--check-only", action="store_true")
    a = ap.parse_args(argv)
    name = a.name or f"spot{a.height_mm:g}"
    run = Path(a.dir or f"bench-out/job_{name}")
    run.parent.mkdir(parents=True, exist_ok=True)
    previous = RESULTS / RESULTS_FILE
    results = json.loads(previous.read_text())["results"] if previous.is_file() else {}
    if a.check_only:
        results[name]["result_check"] = check(a, run, results[name]["optimize_options"])
        write(RESULTS_FILE, {"results": results})
        print(json.dumps(results[name]["result_check"]))
        return 0
    log = run.parent / f"{run.name}.log"
    log.write_bytes(b"")
    load_before = os.getloadavg()[0]
    stages = {}
    opt = ["optimize", a.mesh, "--height-mm", f"{a.height_mm:g}", "--out", str(run), *extra]
    for key, args in (
        ("optimize", opt),
        ("quantize", ["quantize", str(run)]),
        ("export_gcvf", ["export", str(run), "--format", "gcvf"]),
    ):
        stages[key] = stage(args, log)
        print(f"{key}: {stages[key]['seconds']:.0f} s, peak {stages[key]['peak_rss_gb']:.2f} GiB", flush=True)
    total = sum(s["seconds"] for s in stages.values())
    report = json.loads((run / "report.json").read_text())
    keys = ("iterations", "stop", "delta_e76_mean_corrected", "delta_e76_noise_contribution", "delta_e2000_mean")
    entry = {
        "height_mm": a.height_mm,
        "mesh": Path(a.mesh).name,
        "optimize_options": extra,
        "stages": stages,
        "seconds_total": total,
        "peak_rss_gb": max(s["peak_rss_gb"] for s in stages.values()),
        "report": {k: report.get(k) for k in (*keys, "ssim", "eval_spp", "seconds_per_iteration")},
        "load_average_before": load_before,
        "load_average_after": os.getloadavg()[0],
        "machine": machine(),
        **provenance(),
    }
    print(f"job: {total / 60:.1f} min, peak {entry['peak_rss_gb']:.2f} GiB; {json.dumps(entry['report'])}")
    if a.check_spp:
        entry["result_check"] = check(a, run, extra)
        print(f"result re-rendered: {json.dumps(entry['result_check'])}")
    results[name] = entry
    write(RESULTS_FILE, {"results": results})
    return 0


if __name__ == "__main__":
    sys.exit(main())
