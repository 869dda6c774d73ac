"""The exponentiated gradient's step scale of a shell run against the run with every voxel free, on Spot.

    python bench/bench_step_scale.py 20 [--shell-mm 1] [--iterations 3] [--spp 4]

Runs ``--iterations`` steps of Spot at the height with every voxel free, then with the shell, both from white with
the same seed. At each warm-up step of the shell run the 99th percentile of |g| is taken two ways from the same
gradient: over the free voxels alone (what the step scale was before the core joined its population) and with the
core's voxels counted as zero gradients (``ExponentiatedGradient.held_rows``, what it is now); the all-free run's
own percentile is the reference. Their ratios are the shell run's step sizes relative to the all-free run's
(the step is lr m / s). The shell run is made twice, stepping with each; its training ΔE76 after the same
iterations, same seeds, is in both. Writes the entry ``<H>mm_shell<D>`` of bench/results/step_scale_spot.json with the
command, the commit and the load average.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "bench"))

RESULTS_FILE = "step_scale_spot.json"


def percentiles(height: float, shell: float | None, iterations: int, spp: int, core_zeros: bool = True) -> dict:
    """Per iteration the percentile over the free voxels and with the held voxels as zeros, and the ΔE76;
    ``core_zeros`` False: the run steps with the percentile over its free voxels alone (as before)."""
    import numpy as np
    from common import SPOT

    from inkopt.model import InkTable
    from inkopt.optim import Optimization, OptimizeConfig
    from inkopt.optim.optimizers import _rows, abs_percentile
    from inkopt.scenes.mesh import build_mesh_scene
    from inkopt.scenes.spec import MeshSpec

    scene = build_mesh_scene(MeshSpec(str(SPOT), height_mm=height, shell_mm=shell), InkTable.parse("vero-cmykw"))
    run = Optimization(scene, OptimizeConfig(iterations=iterations, spp=spp).for_scene("mesh"), threads=2)
    opt, seen = run.opt, {"free": [], "with_core": []}
    held = opt.held_rows
    prepare = opt._prepare

    def recorded(g):
        g2 = np.ascontiguousarray(_rows(g), np.float32)
        seen["free"].append(abs_percentile(g2, opt.percentile, 2))
        seen["with_core"].append(abs_percentile(g2, opt.percentile, 2, held * g2.shape[1]))
        prepare(g)

    opt._prepare = recorded
    opt.held_rows = held if core_zeros else 0
    for _ in range(iterations):
        run.step()
    return {
        "free_voxels": run.param.n_free,
        "held_rows": held,
        "core_zeros": core_zeros,
        "texels": len(scene.texels),
        "percentile_free": seen["free"],
        "percentile_with_core": seen["with_core"],
        "step_scale": float(opt.v[0]),
        "delta_e76": list(run.history.delta_e76),
    }


def main(argv=None) -> dict:
    from common import RESULTS, machine, provenance, write

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("height_mm", type=float, nargs="?", default=20.0)
    ap.add_argument("--shell-mm", type=float, default=1.0)
    ap.add_argument("--iterations", type=int, default=3)
    ap.add_argument("--spp", type=int, default=4)
    args = ap.parse_args(argv)
    load = [os.getloadavg()[0]]
    free = percentiles(args.height_mm, None, args.iterations, args.spp)
    shell = percentiles(args.height_mm, args.shell_mm, args.iterations, args.spp)
    shell_before = percentiles(args.height_mm, args.shell_mm, args.iterations, args.spp, core_zeros=False)
    ref = free["percentile_free"]
    ratio = {  # the shell run's step relative to the all-free run's: the inverse ratio of the scales
        way: [r / s for r, s in zip(ref, shell[f"percentile_{way}"], strict=True)] for way in ("free", "with_core")
    }
    # over the warm-up so far (the step scale is the running mean of the percentiles): the steps' ratio
    ratio["scale before"] = free["step_scale"] / shell_before["step_scale"]
    ratio["scale now"] = free["step_scale"] / shell["step_scale"]
    load.append(os.getloadavg()[0])
    entry = {
        **provenance(),
        "height_mm": args.height_mm,
        "shell_mm": args.shell_mm,
        "spp": args.spp,
        "all_free": free,
        "shell": shell,
        "shell_stepping_as_before": shell_before,
        "step_ratio_shell_to_all_free": {
            "per iteration, before (free voxels)": ratio["free"],
            "per iteration, now (core as zeros)": ratio["with_core"],
            "step scale, before": ratio["scale before"],
            "step scale, now": ratio["scale now"],
        },
        "load_average_1min_before_after": load,
        "machine": machine(),
    }
    print(json.dumps(entry["step_ratio_shell_to_all_free"]))
    path = RESULTS / RESULTS_FILE
    out = json.loads(path.read_text()) if path.is_file() else {"results": {}}
    out["results"][f"{args.height_mm:g}mm_shell{args.shell_mm:g}"] = entry
    write(RESULTS_FILE, out)
    return entry


if __name__ == "__main__":
    main()
