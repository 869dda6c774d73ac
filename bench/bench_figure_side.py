"""The figures' loss side of a run on Spot, phase by phase, in one process: the loss's set-up (``TexelLoss``: the
target's windowed statistics) and a prediction's figures (``evaluation.metrics.prediction_metrics``), each phase's
own resident peak (VmHWM reset at its start by ``/proc/self/clear_refs``) above the resident memory at its start,
per texel, and the figures themselves (compared between code trees: they must be equal).

    python bench/bench_figure_side.py 60 --texels CACHE.npz [--code DIR] [--tag T]

``--texels``: the voxelized texels (positions and targets) of Spot at that height with a 1 mm shell, made here if
the file does not exist (``scenes.mesh.voxelize``). The prediction is the target plus Gaussian noise of 0.02 with a
variance of 1e-4 (the figures' sizes do not depend on the values). ``--code``: the python/ directory whose inkopt
is measured (default this tree's; run as a subprocess). Writes the entry ``<H>mm_shell1_<T>`` of
bench/results/figure_side_spot.json with the command, the commit and the load average before and after.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

from common import RESULTS, SPOT, machine, provenance, write

ROOT = Path(__file__).resolve().parents[1]
RESULTS_FILE = "figure_side_spot.json"

_SCRIPT = """
import json, sys, time
from pathlib import Path
import numpy as np

def status(field):
    for line in open("/proc/self/status"):
        if line.startswith(field + ":"):
            return int(line.split()[1]) * 1024

height, cache, spot = float(sys.argv[1]), Path(sys.argv[2]), sys.argv[3]
if not cache.is_file():
    from inkopt.footprint import mesh_band
    from inkopt.scenes.mesh import load_mesh
    from inkopt.scenes.mesh.voxelize import voxelize
    from inkopt.units import voxel_mm
    vox = voxelize(load_mesh(spot, height_mm=height), voxel_mm=voxel_mm(), band=mesh_band(voxel_mm(), 1.0))
    np.savez(cache, pos=vox.texels.pos_vox, target=vox.targets)
    del vox
from inkopt.evaluation.metrics import prediction_metrics
from inkopt.loss import TexelLoss
z = np.load(cache)
pos, target = z["pos"], z["target"].astype(np.float64)
n = len(pos)
rng = np.random.default_rng(0)
pred = np.clip(target + 0.02 * rng.standard_normal(target.shape), 0.0, 1.0)
var = np.full_like(pred, 1e-4)
phases = {}

def phase(name, f):
    base = status("VmRSS")
    Path("/proc/self/clear_refs").write_text("5")
    t, c = time.perf_counter(), time.process_time()
    out = f()
    phases[name] = {
        "peak_above_start_bytes_per_texel": (status("VmHWM") - base) / n,
        "held_after_bytes_per_texel": (status("VmRSS") - base) / n,
        "seconds": time.perf_counter() - t,
        "cpu_seconds": time.process_time() - c,
    }
    return out

loss = phase("loss_setup", lambda: TexelLoss(target, pos))
loss.release_operators()  # as a run does after its set-up
m = phase("prediction_metrics", lambda: prediction_metrics(loss, pred, var))
print(json.dumps({"texels": n, "phases": phases, "metrics": m.to_json()}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("height_mm", type=float)
    ap.add_argument("--texels", required=True, help="npz of the voxelized texels (made here if missing)")
    ap.add_argument("--code", default=str(ROOT / "python"), help="python/ directory whose inkopt is measured")
    ap.add_argument("--tag", default="new")
    args = ap.parse_args()
    env = {**os.environ, "PYTHONPATH": args.code}
    load = os.getloadavg()[0]
    cmd = [sys.executable, "-c", _SCRIPT, f"{args.height_mm:g}", args.texels, str(SPOT)]
    out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
    rec = {**json.loads(out.strip().splitlines()[-1]), "code": args.code, "load_before": load}
    rec["load_after"] = os.getloadavg()[0]
    print(json.dumps(rec), flush=True)
    path = RESULTS / RESULTS_FILE
    data = json.loads(path.read_text()) if path.is_file() else {"entries": {}}
    data["entries"][f"{args.height_mm:g}mm_shell1_{args.tag}"] = {**rec, **provenance(), "machine": machine()}
    data.update(provenance())
    write(RESULTS_FILE, data)


if __name__ == "__main__":
    main()
