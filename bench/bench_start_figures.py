"""Time and agreement of a mesh run's start figures (``runfigures.RunFigures.start``) from a texel sample and from
every texel: the figures a run measures of its start and of the extrusion baseline before its first iteration.

    python bench/bench_start_figures.py [HEIGHT_MM=20] [--mesh spot.obj] [--only sample|every] [--name NAME]
        [-- OPTIONS ...]

``OPTIONS`` after ``--``: ``inkopt optimize``'s, read as the command line reads them (default ``--init
white``; a print-shop start needs the run driver's baseline and is not read here; a coarse-to-fine job's fine
stage: ``--init DIR/coarse/fine_start.npz --shell-mm 1 --core white``).
The scene and the run's set-up are built once; then the start's figures are measured as a run measures them (the
choice of a texel sample by its pilot, ``START_STDERR_DE76``), then again over every texel (``figure_texel_sample``
0), each with the run's figure seed. Reported per way: seconds (the sample's include its pilot), the figures, their
uncertainty as the baseline guard takes it (``delta_e76_error``), and the difference of the two corrected mean ΔE76s
against the two uncertainties combined. Writes the entry NAME (default ``spot<H>``) of
bench/results/start_figures.json.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from types import SimpleNamespace

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "bench"))

SPOT = ROOT.parent / "shared" / "data" / "spot" / "spot.obj"  # ../shared beside the repository
RESULTS_FILE = "start_figures.json"
WAYS = {"sample": None, "every": 0}  # RunOptions.figure_texel_sample of each way


def measure(run, scene, cfg, way: str) -> dict:
    """The start's figures of ``run`` measured ``way`` (``WAYS``) by a fresh ``RunFigures``, with their seconds."""
    from inkopt.run import RunOptions
    from inkopt.runfigures import RunFigures

    options = RunOptions(figure_texel_sample=WAYS[way], log=lambda m: print(f"  {m}", flush=True))
    job = SimpleNamespace(run=run, scene=scene, cfg=cfg, options=options)
    t = time.perf_counter()
    kept = RunFigures(job).start()
    return {"seconds": time.perf_counter() - t, **kept}


def set_up(argv, doc: str, default_options: list) -> tuple:
    """(the bench's arguments, ``inkopt optimize``'s OPTIONS, the scene, its ``Optimization``, the set-up's seconds)
    of a bench's command line ``argv`` (None: sys.argv; usage in ``doc``) as the module docstring gives it, OPTIONS
    ``default_options`` unless given."""
    from inkopt.cli import build_parser
    from inkopt.cli.runargs import config_from_args, mesh_spec_from_args
    from inkopt.model import InkTable
    from inkopt.optim import Optimization
    from inkopt.scenes import build_scene

    argv = sys.argv[1:] if argv is None else list(argv)
    extra = argv[argv.index("--") + 1 :] if "--" in argv else default_options
    argv = argv[: argv.index("--")] if "--" in argv else argv
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    ap.add_argument("height_mm", type=float, nargs="?", default=20.0)
    ap.add_argument("--mesh", default=str(SPOT))
    ap.add_argument("--only", choices=sorted(WAYS))
    ap.add_argument("--name")
    a = ap.parse_args(argv)
    args = build_parser().parse_args(["optimize", a.mesh, "--height-mm", f"{a.height_mm:g}", "--out", "-", *extra])
    cfg = config_from_args(args)
    t = time.perf_counter()
    scene = build_scene(mesh_spec_from_args(args, args.mesh), InkTable.parse(args.inks))
    run = Optimization(scene, cfg.for_scene(scene.kind), threads=args.threads)
    setup = time.perf_counter() - t
    print(f"scene and set-up in {setup:.0f} s: {len(scene.texels)} texels, {run.param.n_free} free voxels", flush=True)
    return a, extra, scene, run, setup


def main(argv=None) -> dict:
    a, extra, scene, run, setup = set_up(argv, __doc__, ["--init", "white"])
    ways = {}
    for way in [a.only] if a.only else list(WAYS):
        ways[way] = measure(run, scene, run.cfg, way)
        print(f"{way}: {json.dumps(ways[way])}", flush=True)
    result = entry(a, extra, scene, run, setup, ways, "delta_e76_error")
    if len(ways) == 2:
        result["time_ratio_every_over_sample"] = ways["every"]["seconds"] / ways["sample"]["seconds"]
    return record(RESULTS_FILE, a, result)


def entry(a, extra: list, scene, run, setup: float, ways: dict, error_key: str) -> dict:
    """A bench's results entry: the scene's and the run's counts, each way's figures (``ways``), and with both
    ways the difference of their corrected mean ΔE76s and their uncertainties (``ways[...][error_key]``) combined."""
    from common import machine

    from inkopt.run import peak_rss_gb

    result = {
        "height_mm": a.height_mm,
        "mesh": Path(a.mesh).name,
        "optimize_options": extra,
        "texels": len(scene.texels),
        "free_voxels": run.param.n_free,
        "setup_seconds": setup,
        "ways": ways,
        "peak_rss_gb": peak_rss_gb(),
        "machine": machine(),
    }
    if len(ways) == 2:
        s, e = ways["sample"], ways["every"]
        diff = s["delta_e76_mean_corrected"] - e["delta_e76_mean_corrected"]
        result["sample_minus_every_delta_e76_corrected"] = diff
        result["combined_error_delta_e76"] = math.hypot(s[error_key], e[error_key])
    return result


def record(results_file: str, a, result: dict) -> dict:
    """``result`` written as the entry ``a.name`` (default ``spot<H>``) of bench/results/``results_file``, with its
    commit and command."""
    from common import RESULTS, provenance, write

    path = RESULTS / results_file
    data = json.loads(path.read_text()) if path.is_file() else {}
    data.setdefault("results", {})[a.name or f"spot{a.height_mm:g}"] = {**result, **provenance()}
    write(results_file, data)
    return result


if __name__ == "__main__":
    main()
