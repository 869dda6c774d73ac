"""The finishing smoothing on a Spot result: a run's volume.npz smoothed by 0, 1, ... passes of the step's smoothing
operator (what ``OptimizeConfig.finish_smooth`` does after the last iteration), each rendered at a fixed number of
samples per texel: noise-corrected mean ΔE76, ΔE2000, SSIM and the flat texels' mottle. Writes
experiments/results/finish_smooth.json (one entry per name, updated in place).

    .venv/bin/python experiments/finish_smooth.py NAME RUN/volume.npz [--height-mm 20] [--passes 0,1,4] [--spp 256]

The volume must be a result on the grid of Spot at ``--height-mm`` (300 DPI, every inside voxel free: the defaults
of ``inkopt optimize``). The smoothing operator is the mesh defaults' (width 3 voxels, edge 4 ΔE76, under flat
texels); the renders use the evaluation's seeds, the same for every entry.
"""

import argparse
import json
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import STUDY_RESULTS as RESULTS  # noqa: E402
from common import machine, provenance
from common import write_study as write
from shell_compare import SPOT  # noqa: E402

from inkopt.model import InkTable  # noqa: E402
from inkopt.optim import OptimizeConfig  # noqa: E402
from inkopt.optim.loop import Optimization  # noqa: E402
from inkopt.run import RunOptions, run_optimisation  # noqa: E402
from inkopt.scenes import build_scene  # noqa: E402
from inkopt.scenes.spec import MeshSpec  # noqa: E402

KEYS = ("delta_e76_mean_corrected", "delta_e2000_mean", "ssim", "mottle_l2", "eval_spp")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    ap.add_argument("volume")
    ap.add_argument("--height-mm", type=float, default=20.0)
    ap.add_argument("--passes", default="0,1,4")
    ap.add_argument("--spp", type=int, default=256)
    a = ap.parse_args()
    inks = InkTable.parse("vero-cmykw")
    scene = build_scene(MeshSpec(SPOT, height_mm=a.height_mm), inks)
    cfg = OptimizeConfig(iterations=0, init=a.volume, lr=1.0).for_scene("mesh")
    run = Optimization(scene, cfg)
    x0, rows = run.x.copy(), {}
    with tempfile.TemporaryDirectory() as tmp:
        for k in (int(p) for p in a.passes.split(",")):
            x = x0.copy()
            for _ in range(k):
                x = run.smoother.apply(x)
            path = Path(tmp) / f"passes{k}.npz"
            scene.volume.save_with_mixture(path, run.param.mixture_slabs(x), inks)
            figures = OptimizeConfig(iterations=0, init=str(path), lr=1.0, finish_smooth=0)
            options = RunOptions(eval_spp=a.spp, log=lambda s: None)
            rep = run_optimisation(scene, Path(tmp) / f"run{k}", figures, options)
            rows[str(k)] = {key: rep.to_json()[key] for key in KEYS}
            print(k, " ".join(f"{key}={v:.4g}" for key, v in rows[str(k)].items()), flush=True)
    path = RESULTS / "finish_smooth.json"
    out = json.loads(path.read_text()) if path.is_file() else {"results": {}}
    out["results"][a.name] = {
        **provenance(),
        "height_mm": a.height_mm,
        "smooth": cfg.smooth,
        "smoothed_rows": None if run.smoother.rows is None else int(len(run.smoother.rows)),
        "free_voxels": int(run.param.n_free),
        "passes": rows,
    }
    out.update(machine())
    write("finish_smooth.json", out)


if __name__ == "__main__":
    main()
