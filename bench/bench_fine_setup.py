"""Peak memory of the fine stage's set-up of a coarse-to-fine mesh run: the 300-DPI scene of Spot, the fine
``Optimization`` started from a transferred start volume (``--init`` that file, as ``coarse.run_coarse_to_fine`` does),
then its renderer set to the start; it stops before the first iteration (``--step``: after one).

    python bench/bench_fine_setup.py START.npz [HEIGHT_MM=40] [--mesh spot.obj] [--step] [--name NAME]
        [-- OPTIONS ...]

``START.npz``: a start on the fine grid, a mixture volume or a start-rows file (``DIR/coarse/fine_start.npz`` of a
coarse-to-fine run of that mesh and height). ``OPTIONS`` after ``--``: ``inkopt optimize``'s, read as the command
line reads them (default ``--coarse-dpi 150 --time-budget 27m``). Peak memory is the process's resident-set
high-water mark (getrusage) after each stage (and the resident set at its end, ``rss_gb_by_stage``); run one per
process, with nothing else heavy on the machine. Writes the entry NAME (default ``spot<H>``) of
bench/results/fine_setup.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "bench"))

SPOT = ROOT.parent / "shared" / "data" / "spot" / "spot.obj"  # ../shared beside the repository
RESULTS_FILE = "fine_setup.json"


def rss_gb() -> float:
    """The resident set of this process now, GiB (``/proc/self/statm``, Linux)."""
    import os

    return int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**30


def main(argv=None) -> dict:
    from common import RESULTS, machine, provenance, write

    from inkopt.cli import build_parser
    from inkopt.cli.runargs import config_from_args, mesh_spec_from_args
    from inkopt.model import InkTable
    from inkopt.optim import Optimization
    from inkopt.run import peak_rss_gb
    from inkopt.scenes import build_scene

    argv = sys.argv[1:] if argv is None else list(argv)
    extra = argv[argv.index("--") + 1 :] if "--" in argv else ["--coarse-dpi", "150", "--time-budget", "27m"]
    argv = argv[: argv.index("--")] if "--" in argv else argv
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("start", help="the start on the fine grid (DIR/coarse/fine_start.npz)")
    ap.add_argument("height_mm", type=float, nargs="?", default=40.0)
    ap.add_argument("--mesh", default=str(SPOT))
    ap.add_argument("--step", action="store_true", help="also run the first iteration")
    ap.add_argument("--name")
    a = ap.parse_args(argv)
    args = build_parser().parse_args(
        ["optimize", a.mesh, "--height-mm", f"{a.height_mm:g}", "--out", "unused", "--init", a.start, *extra]
    )
    inks = InkTable.parse(args.inks)
    cfg = config_from_args(args)
    rss, now, seconds = {"start": peak_rss_gb()}, {}, {}

    t = time.perf_counter()
    scene = build_scene(mesh_spec_from_args(args, args.mesh), inks)
    seconds["scene"], rss["after_scene"], now["after_scene"] = time.perf_counter() - t, peak_rss_gb(), rss_gb()
    t = time.perf_counter()
    run = Optimization(scene, replace(cfg, init=a.start).for_scene(scene.kind), threads=args.threads)
    seconds["optimization"], rss["after_optimization"] = time.perf_counter() - t, peak_rss_gb()
    now["after_optimization"] = rss_gb()
    t = time.perf_counter()
    run.renderer()
    seconds["renderer"], rss["after_renderer"], now["after_renderer"] = time.perf_counter() - t, peak_rss_gb(), rss_gb()
    if a.step:
        t = time.perf_counter()
        run.step()
        seconds["step"], rss["after_step"], now["after_step"] = time.perf_counter() - t, peak_rss_gb(), rss_gb()
    result = {
        "height_mm": a.height_mm,
        "mesh": Path(a.mesh).name,
        "start": str(a.start),
        "optimize_options": extra,
        "grid_zyx": list(scene.volume.shape),
        "free_voxels": run.param.n_free,
        "peak_rss_gb_by_stage": rss,
        "rss_gb_by_stage": now,
        "seconds_by_stage": seconds,
        "machine": machine(),
        "note": "peak memory: resident-set high-water mark after each stage, in order (the scene, the fine "
        "Optimization from the start file, its renderer set to the start, with --step its first iteration); "
        "rss_gb_by_stage: the resident set at the end of each stage; wall times on a shared machine",
    }
    path = RESULTS / RESULTS_FILE
    data = json.loads(path.read_text()) if path.is_file() else {}
    data.setdefault("results", {})[a.name or f"spot{a.height_mm:g}"] = {**result, **provenance()}
    write(RESULTS_FILE, data)
    keys = ("grid_zyx", "peak_rss_gb_by_stage", "rss_gb_by_stage", "seconds_by_stage")
    print(json.dumps({k: result[k] for k in keys}))
    return result


if __name__ == "__main__":
    main()
