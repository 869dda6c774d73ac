"""Convergence study on the demo slab (6 x 4 x 1 mm, colour chart on top, zebra below, the `inkopt demo` run):
final noise-free quality of the optimiser's settings at equal iterations and at about equal time; with --case,
on the zebra chart or the astronaut photograph of experiments/printable_eval.py instead (200-300 iterations).

    .venv/bin/python experiments/convergence_study.py [--threads 2] [--only NAME ...] [--case demo|zebra|astronaut]

Each setting is one `run_optimisation` of a `SlabSpec` scene from the 97 %-white start with seed 0; the final figures
come from the driver's adaptive evaluation (noise adds <= 0.5 to the mean dE76), so differences of a few tenths are real
for this seed and scene, not for every scene. Writes experiments/results/convergence_CASE.json (one entry per setting:
mean dE76 (noise-corrected), mean dE2000, SSIM, mottle (dL*)^2 in the target's flat regions, seconds of the whole run).
"""

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import STUDY_RESULTS as RESULTS  # noqa: E402
from common import machine
from common import write_study as write

from inkopt import charts  # noqa: E402
from inkopt.model import InkTable  # noqa: E402
from inkopt.optim import OptimizeConfig  # noqa: E402
from inkopt.run import RunOptions, run_optimisation  # noqa: E402
from inkopt.scenes import build_scene  # noqa: E402
from inkopt.scenes.spec import SlabSpec  # noqa: E402

# name -> (iterations, OptimizeConfig overrides), all with a constant step (decay 0; the default decay is 0.25);
# otherwise the defaults: spp 4, forward spp 16, lr 2 (eg), ema 0.8 and step smoothing 1.5 under flat texels;
# "nosmooth" entries turn the smoothing off. Entries of the results file that are not listed here were made by
# other code (see their "note" and docs/experiments.md).
SETTINGS = {
    "default_150": (150, {"decay": 0.0}),
    "default_150_seed1": (150, {"decay": 0.0, "seed": 1}),
    "nosmooth_150": (150, {"decay": 0.0, "smooth": 0.0}),
    "nosmooth_300": (300, {"decay": 0.0, "smooth": 0.0}),
    "nosmooth_150_seed1": (150, {"decay": 0.0, "smooth": 0.0, "seed": 1}),
    "lr1_150": (150, {"decay": 0.0, "lr": 1.0, "smooth": 0.0}),
    "lr0.5_300": (300, {"decay": 0.0, "lr": 0.5, "smooth": 0.0}),
    "spp16_150": (150, {"decay": 0.0, "spp": 16, "smooth": 0.0}),
    "spp8_150": (150, {"decay": 0.0, "spp": 8, "smooth": 0.0}),
    "spp8_smooth0.7_150": (150, {"decay": 0.0, "spp": 8, "smooth": 0.7}),
    "forward0_ema0.9_150": (150, {"decay": 0.0, "forward_spp": 0, "adjoint_ema": 0.9, "smooth": 0.0}),
    "forward0_ema0.9_400": (400, {"decay": 0.0, "forward_spp": 0, "adjoint_ema": 0.9, "smooth": 0.0}),
    "forward0_ema0.9_spp8_150": (150, {"decay": 0.0, "forward_spp": 0, "adjoint_ema": 0.9, "spp": 8, "smooth": 0.0}),
    "smooth0.7_unguided_150": (150, {"decay": 0.0, "smooth": 0.7, "smooth_edge": 0.0}),
    # half the forward samples (an iteration ~30 % cheaper): at equal iterations and at about equal time (the
    # entries in the results file were made with the smoothing's depth weight 30; docs/experiments.md)
    "forward8_150": (150, {"decay": 0.0, "forward_spp": 8, "smooth": 0.7}),
    "forward8_215": (215, {"decay": 0.0, "forward_spp": 8, "smooth": 0.7}),
    # wider step smoothing under flat texels (kernel width 1.5 / 3 voxels; the results were made with depth weight 30)
    "smooth1.5_150": (150, {"decay": 0.0, "smooth": 1.5}),
    "smooth3_150": (150, {"decay": 0.0, "smooth": 3.0}),
    "smooth0.7_150": (150, {"decay": 0.0, "smooth": 0.7}),
}
# --case zebra|astronaut: name -> (iterations, overrides); "default_300" is the default run (300 iterations, step
# decay 0.25); the other entries vary one setting from 200 iterations
CASE_SETTINGS = {
    "default_300": (300, {}),
    "constant_200": (200, {"decay": 0.0}),
    "decay0.25_200": (200, {}),
    "decay0.5_200": (200, {"decay": 0.5}),
    "decay0.25_250": (250, {}),
    "decay0.25_lr3_200": (200, {"lr": 3.0}),
    "decay0.25_spp8_200": (200, {"spp": 8}),
    "nosmooth_200": (200, {"smooth": 0.0, "decay": 0.0}),
    "spp8_200": (200, {"spp": 8, "smooth": 0.0, "decay": 0.0}),
    "forward8_200": (200, {"forward_spp": 8, "smooth": 0.7, "decay": 0.0}),
    "smooth0.7_200": (200, {"smooth": 0.7, "decay": 0.0}),
}
KEYS = (
    "delta_e76_mean_corrected",
    "delta_e76_mean",
    "delta_e2000_mean",
    "ssim",
    "mottle_l2",
    "seconds",
    "seconds_per_iteration",
)


def scene(case: str, tmp: Path):
    """(top picture, bottom picture or None, size in mm) of a case; zebra and astronaut as in printable_eval.py."""
    if case == "demo":
        return (
            charts.save(charts.colour_chart(288, 192), tmp / "chart.png"),
            charts.save(charts.zebra(71, 47), tmp / "zebra.png"),
            (6.0, 4.0, 1.0),
        )
    if case == "zebra":
        return charts.save(charts.zebra(180, 60), tmp / "zebra.png"), None, (180 * 25.4 / 300, 60 * 25.4 / 300, 1.0)
    from skimage import data
    from skimage.transform import resize

    img = (resize(data.astronaut(), (236, 236), anti_aliasing=True) * 255).astype(np.uint8)
    return charts.save(img, tmp / "astronaut.png"), None, (10.0, 10.0, 2.0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int)
    ap.add_argument("--only", nargs="*", choices=sorted(SETTINGS) + sorted(CASE_SETTINGS))
    ap.add_argument("--case", choices=("demo", "zebra", "astronaut"), default="demo")
    a = ap.parse_args()
    settings = SETTINGS if a.case == "demo" else CASE_SETTINGS
    unknown = set(a.only or ()) - set(settings)
    if unknown:
        ap.error(f"settings {sorted(unknown)} are not run for --case {a.case}")
    inks = InkTable.parse("vero-cmykw")
    out = {"machine": machine(), "threads": a.threads, "settings": {}}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        top, bottom, size = scene(a.case, tmp)
        for name in a.only or settings:
            iterations, kw = settings[name]
            cfg = OptimizeConfig(**{"iterations": iterations, "seed": 0, **kw})
            rep = run_optimisation(
                build_scene(SlabSpec(top, size, bottom=bottom), inks),
                tmp / name,
                cfg,
                RunOptions(threads=a.threads, log=lambda s: None),
            ).to_json()
            row = {"iterations": iterations, **kw, **{k: rep[k] for k in KEYS}}
            if rep["smooth"]:
                row.setdefault("smooth_edge", cfg.smooth_edge)
            out["settings"][name] = row
            print(
                name,
                " ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()),
                flush=True,
            )
    previous = RESULTS / f"convergence_{a.case}.json"
    if a.only and previous.is_file():  # a partial run updates the settings it ran
        old = json.loads(previous.read_text())
        old["settings"].update(out["settings"])
        out["settings"] = old["settings"]
    write(f"convergence_{a.case}.json", out)


if __name__ == "__main__":
    main()
