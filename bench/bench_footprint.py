"""The footprint's estimates (``inkopt.footprint``: counts, peak memory, seconds per iteration from the mesh alone)
against what happens, on Spot.

    python bench/bench_footprint.py counts                 # against bench/results/mesh_*mm.json and the runs below
    python bench/bench_footprint.py dry 100 200 [-- --shell-mm 1]   # `inkopt optimize --dry-run`: seconds, peak
    python bench/bench_footprint.py run 40 --dir D [--stages] [--tag T] [-- OPTIONS]   # a real run (--iterations 2
                                                   # unless OPTIONS say); --stages: each stage's own peak
    python bench/bench_footprint.py timed 40 --dir D --time-log LOG   # a run made under /usr/bin/time -v
    python bench/bench_footprint.py fit --tag T             # the band runs' stages against the footprint's
    python bench/bench_footprint.py walk [--check mesh_100mm_shell1_s65.json ...] [--estimate 80 ...]   # the time
                                                   # model's fit (below); a 1 mm band's estimates at those heights
    python bench/bench_footprint.py watch 40 --pid PID --stage TEXT --run-command CMD [-- --shell-mm 1]   # a run
                                                   # under way: peak so far

Each mode writes its entries into bench/results/footprint_spot.json (``entries``: ``counts``, ``dry_<H>mm``,
``run_<H>mm``) with
the command, the commit and the load average before and after; every command runs in its own process, measured by
``os.wait4`` (peak resident memory and CPU seconds of that process). A run's seconds per iteration is report.json's
``seconds_iterations`` over its iterations; its CPU seconds per iteration are not separable from the set-up and
figures, so the load average says how far the wall time is the machine's.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import RESULTS, SPOT, machine, provenance, write

ROOT = Path(__file__).resolve().parents[1]
RESULTS_FILE = "footprint_spot.json"


def _process(args: list[str], log: Path, stages: Path | None = None) -> dict:
    """Run ``python -m inkopt.cli ARGS`` (stdout and stderr to ``log``): exit status, wall and CPU seconds, peak
    RSS (GiB); with ``stages`` (a JSON path) under ``run_stages.py``, which adds ``stages``: each stage's own peak
    (``run_stages.py``'s marks, its reset peaks making ``peak_rss_gb`` the largest of them)."""
    t = time.perf_counter()
    command = [sys.executable, "-m", "inkopt.cli"]
    if stages is not None:
        command = [sys.executable, str(ROOT / "bench" / "run_stages.py"), str(stages)]
    with open(log, "wb") as f:
        proc = subprocess.Popen([*command, *args], stdout=f, stderr=f)
        _, status, usage = os.wait4(proc.pid, 0)
    rec = {
        "exit_status": os.waitstatus_to_exitcode(status),
        "seconds": time.perf_counter() - t,
        "cpu_seconds": usage.ru_utime + usage.ru_stime,
        "peak_rss_gb": usage.ru_maxrss / 2**20,
        "output": log.read_text().strip().splitlines(),
    }
    if stages is not None:
        marks = json.loads(stages.read_text())["marks"]
        rec["peak_rss_gb"] = max(m["peak_gib"] for m in marks)  # ru_maxrss is reset with the marks' peaks
        rec["stages"] = [[m["mark"], m["peak_gib"], round(m["seconds"], 1)] for m in marks]
    return rec


def _footprint(height: float, shell_mm=None):
    from inkopt.footprint import spec_footprint
    from inkopt.scenes.spec import MeshSpec

    return spec_footprint(MeshSpec(str(SPOT), height_mm=height, shell_mm=shell_mm), 5)[0]


def counts() -> dict:
    """The footprint's counts and peak against every bench/results/mesh_*mm.json (voxelized Spot)."""
    rows = {}
    for path in sorted(RESULTS.glob("mesh_*mm*.json")):
        rec = json.loads(path.read_text())
        if rec.get("dpi", 300.0) != 300.0:
            continue
        fp = _footprint(rec["height_mm"], rec.get("shell_mm"))
        measured = {k: rec[k] for k in ("voxels", "inside_voxels", "free_voxels", "texels")}
        est = {"voxels": fp.grid_voxels, "inside_voxels": fp.inside_voxels, "free_voxels": fp.free_voxels}
        est["texels"] = fp.texels
        rows[path.name] = {
            "measured": measured,
            "estimated": est,
            "relative_error": {k: est[k] / measured[k] - 1.0 for k in measured},
            "peak_gib": {"measured": rec["peak_rss_gb"], "estimated": fp.peak_bytes() / 2**30},
            "seconds_per_iteration": {
                "measured": rec["seconds_per_iteration"],
                "estimated": fp.seconds_per_iteration(),
            },
            "measured_code": rec.get("commit"),
        }
    return {"counts": {"rows": rows}}


def reestimate(entries: dict) -> None:
    """Each recorded run's (``run_<H>mm``) estimate by the current footprint, beside the one recorded with it
    (``estimated_now``, ``ratio_now``)."""
    for name, rec in entries.items():
        if name.startswith("run_") and "peak_rss_gb" in rec:
            fp = _footprint(rec.get("height_mm", float(name[4:].split("mm")[0])), rec.get("shell_mm"))
            now = {"peak_gib": fp.peak_bytes() / 2**30, "seconds_per_iteration": fp.seconds_per_iteration()}
            rec["estimated_now"] = now
            rec["ratio_now"] = {
                "peak": now["peak_gib"] / rec["peak_rss_gb"],
                "seconds_per_iteration": now["seconds_per_iteration"] / rec["seconds_per_iteration"],
            }


def _shell(options: list[str]) -> float | None:
    """The ``--shell-mm`` of a run's options (None: not given)."""
    return float(options[options.index("--shell-mm") + 1]) if "--shell-mm" in options[:-1] else None


def dry(heights: list[float], extra: list[str]) -> dict:
    """``inkopt optimize --dry-run`` of Spot at each height with the options ``extra`` (a ``--shell-mm D`` names the
    entries ``dry_<H>mm_shell<D>``)."""
    out = {}
    shell = f"_shell{float(extra[extra.index('--shell-mm') + 1]):g}" if "--shell-mm" in extra[:-1] else ""
    with tempfile.TemporaryDirectory() as tmp:
        for h in heights:
            args = ["optimize", str(SPOT), "--height-mm", f"{h:g}", "--dry-run", "--out", f"{tmp}/run", *extra]
            key = f"dry_{h:g}mm{shell}"
            out[key] = {"load_before": os.getloadavg()[0], **_process(args, Path(tmp) / "log")}
            out[key]["load_after"] = os.getloadavg()[0]
    return out


def run(height: float, run_dir: str, options: list[str], stages: bool = False) -> dict:
    """A run of Spot at ``height`` mm into ``run_dir`` with ``options``; ``stages``: each stage's own peak
    (``_process``)."""
    if "--iterations" not in options and "--time-budget" not in options:
        options = ["--iterations", "2", *options]
    fp = _footprint(height, _shell(options))
    args = ["optimize", str(SPOT), "--height-mm", f"{height:g}", "--out", run_dir, *options]
    before = os.getloadavg()[0]
    rec = _process(args, Path(run_dir + ".log"), Path(run_dir + ".stages.json") if stages else None)
    report = json.loads((Path(run_dir) / "report.json").read_text())
    per = report["seconds_iterations"] / max(report["iterations"], 1)
    rec.update(
        load_before=before,
        load_after=os.getloadavg()[0],
        seconds_per_iteration=per,
        iterations=report["iterations"],
        estimated={"peak_gib": fp.peak_bytes() / 2**30, "seconds_per_iteration": fp.seconds_per_iteration()},
    )
    rec["ratio_estimated_to_measured"] = {
        "peak": rec["estimated"]["peak_gib"] / rec["peak_rss_gb"],
        "seconds_per_iteration": rec["estimated"]["seconds_per_iteration"] / per,
    }
    shell = _shell(options)
    rec.update(height_mm=height, shell_mm=shell, options=options)
    return {f"run_{height:g}mm" + ("" if shell is None else f"_shell{shell:g}"): rec}


def stage_peaks(marks: list) -> dict:
    """The largest peak (GiB) of each footprint stage among a run's marks (``run_stages.py``: [mark, peak since the
    previous mark, seconds]): "voxelize" up to the scene's end, "step" inside ``Optimization.step``, "figures" the
    rest (the set-up, the figures, the baseline guard, the result's files)."""
    out = {"voxelize": 0.0, "step": 0.0, "figures": 0.0}
    stage = "voxelize"
    for name, peak, _ in marks:
        out[stage] = max(out[stage], peak)  # the interval that ends at this mark
        if name == "exit mesh.build_mesh_scene" or name == "exit Optimization.step":
            stage = "figures"
        elif name == "enter Optimization.step":
            stage = "step"
    return out


def fit(tag: str, entries: dict) -> dict:
    """The data the footprint's band constants are fitted to: for each recorded run ``run_<H>mm_shell<D><tag>``
    with stages, its stages' measured peaks (``stage_peaks``), the footprint's counts and its stages' estimates
    (GiB) and their ratio to the measured."""
    rows = {}
    for name, rec in sorted(entries.items()):
        if not (name.startswith("run_") and name.endswith(tag) and "stages" in rec and rec.get("shell_mm")):
            continue
        fp = _footprint(rec["height_mm"], rec["shell_mm"])
        est = {k: v / 2**30 for k, v in fp.stage_bytes().items()}
        measured = stage_peaks(rec["stages"])
        rows[name] = {
            "counts": {"grid": fp.grid_voxels, "inside": fp.inside_voxels, "free": fp.free_voxels, "texels": fp.texels},
            "measured_gib": measured,
            "estimated_gib": est,
            "peak": {"measured": rec["peak_rss_gb"], "estimated": fp.peak_bytes() / 2**30},
            "ratio_estimated_to_measured": fp.peak_bytes() / 2**30 / rec["peak_rss_gb"],
        }
    return {f"fit_shell{tag}": {"rows": rows}}


#: the runs the time model (``inkopt.footprint.walk``) is fitted to, bench/results/mesh_*.json: the events per path
#: of every voxel free (Spot 10-60 mm) and of a 1 mm band over a white core (20-60 mm; events do not depend on the
#: code's speed or the load); the CPU seconds per texel and event of the quiet runs (CPU / wall >= 1.85 with 2
#: threads) of the code since the branch-free traversal (the 10 and 60 mm every-voxel-free runs are older code);
#: the set-up's CPU seconds of the runs that record them (bench_mesh.py's build_cpu_seconds), below 100 mm
WALK_FREE = ("mesh_10mm.json", "mesh_20mm.json", "mesh_40mm.json", "mesh_60mm.json")
WALK_BAND = ("mesh_20mm_shell1_band.json", "mesh_40mm_shell1_corewhite.json", "mesh_60mm_shell1_vx.json")
WALK_COST = ("mesh_20mm.json", "mesh_40mm.json", "mesh_40mm_shell1_corewhite.json", "mesh_60mm_shell1_vx.json")
WALK_SETUP = ("mesh_20mm_s58.json", "mesh_60mm_shell1_gsum.json")
QUIET_CPU_PER_WALL = 1.85


def _thickness(rec: dict) -> float:
    """r = 3 V / A (mm) of the Spot a bench_mesh.py result measured."""
    from inkopt.footprint import mesh_shape, walk
    from inkopt.scenes.mesh import load_spec_mesh
    from inkopt.scenes.spec import MeshSpec

    shape = mesh_shape(load_spec_mesh(MeshSpec(str(SPOT), height_mm=rec["height_mm"])))
    return walk.thickness_mm(shape.volume_mm3, shape.area_mm2)


def walk_fit() -> dict:
    """The time model's constants fitted to the runs named above (least squares: every voxel free, events = L - K / r;
    a band, events = E + S ln(r / r_20mm); the geometric mean of the quiet runs' passes' CPU seconds per texel and
    event, and of their CPU per wall second; the mean set-up CPU seconds per texel), each run's residual, and the
    constants the code holds (``walk``)."""
    import numpy as np

    from inkopt.footprint import walk

    load = {n: json.loads((RESULTS / n).read_text()) for n in {*WALK_FREE, *WALK_BAND, *WALK_COST, *WALK_SETUP}}
    r = {n: _thickness(rec) for n, rec in load.items()}
    ev = {n: rec["events_per_path"]["forward"] for n, rec in load.items() if rec.get("events_per_path")}
    a = np.array([[1.0, -1.0 / r[n]] for n in WALK_FREE])
    limit, k = np.linalg.lstsq(a, [ev[n] for n in WALK_FREE], rcond=None)[0]
    r_ref = r[WALK_BAND[0]]
    a = np.array([[1.0, np.log(r[n] / r_ref)] for n in WALK_BAND])
    ref, slope = np.linalg.lstsq(a, [ev[n] for n in WALK_BAND], rcond=None)[0]
    cost, busy = {}, {}
    for n in WALK_COST:
        rec, split = load[n], load[n]["time_split"]
        busy[n] = rec["cpu_seconds_per_iteration"] / rec["seconds_per_iteration"]
        passes = rec["cpu_seconds_per_iteration"] * (split["render_s"] + split["gradient_s"] + split["loss_s"])
        cost[n] = passes / rec["seconds_per_iteration"] / (rec["texels"] * ev[n])
    quiet = [n for n in WALK_COST if busy[n] >= QUIET_CPU_PER_WALL]
    setup = {n: (load[n]["build_cpu_seconds"] + load[n]["setup_cpu_seconds"]) / load[n]["texels"] for n in WALK_SETUP}
    fitted = {
        "FREE_EVENTS_LIMIT": limit,
        "FREE_EVENTS_MM": k,
        "BAND_EVENTS_REF": ref,
        "BAND_R_REF_MM": r_ref,
        "BAND_EVENTS_PER_LOG": slope,
        "CPU_SECONDS_PER_TEXEL_EVENT": float(np.exp(np.mean(np.log([cost[n] for n in quiet])))),
        "BUSY_CORES": float(np.exp(np.mean(np.log([busy[n] for n in quiet])))),
        "SETUP_CPU_SECONDS_PER_TEXEL": float(np.mean(list(setup.values()))),
    }
    events = {
        n: {"measured": ev[n], "r_mm": r[n], "model": walk.events_per_path(r[n], n in WALK_BAND)}
        for n in (*WALK_FREE, *WALK_BAND)
    }
    return {
        "fit_walk": {
            "fitted": {k: float(v) for k, v in fitted.items()},
            "code": {k: getattr(walk, k) for k in fitted},
            "events_per_path": events,
            "cpu_seconds_per_texel_event": cost,
            "cpu_per_wall": busy,
            "quiet_runs": quiet,
            "setup_cpu_seconds_per_texel": setup,
            "runs": {"free": WALK_FREE, "band": WALK_BAND, "cost": WALK_COST, "setup": WALK_SETUP},
        }
    }


def walk_check(names: list[str]) -> dict:
    """Each bench_mesh.py result of ``names`` against the footprint's estimates: seconds per iteration (the run's
    CPU seconds over ``walk.BUSY_CORES``: what a quiet machine takes, whatever the load was), events per path,
    the set-up's CPU seconds, and each stage's peak against the stage it measured (the scene: voxelize; through the
    iterations: step; the figures' loss side against the figures' stage)."""
    from inkopt.footprint import walk

    out = {}
    for name in names:
        rec = json.loads((RESULTS / name).read_text())
        fp = _footprint(rec["height_mm"], rec.get("shell_mm"))
        stages, rss = {k: v / 2**30 for k, v in fp.stage_bytes().items()}, rec["peak_rss_gb_by_stage"]
        measured = {
            "seconds_per_iteration_quiet": rec["cpu_seconds_per_iteration"] / walk.BUSY_CORES,
            "events_per_path": rec["events_per_path"]["forward"],
            "setup_cpu_seconds": rec["build_cpu_seconds"] + rec["setup_cpu_seconds"],
            "peak_gib": rec["peak_rss_gb"],
            "voxelize_gib": rss["after_voxelize"],
            "step_gib": rss["after_iterations"],
            "figures_gib": rss.get("after_figure_metrics"),
        }
        estimated = {
            "seconds_per_iteration_quiet": fp.seconds_per_iteration(),
            "events_per_path": fp.events,
            "setup_cpu_seconds": fp.setup_seconds(),
            "peak_gib": fp.peak_bytes() / 2**30,
            "voxelize_gib": stages["voxelize"],
            "step_gib": stages["step"],
            "figures_gib": stages["figures"],
        }
        ratio = {k: estimated[k] / measured[k] - 1.0 for k in measured if measured[k]}
        out[f"check_{Path(name).stem}"] = {
            "measured": measured,
            "estimated": estimated,
            "relative_error": ratio,
            "measured_code": rec.get("commit"),
            "measured_load": rec.get("load_average_1min"),
        }
    return out


def walk_estimates(heights: list[float], shell_mm: float = 1.0) -> dict:
    """The footprint's estimates of Spot at each height with a ``shell_mm`` band (entries
    ``estimate_<H>mm_shell<D>``): counts, events per path, seconds per iteration on a quiet machine and their CPU
    seconds, the set-up's seconds, each stage's peak (GiB)."""
    out = {}
    for h in heights:
        fp = _footprint(h, shell_mm)
        seconds = fp.seconds_per_iteration()
        out[f"estimate_{h:g}mm_shell{shell_mm:g}"] = {
            "height_mm": h,
            "shell_mm": shell_mm,
            "counts": {"grid": fp.grid_voxels, "inside": fp.inside_voxels, "free": fp.free_voxels, "texels": fp.texels},
            "events_per_path": fp.events,
            "seconds_per_iteration_quiet": seconds,
            "cpu_seconds_per_iteration": _busy_cores() * seconds,
            "setup_seconds": fp.setup_seconds(),
            "stage_gib": {k: v / 2**30 for k, v in fp.stage_bytes().items()},
            "peak_gib": fp.peak_bytes() / 2**30,
        }
    return out


def _busy_cores() -> float:
    from inkopt.footprint import walk

    return walk.BUSY_CORES


def timed(height: float, run_dir: str, time_log: str) -> dict:
    """A run made outside this script under ``/usr/bin/time -v`` (``time_log``: its stderr, the run's log with
    time's lines at the end): its peak RSS and CPU seconds from time's lines, its seconds per iteration from
    report.json, against the footprint's."""
    import re

    text = Path(time_log).read_text()
    rss_kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", text).group(1))
    user = float(re.search(r"User time \(seconds\): ([0-9.]+)", text).group(1))
    system = float(re.search(r"System time \(seconds\): ([0-9.]+)", text).group(1))
    command = re.search(r'Command being timed: "(.*)"', text).group(1)
    report = json.loads((Path(run_dir) / "report.json").read_text())
    per = report["seconds_iterations"] / max(report["iterations"], 1)
    fp = _footprint(height)
    rec = {
        "run_command": command,
        "peak_rss_gb": rss_kb / 2**20,
        "cpu_seconds": user + system,
        "seconds": report["seconds"],
        "seconds_per_iteration": per,
        "iterations": report["iterations"],
        "estimated": {"peak_gib": fp.peak_bytes() / 2**30, "seconds_per_iteration": fp.seconds_per_iteration()},
        "run_estimate": report.get("estimate"),
    }
    rec["ratio_estimated_to_measured"] = {
        "peak": rec["estimated"]["peak_gib"] / rec["peak_rss_gb"],
        "seconds_per_iteration": rec["estimated"]["seconds_per_iteration"] / per,
    }
    return {f"run_{height:g}mm": rec}


def watch(height: float, pid: int, stage: str, command: str, shell_mm: float | None = None) -> dict:
    """A run under way (process ``pid``, ``command``) that will not finish in time: its peak resident memory so far
    (VmHWM) and CPU seconds from /proc, in ``stage``, against the footprint's peak (with a ``shell_mm`` band)."""
    import subprocess as sp

    status = dict(line.split(":", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines())
    stat = Path(f"/proc/{pid}/stat").read_text().split()
    peak = int(status["VmHWM"].split()[0]) / 2**20
    fp = _footprint(height, shell_mm)
    est = {"peak_gib": fp.peak_bytes() / 2**30, "seconds_per_iteration": fp.seconds_per_iteration()}
    return {
        f"run_{height:g}mm": {
            "partial": True,
            "run_command": command,
            "stage_reached": stage,
            "peak_rss_gb_so_far": peak,
            "cpu_seconds_so_far": (int(stat[13]) + int(stat[14])) / os.sysconf("SC_CLK_TCK"),
            "wall_seconds_so_far": int(sp.check_output(["ps", "-o", "etimes=", "-p", str(pid)])),
            "estimated": est,
            "ratio_estimated_to_measured": {"peak": est["peak_gib"] / peak},
        }
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", choices=("counts", "dry", "run", "timed", "watch", "fit", "walk"))
    ap.add_argument("heights", type=float, nargs="*")
    ap.add_argument("--dir", help="run directory (run, timed)")
    ap.add_argument("--time-log", help="timed: the stderr of `/usr/bin/time -v inkopt optimize ...`")
    ap.add_argument("--pid", type=int, help="watch: the run's process")
    ap.add_argument("--stage", default="", help="watch: how far the run has come")
    ap.add_argument("--run-command", default="", help="watch: the run's command line")
    ap.add_argument("--stages", action="store_true", help="run: each stage's own peak (bench/run_stages.py)")
    ap.add_argument("--check", nargs="*", default=[], help="walk: bench_mesh.py results to compare (bench/results/)")
    ap.add_argument("--estimate", nargs="*", type=float, default=[], help="walk: heights to estimate with a band")
    ap.add_argument("--tag", default="", help="run, timed, watch, dry: appended to the entry's name (e.g. _before)")
    argv = sys.argv[1:]
    extra = argv[argv.index("--") + 1 :] if "--" in argv else []
    args = ap.parse_args(argv[: argv.index("--")] if "--" in argv else argv)
    sys.path.insert(0, str(ROOT / "python"))
    if args.mode == "counts":
        entries = counts()
    elif args.mode == "fit":
        recorded = json.loads((RESULTS / RESULTS_FILE).read_text())["entries"]
        entries = fit(args.tag, recorded)
    elif args.mode == "walk":
        entries = {**walk_fit(), **walk_check(args.check), **walk_estimates(args.estimate)}
    elif args.mode == "dry":
        entries = dry(args.heights or [100.0, 200.0], extra)
    elif args.mode == "watch":
        entries = watch(args.heights[0], args.pid, args.stage, args.run_command, _shell(extra))
    elif not args.dir or len(args.heights) != 1:
        raise SystemExit(f"{args.mode}: one height and --dir")
    elif args.mode == "timed":
        entries = timed(args.heights[0], args.dir, args.time_log)
    else:
        entries = run(args.heights[0], args.dir, extra, args.stages)
    if args.mode in ("run", "timed", "watch", "dry"):
        entries = {name + args.tag: rec for name, rec in entries.items()}
    path = RESULTS / RESULTS_FILE
    data = json.loads(path.read_text()) if path.is_file() else {"entries": {}}
    for name, rec in entries.items():
        data["entries"][name] = {**rec, **provenance(), "machine": machine()}
    if args.mode == "counts":
        reestimate(data["entries"])
    data.update(provenance())  # the last writer's
    write(RESULTS_FILE, data)
    print(json.dumps(entries, indent=1)[:4000])


if __name__ == "__main__":
    main()
