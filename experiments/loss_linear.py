"""The colour term as the figure users read, mean ΔE76, against today's mean ΔE76², side by side on suite meshes,
each arm printed and evaluated as ``inkopt quantize`` and ``inkopt evaluate`` do, against the print-shop baselines.

    nice -n 5 .venv/bin/python experiments/loss_linear.py RUN_DIR --name NAME --iterations N [--texels T]
        [--texture PNG]

Both arms start from the suite run's fine start (``coarse/fine_start.npz``: the coarse stage's result moved onto the
fine grid) with the optimiser's default mesh settings, the same iteration seeds and exactly N iterations (the
convergence rule off), are finished alike (the finishing smoothing), written into a copy of the run, quantized
(blue noise) and evaluated on the same sampled texels with the same seeds (``EvaluateOptions(texel_sample=T,
seed=0)``), so each arm's differences from the extrusion baseline are paired on those texels and the baselines'
renders are the same bits in both arms. Writes the entry NAME of experiments/results/loss_linear.json.

The linear term is the loss's ``colour_term="linear"`` (``inkopt optimize --colour-term linear``;
``loss.TexelLoss``), the Charbonnier form of mean ΔE76, E = mean_i sqrt(|d_i|² + eps²) with d_i a texel's CIELAB
error and eps = ``loss.LINEAR_EPS`` = 1 ΔE76, entering the loss as E1_WEIGHT_SCALE E² (same minimiser); the entries
``duck_20mm_medium_11it``, ``box_20mm_medium_7it`` and ``eyeball_20mm_medium_5it`` ran with this script's own copy of
the same formula (commit 13adcbf), before it became the library's option. The Monte Carlo estimate of d_i / |d_i|
from a 16-spp forward render is biased towards 0 where the render's noise is comparable to |d_i| (texels already
near their target get a smaller push).

Why try it: on the suite's saturated meshes every texel is out of gamut, so the optimum of the squared term trades
a lower mean ΔE76 for fewer large errors, while the suite's targets are stated in mean ΔE76 (docs/quality.md,
"Which figure the optimiser serves").
"""

import argparse
import json
import shutil
import sys
import tempfile
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import add_study_entry, machine, provenance  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from loss_de2000 import check_gradient  # noqa: E402

from inkopt.evaluation.evaluate import evaluate_run  # noqa: E402
from inkopt.evaluation.options import EvaluateOptions  # noqa: E402
from inkopt.loss import LINEAR_EPS, TexelLoss  # noqa: E402
from inkopt.model import InkTable, Quantization  # noqa: E402
from inkopt.optim import OptimizeConfig  # noqa: E402
from inkopt.optim.loop import Optimization  # noqa: E402
from inkopt.printing.stream import quantize_run  # noqa: E402
from inkopt.rundir import RunDir  # noqa: E402
from inkopt.scenes import build_scene  # noqa: E402
from inkopt.scenes.spec import MeshSpec  # noqa: E402

#: the files of a suite run an evaluation reads besides the result (copied into each arm's folder)
RUN_FILES = ("scene.npz", "report.json", "checkpoint.npz")


def optimise(scene, cfg, out: Path) -> None:
    """One arm: ``cfg.iterations`` iterations from ``cfg.init`` with ``cfg.colour_term``, finished as ``optimize``
    finishes, its volume written to ``out``/volume.npz."""
    run = Optimization(scene, cfg, threads=2)
    run.run()
    run.finish()
    run.volume().save(out / "volume.npz")
    run.release_renderer()


def evaluate(folder: Path, texels: int) -> dict:
    """Quantize (defaults) and evaluate the arm in ``folder`` on ``texels`` sampled texels; its evaluation.json."""
    quantize_run(RunDir(folder), Quantization())
    evaluate_run(folder, EvaluateOptions(seed=0, threads=2, texel_sample=texels))
    return json.loads((folder / "evaluation.json").read_text())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--name", required=True)
    ap.add_argument("--iterations", type=int, required=True)
    ap.add_argument("--texels", type=int, default=1500)
    ap.add_argument("--keep", type=Path, help="keep the arms' folders under this directory")
    ap.add_argument("--texture", help="the texture the suite passes for a mesh without one of its own")
    a = ap.parse_args()
    grad_err = check_gradient(partial(TexelLoss, colour_term="linear"))
    print(f"gradient check: largest relative difference {grad_err:.2e}")
    report = json.loads((a.run / "report.json").read_text())
    spec = MeshSpec(report["mesh_path"], height_mm=report["height_mm"], texture=a.texture)
    scene = build_scene(spec, InkTable.parse("vero-cmykw"))
    recorded = np.load(a.run / "scene.npz")["target_rgb"]
    if recorded.shape != scene.target_rgb.shape or not np.allclose(recorded, scene.target_rgb, atol=1e-6):
        raise RuntimeError(f"the rebuilt scene differs from {a.run / 'scene.npz'}")
    start = a.run / "coarse" / "fine_start.npz"
    cfg = OptimizeConfig(init=str(start), iterations=a.iterations, stop_gain=0.0).for_scene("mesh")
    entry = {**provenance(), "run": str(a.run), "init": str(start), "iterations": a.iterations, "eps": LINEAR_EPS}
    entry |= {"texels_sampled": a.texels, "gradient_check": grad_err}
    root = Path(tempfile.mkdtemp(prefix="loss_linear_", dir=a.keep))
    for arm, term in (("delta_e76_squared", "squared"), ("delta_e76_linear", "linear")):
        folder = root / arm
        folder.mkdir()
        for name in RUN_FILES:
            if (a.run / name).exists():
                shutil.copy2(a.run / name, folder / name)
        optimise(scene, replace(cfg, colour_term=term), folder)
        entry[arm] = evaluate(folder, a.texels)
        print(arm, json.dumps(entry[arm].get("differences", {}))[:600])
    if a.keep is None:
        shutil.rmtree(root)
    entry.update(machine())
    add_study_entry("loss_linear.json", a.name, entry)


if __name__ == "__main__":
    main()
