"""``inkopt evaluate`` of an optimised Spot run: wall time, CPU time and peak memory of the whole command (its own
process, ``/usr/bin/time -v``), and per result (continuous, quantized, surface and extrusion baselines) its seconds,
samples per scene texel, events per path and noise figures from the evaluation file.

    .venv/bin/python bench/bench_evaluate.py HEIGHT_MM [--dir D] [--reuse] [--spp N] [--texel-sample N]
        [--sample-windows M] [--code CHECKOUT] [--name NAME] [--versus OTHER.json ...] [--only-versus R.json]

The run directory is made first unless ``--reuse`` finds one (each step its own process, timed, recorded as
``setup``): ``inkopt optimize spot.obj --height-mm H --iterations 1 --eval-spp 16 --out D`` and ``inkopt quantize
D``. Then ``inkopt evaluate D --out D/bench_evaluation.json``, its log written to D/bench_evaluate.log as it
runs (``--spp N``: fixed samples instead of the adaptive default; ``--time-budget``, ``--max-spp``,
``--texel-sample``, ``--sample-windows``, ``--seed`` passed on; with a texel sample each result also keeps its figures'
standard errors, and the file the sample and the paired differences).
``--code``: evaluate with another checkout's Python package (e.g. the commit before a change, with its own built
``_core``), so one run directory serves both. ``sampling_choice``: every texel or a texel sample and the times the
evaluation predicted for both (``evaluation.choice``), beside the continuous result's measured seconds.
``--versus`` (repeatable): another results file of this bench (e.g. a larger object's, measured in the same
session, or the same run's evaluated by other code): its wall and CPU seconds, this evaluation's ratios to them
and, for the same run, the figures side by side with their standard errors and z (``versus``);
``--only-versus RESULTS.json`` adds those to a results file without evaluating. Writes
bench/results/evaluate_<H>mm.json (``--name`` for another name). Wall-clock times on the shared 2-core machine are
upper bounds; CPU seconds and events per path do not depend on the load.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
SPOT = ROOT.parent / "shared" / "data" / "spot" / "spot.obj"
RESULTS = ("continuous", "quantized", "surface", "extrusion")
KEEP = (
    "seconds",
    "spp",
    "spp_passes",
    "spp_printer",
    "events_per_path",
    "delta_e76_mean",
    "delta_e76_mean_corrected",
    "delta_e76_noise_contribution",
    "delta_e2000_mean",
    "ssim",
    "mottle_l2",
    "spp_windows",
)


def timed(args: list[str], code: Path, log_file: Path | None = None) -> dict:
    """Run ``python -m inkopt.cli ARGS`` with ``code``/python first on the path under /usr/bin/time -v: seconds,
    CPU seconds, peak RSS (GiB), the 1-minute load average before and after, stdout and stderr (written to
    ``log_file`` as it runs, when given, so that a long evaluation can be followed)."""
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryFile("w+") if log_file is None else open(log_file, "w+") as err:
        proc = subprocess.run(
            ["/usr/bin/time", "-v", sys.executable, "-m", "inkopt.cli", *args],
            stdout=subprocess.PIPE,
            stderr=err,
            text=True,
            env={**os.environ, "PYTHONPATH": str(code / "python")},
        )
        err.seek(0)
        stderr = err.read()
    if proc.returncode:
        raise SystemExit(f"inkopt {' '.join(args)} failed:\n{proc.stdout}\n{stderr}")
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", stderr).group(1)
    secs = sum(float(p) * 60**i for i, p in enumerate(reversed(wall.split(":"))))
    rss_kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", stderr).group(1))
    cpu = sum(float(re.search(rf"{k} time \(seconds\): (\S+)", stderr).group(1)) for k in ("User", "System"))
    log = stderr[: stderr.find("\tCommand being timed")].strip()
    return {
        "seconds": secs,
        "cpu_seconds": cpu,
        "peak_rss_gb": rss_kb / 2**20,
        "load_average_before": load0,
        "load_average_after": os.getloadavg()[0],
        "stdout": proc.stdout.strip(),
        "log": log,
    }


COMPARED = ("delta_e76_mean", "delta_e76_mean_corrected", "delta_e2000_mean", "ssim")


def versus(res: dict, other: Path) -> dict:
    """This evaluation's wall and CPU seconds as ratios of those of ``other`` (a results file of this bench) and,
    when both evaluated the same run (same texels), each result's figures side by side: both values, their
    standard errors (0 for every texel rendered) and z = (this - other) / the errors combined."""
    o = json.loads(other.read_text())
    out = {
        "file": other.name,
        "height_mm": o["height_mm"],
        "texels": o["texels"],
        "evaluate_seconds": o["evaluate_seconds"],
        "evaluate_cpu_seconds": o["evaluate_cpu_seconds"],
        "seconds_ratio": res["evaluate_seconds"] / o["evaluate_seconds"],
        "cpu_seconds_ratio": res["evaluate_cpu_seconds"] / o["evaluate_cpu_seconds"],
    }
    if o["texels"] != res["texels"]:
        return out
    figures = {}
    for name, r in res["results"].items():
        q = o["results"].get(name)
        if q is None:
            continue
        figures[name] = {}
        for k in COMPARED:
            se_a, se_b = (x.get("stderr", {}).get(k) or 0.0 for x in (r, q))
            se = math.hypot(se_a, se_b)
            z = (r[k] - q[k]) / se if se > 0 else None
            figures[name][k] = {"this": r[k], "stderr": se_a, "other": q[k], "other_stderr": se_b, "z": z}
    return {**out, "figures": figures}


def add_versus(res: dict, others: list[str]) -> None:
    """``res["versus"]``: a ``versus`` entry for each of the ``others`` results files (none: unchanged)."""
    if others:
        res["versus"] = [versus(res, Path(f)) for f in others]


def main() -> dict:
    from common import machine, write

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("height_mm", type=float)
    ap.add_argument("--dir", help="run directory (default /tmp/inkopt_eval_bench_<H>mm)")
    ap.add_argument("--reuse", action="store_true", help="keep an optimised and quantized run directory")
    ap.add_argument("--mesh", default=str(SPOT))
    ap.add_argument("--spp", type=int, help="fixed samples per scene texel (default: adaptive)")
    ap.add_argument("--time-budget", type=float)
    ap.add_argument("--max-spp", type=int)
    ap.add_argument("--texel-sample", type=int, help="evaluate's --texel-sample (default: evaluate's default)")
    ap.add_argument("--sample-windows", type=int)
    ap.add_argument("--seed", type=int, help="evaluate's --seed: another texel sample and other render seeds")
    ap.add_argument("--code", default=str(ROOT), help="checkout whose python/ package evaluates (default: this one)")
    ap.add_argument("--name", help="results file name (default evaluate_<H>mm.json)")
    ap.add_argument(
        "--versus",
        action="append",
        default=[],
        help="another results file of this bench to compare with (repeatable): time ratios, and figures of one run",
    )
    ap.add_argument("--only-versus", metavar="RESULTS.json", help="evaluate nothing: add --versus to this file")
    args = ap.parse_args()
    if args.only_versus:
        res = json.loads(Path(args.only_versus).read_text())
        add_versus(res, args.versus)
        print(json.dumps(res["versus"], indent=1))
        print("wrote", write(Path(args.only_versus).name, res))
        return res
    code = Path(args.code).resolve()
    out = Path(args.dir or f"/tmp/inkopt_eval_bench_{args.height_mm:g}mm")
    setup = {}
    if not (args.reuse and (out / "quantized.npz").is_file()):
        h = f"{args.height_mm:g}"
        opt = ["optimize", args.mesh, "--height-mm", h, "--iterations", "1", "--eval-spp", "16", "--out", str(out)]
        setup["optimize"] = {k: v for k, v in timed(opt, ROOT).items() if k != "log"}
        setup["quantize"] = {k: v for k, v in timed(["quantize", str(out)], ROOT).items() if k != "log"}
    ev_path = out / "bench_evaluation.json"
    cmd = ["evaluate", str(out), "--out", str(ev_path)]
    passed = [("--spp", args.spp), ("--time-budget", args.time_budget), ("--max-spp", args.max_spp)]
    passed += [("--texel-sample", args.texel_sample), ("--sample-windows", args.sample_windows), ("--seed", args.seed)]
    for flag, v in passed:
        if v is not None:
            cmd += [flag, str(v)]
    t = timed(cmd, code, out / "bench_evaluate.log")
    ev = json.loads(ev_path.read_text())
    entries = {"continuous": ev["continuous"], "quantized": ev["quantized"], **(ev.get("baselines") or {})}
    per = {name: {k: entries[name].get(k) for k in KEEP} for name in RESULTS if name in entries}
    for name, r in per.items():  # what one sample per scene texel costs, comparable at any spp
        r["seconds_per_spp"] = r["seconds"] / r["spp"]
        if entries[name].get("stderr") is not None:
            r["stderr"] = {k: entries[name]["stderr"].get(k) for k in KEEP if k in entries[name]["stderr"]}
    code_commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=code, capture_output=True, text=True).stdout.strip()
    res = {
        "mesh": Path(args.mesh).name,
        "height_mm": args.height_mm,
        "texels": ev["texels"],
        "printer_texels": ev["printer_texels"],
        "spp_adaptive": ev["spp_adaptive"],
        "evaluate_seconds": t["seconds"],
        "evaluate_cpu_seconds": t["cpu_seconds"],
        "evaluate_peak_rss_gb": t["peak_rss_gb"],
        "load_average_before": t["load_average_before"],
        "load_average_after": t["load_average_after"],
        "results": per,
        "colour_table_cached": (ev.get("colour_table") or {}).get("cached"),
        "texel_sample": ev.get("texel_sample"),
        "differences": ev.get("differences"),
        "sampling_choice": ev.get("sampling_choice"),
        "evaluated_by": str(code),
        "evaluated_by_commit": code_commit or None,
        "evaluate_command": " ".join(["inkopt", *cmd]),
        "setup": setup,
        "log": t["log"],
        "targets": {"seconds": 600, "peak_rss_gb": 4},
        **machine(),
        "finished": time.strftime("%Y-%m-%d %H:%M"),
    }
    add_versus(res, args.versus)
    print(json.dumps({k: v for k, v in res.items() if k not in ("log", "setup")}, indent=1))
    print("wrote", write(args.name or f"evaluate_{args.height_mm:g}mm.json", res))
    return res


if __name__ == "__main__":
    main()
