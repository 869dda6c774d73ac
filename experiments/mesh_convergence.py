"""Convergence of the optimiser on Spot (public-domain mesh, ``SPOT``): the training ΔE76 of every
iteration (does it fall steadily or oscillate?) and the noise-free final figures, for settings given as
OptimizeConfig overrides. Writes experiments/results/mesh_convergence.json (one entry per name, updated in place).

    .venv/bin/python experiments/mesh_convergence.py NAME [--height-mm 10] [--iterations 60] [--set KEY=VALUE ...]
        [--out DIR]

``--out DIR`` keeps the run directory (default: a temporary one), and a run stopped part-way resumes from its
checkpoint there.

e.g. ``spot20_default_300 --height-mm 20 --iterations 300`` (the mesh defaults: running-average weight 0.5,
smoothing 3), ``ema0.8_60 --set adjoint_ema=0.8 smooth=1.5`` (the slabs' settings) and the converged reference,
a warm start from the default run's result at 4x the gradient and 2x the forward samples, at half the step (a
warm start calibrates the step scale on its small gradients: 3.0e-6 against the cold start's 6.5e-6, so ``lr`` 2
overshoots): ``spot20_converged --height-mm 20 --iterations 80 --set spp=16 forward_spp=32 seed=7 lr=1
init='"bench-out/spot20_default_300/volume.npz"' --out bench-out/spot20_converged``. Every entry records the
resolved ``adjoint_ema`` and ``smooth`` (``default_60``, ``ema0.5_60`` and ``spot20_ema0.5_60``: 0.8 / 1.5,
0.5 / 1.5 and 0.5 / 1.5) and the command. Seed 0 unless set, all cores,
adaptive final evaluation (Monte Carlo noise adds <= 0.5 to the mean ΔE76, SSIM noise ratio <= 0.1).
"""

import argparse
import json
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import STUDY_RESULTS as RESULTS  # noqa: E402
from common import machine
from common import write_study as write
from shell_compare import SPOT  # noqa: E402

from inkopt.model import InkTable  # noqa: E402
from inkopt.optim import OptimizeConfig  # noqa: E402
from inkopt.optim.checkpoint import read_checkpoint  # noqa: E402
from inkopt.run import RunOptions, run_optimisation  # noqa: E402
from inkopt.rundir import RunDir  # noqa: E402
from inkopt.scenes import build_scene  # noqa: E402
from inkopt.scenes.spec import MeshSpec  # noqa: E402

KEYS = (
    "initial_delta_e76_mean_corrected",
    "delta_e76_mean_corrected",
    "delta_e2000_mean",
    "initial_ssim",
    "ssim",
    "mottle_l2",
    "seconds",
    "seconds_iterations",
    "seconds_per_iteration",
    "eval_spp",
    "adjoint_ema",
    "smooth",
)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    ap.add_argument("--height-mm", type=float, default=10.0)
    ap.add_argument("--iterations", type=int, default=60)
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="OptimizeConfig overrides (JSON values)")
    ap.add_argument("--threads", type=int)
    ap.add_argument("--out", help="run directory to keep (and resume from)")
    a = ap.parse_args()
    kw = {k: json.loads(v) for k, v in (s.split("=", 1) for s in a.set)}
    cfg = OptimizeConfig(**{"iterations": a.iterations, "seed": 0, **kw})
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(a.out or tmp)
        scene = build_scene(MeshSpec(SPOT, height_mm=a.height_mm), InkTable.parse("vero-cmykw"))
        options = RunOptions(threads=a.threads, resume=a.out is not None, log=lambda s: None)
        rep = run_optimisation(scene, d, cfg, options).to_json()
        ck = read_checkpoint(RunDir(d).checkpoint_path)
        train = [round(float(v), 3) for v in ck["hist_delta_e76"]]
    row = {
        "command": "python experiments/mesh_convergence.py " + " ".join(sys.argv[1:]),
        "height_mm": a.height_mm,
        "iterations": a.iterations,
        **kw,
        **{k: rep[k] for k in KEYS if k in rep},
        "train_delta_e76": train,
    }
    print(a.name, " ".join(f"{k}={v:.4g}" for k, v in row.items() if isinstance(v, float)))
    print("training ΔE76:", train)
    path = RESULTS / "mesh_convergence.json"
    out = json.loads(path.read_text()) if path.is_file() else {"results": {}}
    out["results"][a.name] = row
    out.update(machine())
    write("mesh_convergence.json", out)


if __name__ == "__main__":
    main()
