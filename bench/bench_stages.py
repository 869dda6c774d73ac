"""Peak memory of a mesh run's per-texel and per-grid-voxel stages, each in its own process, for two code trees in
one session (before / after a change), on Spot.

    python bench/bench_stages.py 40 [--shell-mm 1] [--code main=MAIN/python --code new=python] [--run] [--tag T]

(MAIN: a checkout of the code before the change; without --code, only this tree's, labelled new.)

Stages (each a fresh process, its peak resident memory by ``os.wait4``, less the same process's memory before the
stage, so the interpreter and libraries are not counted):

- ``voxelize``: ``scenes.mesh.voxelize.voxelize`` of the placed mesh, with the exact-distance band a shell needs
  (``footprint.mesh_band``);
- ``figure_metrics``: the figures' loss side on the voxelized texels: ``TexelLoss`` with its window and Sobel
  operators and ``evaluation.metrics.prediction_metrics`` of a noisy prediction with its variance (the target plus
  Gaussian noise of 0.02, variance 1e-4: the operators' sizes do not depend on the values).

With ``--run``, also a run's stages: ``bench_mesh.py H --shell-mm D --iterations 1 --figure-metrics --code DIR``
(this tree's benchmark, the tree's package) in its own process: peak resident memory after the scene, the
set-up, the figures and one iteration, the scene's and set-up's wall and CPU seconds, CPU seconds per iteration.

Writes the entries ``<H>mm[_shell<D>]_<label>[_<T>]`` of bench/results/stages_spot.json (with the command, the
commit and the load average before and after each stage).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from common import RESULTS, SPOT, machine, provenance, write

ROOT = Path(__file__).resolve().parents[1]
RESULTS_FILE = "stages_spot.json"

_PRELUDE = """
import sys, time, numpy as np
def rss():
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS"):
            return int(line.split()[1]) * 1024
"""

_VOXELIZE = (
    _PRELUDE
    + """
from inkopt.footprint import mesh_band
from inkopt.scenes.mesh import load_mesh
from inkopt.scenes.mesh.voxelize import voxelize
from inkopt.units import voxel_mm
height, shell, out = float(sys.argv[1]), (None if sys.argv[2] == "none" else float(sys.argv[2])), sys.argv[3]
mesh = load_mesh(sys.argv[4], height_mm=height)
base = rss()
t = time.perf_counter()
vox = voxelize(mesh, voxel_mm=voxel_mm(), band=mesh_band(voxel_mm(), shell))
seconds = time.perf_counter() - t
np.savez(out, pos=vox.texels.pos_vox, target=vox.targets)
print(base, seconds, int(np.prod(vox.inside.shape)), len(vox.texels))
"""
)

_FIGURES = (
    _PRELUDE
    + """
from inkopt.evaluation.metrics import prediction_metrics
from inkopt.loss import TexelLoss
z = np.load(sys.argv[1])
pos, target = z["pos"], z["target"].astype(np.float64)
rng = np.random.default_rng(0)
pred = np.clip(target + 0.02 * rng.standard_normal(target.shape), 0.0, 1.0)
base = rss()
t = time.perf_counter()
loss = TexelLoss(target, pos)
m = prediction_metrics(loss, pred, np.full_like(pred, 1e-4))
print(base, time.perf_counter() - t, repr(m.ssim), repr(m.e3), repr(m.mottle_l2))
"""
)


def _stage(code: str, script: str, args: list[str]) -> dict:
    """``script`` run with ``code`` first on the path: its printed fields, peak RSS over its start (GiB), seconds."""
    env = {**os.environ, "PYTHONPATH": code}
    load = os.getloadavg()[0]
    proc = subprocess.Popen([sys.executable, "-c", script, *args], stdout=subprocess.PIPE, env=env)
    _, status, usage = os.wait4(proc.pid, 0)
    fields = proc.stdout.read().decode().split()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"stage failed ({code})")
    base = float(fields[0])
    return {
        "peak_rss_gb": usage.ru_maxrss / 2**20,
        "stage_peak_gb": (usage.ru_maxrss * 1024 - base) / 2**30,
        "seconds": float(fields[1]),
        "fields": fields[2:],
        "load_before": load,
        "load_after": os.getloadavg()[0],
    }


def _run(code: str, height_mm: float, shell_mm: float | None, out: str) -> dict:
    """A run's stages of ``code``'s package through one iteration (``bench_mesh.py``): the fields compared."""
    cmd = [sys.executable, str(ROOT / "bench" / "bench_mesh.py"), f"{height_mm:g}", "--iterations", "1"]
    cmd += ["--figure-metrics", "--code", code, "--out", out]
    cmd += [] if shell_mm is None else ["--shell-mm", f"{shell_mm:g}"]
    load = os.getloadavg()[0]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    rec = json.loads(Path(out).read_text())
    keys = ("peak_rss_gb_by_stage", "build_seconds", "build_cpu_seconds", "setup_seconds", "setup_cpu_seconds")
    keys += ("figure_metrics_seconds", "seconds_per_iteration", "cpu_seconds_per_iteration", "free_voxels")
    return {**{k: rec[k] for k in keys}, "load_before": load, "load_after": os.getloadavg()[0]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("height_mm", type=float)
    ap.add_argument("--shell-mm", type=float)
    ap.add_argument("--code", action="append", help="LABEL=PYTHON_DIR, repeated (default new=this tree's python)")
    ap.add_argument("--run", action="store_true", help="also a run's stages through one iteration (bench_mesh.py)")
    ap.add_argument("--tag", default="", help="suffix of the entries' names (another session's measurements)")
    args = ap.parse_args()
    codes = dict(c.split("=", 1) for c in (args.code or [f"new={ROOT / 'python'}"]))
    shell = "none" if args.shell_mm is None else f"{args.shell_mm:g}"
    name = f"{args.height_mm:g}mm" + ("" if args.shell_mm is None else f"_shell{args.shell_mm:g}")
    entries = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, code in codes.items():
            texels = f"{tmp}/{label}.npz"
            vox = _stage(code, _VOXELIZE, [f"{args.height_mm:g}", shell, texels, str(SPOT)])
            grid, n_texels = (int(x) for x in vox.pop("fields"))
            fig = _stage(code, _FIGURES, [texels])
            fig["ssim"], fig["e3"], fig["mottle_l2"] = (float(x) for x in fig.pop("fields"))
            key = f"{name}_{label}" + (f"_{args.tag}" if args.tag else "")
            entries[key] = {
                "code": code,
                "grid_voxels": grid,
                "texels": n_texels,
                "voxelize": vox,
                "figure_metrics": fig,
                "figure_metrics_bytes_per_texel": fig["stage_peak_gb"] * 2**30 / n_texels,
            }
            if args.run:
                entries[key]["run"] = _run(code, args.height_mm, args.shell_mm, f"{tmp}/{label}.json")
            print(label, json.dumps(entries[key]), flush=True)
    path = RESULTS / RESULTS_FILE
    data = json.loads(path.read_text()) if path.is_file() else {"entries": {}}
    for key, rec in entries.items():
        data["entries"][key] = {**rec, **provenance(), "machine": machine()}
    data.update(provenance())
    write(RESULTS_FILE, data)


if __name__ == "__main__":
    main()
