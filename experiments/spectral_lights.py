"""Two lights: does optimising a print for D65 and A at once lower its worst-light error?

A colour-chart slab (2.71 x 1.78 x 1 mm, 32 x 21 x 12 voxels at 300 DPI, the chart on top) with a spectral ink table
is optimised twice with the same seeds and settings: for D65 alone (``Viewing(table, (D65,))``) and for D65 and A
together (the mean of the two lights' losses). Both results are rendered once more with fresh seeds at
``--eval-spp`` and scored under both lights (``evaluation.lights.light_figures``: mean ΔE2000 per light against the
target's CIELAB, the worst light, the print's colour inconstancy between the lights). The spectral table is the
benchmark's rule (bench/bench_spectral.py ``spectral_from_rgb``: the Vero RGB coefficients at 610/540/465 nm,
linear in wavelength, 16 bands over 400-700 nm): an assumption, not a calibration.

    nice -n 5 .venv/bin/python experiments/spectral_lights.py [--iterations 150] [--spp 8] [--eval-spp 2048]
        [--seed 0]

Writes experiments/results/spectral_lights.json (``--seed S`` other than 0: spectral_lights_seed<S>.json) and
prints the table.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from bench_spectral import spectral_from_rgb  # noqa: E402
from common import machine  # noqa: E402
from common import write_study as write  # noqa: E402

from inkopt import charts  # noqa: E402
from inkopt.color import srgb_to_linear  # noqa: E402
from inkopt.evaluation.lights import light_figures  # noqa: E402
from inkopt.model import InkTable  # noqa: E402
from inkopt.optim import Optimization, OptimizeConfig  # noqa: E402
from inkopt.scenes.slab import build_slab  # noqa: E402
from inkopt.spectral.lights import named_light  # noqa: E402
from inkopt.spectral.render import SpectralRenderer  # noqa: E402
from inkopt.spectral.viewing import Viewing  # noqa: E402

SIZE_MM = (2.71, 1.78, 1.0)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--iterations", type=int, default=150)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--eval-spp", type=int, default=2048)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0, help="the optimisations' seed (OptimizeConfig.seed)")
    a = ap.parse_args()
    inks = InkTable.parse("vero-cmykw")
    table = spectral_from_rgb(inks, 16)
    top = srgb_to_linear(charts.colour_chart(128, 84) / 255.0).astype(np.float32)
    scene = build_slab(top, None, SIZE_MM, inks)
    d65, a_light = named_light("D65"), named_light("A")
    both = Viewing(table, (d65, a_light))
    scorer = both.loss(scene.target_rgb, scene.texels.pos_vox, (1.0, 0.0, 0.0))
    cfg = OptimizeConfig(iterations=a.iterations, spp=a.spp, forward_spp=a.spp, seed=a.seed).for_scene(scene.kind)
    out = {"iterations": a.iterations, "spp": a.spp, "eval_spp": a.eval_spp, "seed": a.seed}
    out["texels"] = len(scene.texels)
    t0 = time.perf_counter()
    for name, viewing in (("D65", Viewing(table, (d65,))), ("D65,A", both)):
        run = Optimization(scene, cfg, threads=a.threads, viewing=viewing)
        run.run()
        vol = run.volume()
        res = SpectralRenderer(vol, table, a.threads).render(scene.texels, a.eval_spp, seed=2**62 + 1)
        fig = light_figures(scorer, res.rgb, res.var_mean, ("D65", "A"))
        out[f"optimised_for_{name}"] = fig
        by = fig["by_light"]
        print(
            f"optimised for {name:6s}: mean ΔE2000 under D65 {by['D65']['delta_e2000_mean']:.2f}, under A "
            f"{by['A']['delta_e2000_mean']:.2f}, worst {fig['worst_delta_e2000_mean']:.2f} ({fig['worst_light']}); "
            f"noise (ΔE76 per texel) {by['D65']['delta_e76_noise']:.3f}; inconstancy D65-A "
            f"{fig['inconstancy_delta_e2000_mean']['D65-A']:.2f}"
        )
    out.update(wall_s=time.perf_counter() - t0, threads=a.threads, **machine())
    print("wrote", write(f"spectral_lights_seed{a.seed}.json" if a.seed else "spectral_lights.json", out))


if __name__ == "__main__":
    main()
