"""Two lights: does optimising a print for D65 and A at once lower its worst-light error?

A colour-chart slab (2.71 x 1.78 x 1 mm, 32 x 21 x 12 voxels at 300 DPI, the chart on top) with a spectral ink table
is optimised three times with the same seeds and settings: for D65 alone (``Viewing(table, (D65,))``), for D65 and A
together (the mean of the two lights' losses) and for the worse of the two (``combine="worst"``: each iteration steps
on the light whose loss is largest). Every result is rendered once more with fresh seeds at ``--eval-spp`` and scored
under both lights (``evaluation.lights.light_figures``: mean ΔE2000 per light against the
target's CIELAB, the worst light, the print's colour inconstancy between the lights). The spectral table is the
benchmark's rule (bench/bench_spectral.py ``spectral_from_rgb``: the Vero RGB coefficients at 610/540/465 nm,
linear in wavelength, 16 bands over 400-700 nm): an assumption, not a calibration.

    nice -n 5 .venv/bin/python experiments/spectral_lights.py [--iterations 150] [--spp 8] [--eval-spp 2048]
        [--seed 0 | --seeds 0,1,2]

Writes experiments/results/spectral_lights.json (``--seed S`` other than 0: spectral_lights_seed<S>.json) and
prints the table. ``--seeds``: every optimisation seed in turn (the final renders' seed is the same for all), each
seed's entries under ``per_seed``, and per variant the worst light's mean ΔE2000 over the seeds with its standard
error and its paired difference to D65 alone (``over_seeds``), in spectral_lights_seeds.json.
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
#: (what the run is optimised for, its lights, how their losses combine)
VARIANTS = (("D65", ("D65",), "mean"), ("D65,A", ("D65", "A"), "mean"), ("D65,A_worst", ("D65", "A"), "worst"))


def one_seed(scene, table, seed: int, a) -> dict:
    """Every variant optimised with seed ``seed`` and scored under D65 and A (``light_figures``' dicts by key)."""
    lights = {n: named_light(n) for n in ("D65", "A")}
    scorer = Viewing(table, tuple(lights.values())).loss(scene.target_rgb, scene.texels.pos_vox, (1.0, 0.0, 0.0))
    cfg = OptimizeConfig(iterations=a.iterations, spp=a.spp, forward_spp=a.spp, seed=seed).for_scene(scene.kind)
    out = {}
    for name, names, combine in VARIANTS:
        viewing = Viewing(table, tuple(lights[n] for n in names), combine=combine)
        run = Optimization(scene, cfg, threads=a.threads, viewing=viewing)
        run.run()
        res = SpectralRenderer(run.volume(), table, a.threads).render(scene.texels, a.eval_spp, seed=2**62 + 1)
        out[f"optimised_for_{name}"] = fig = light_figures(scorer, res.rgb, res.var_mean, ("D65", "A"))
        by = fig["by_light"]
        print(
            f"seed {seed}, optimised for {name:11s}: mean ΔE2000 under D65 {by['D65']['delta_e2000_mean']:.3f}, "
            f"under A {by['A']['delta_e2000_mean']:.3f}, worst {fig['worst_delta_e2000_mean']:.3f} "
            f"({fig['worst_light']}); noise (ΔE76 per texel) {by['D65']['delta_e76_noise']:.3f}; inconstancy D65-A "
            f"{fig['inconstancy_delta_e2000_mean']['D65-A']:.2f}"
        )
    return out


def over_seeds(per_seed: dict) -> dict:
    """Per variant: each light's and the worst light's mean ΔE2000 over the seeds with its standard error, and the
    worst light's paired difference to D65 alone (seed by seed)."""
    se = lambda v: float(np.std(v, ddof=1) / np.sqrt(len(v))) if len(v) > 1 else None
    out = {}
    for name, _, _ in VARIANTS:
        figs = [s[f"optimised_for_{name}"] for s in per_seed.values()]
        base = [s["optimised_for_D65"]["worst_delta_e2000_mean"] for s in per_seed.values()]
        worst = [f["worst_delta_e2000_mean"] for f in figs]
        diff = np.subtract(worst, base)
        out[f"optimised_for_{name}"] = {
            **{
                light: {"mean": float(np.mean(v)), "stderr": se(v)}
                for light in ("D65", "A")
                for v in [[f["by_light"][light]["delta_e2000_mean"] for f in figs]]
            },
            "worst": {"mean": float(np.mean(worst)), "stderr": se(worst)},
            "worst_minus_D65_alone": {"mean": float(diff.mean()), "stderr": se(diff), "per_seed": diff.tolist()},
        }
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--iterations", type=int, default=150)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--eval-spp", type=int, default=2048)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0, help="the optimisations' seed (OptimizeConfig.seed)")
    ap.add_argument("--seeds", help="several optimisation seeds, comma-separated (spectral_lights_seeds.json)")
    a = ap.parse_args()
    inks = InkTable.parse("vero-cmykw")
    table = spectral_from_rgb(inks, 16)
    top = srgb_to_linear(charts.colour_chart(128, 84) / 255.0).astype(np.float32)
    scene = build_slab(top, None, SIZE_MM, inks)
    seeds = [int(s) for s in a.seeds.split(",")] if a.seeds else [a.seed]
    out = {"iterations": a.iterations, "spp": a.spp, "eval_spp": a.eval_spp, "texels": len(scene.texels)}
    t0 = time.perf_counter()
    per_seed = {str(s): one_seed(scene, table, s, a) for s in seeds}
    if a.seeds:
        out.update(seeds=seeds, per_seed=per_seed, over_seeds=over_seeds(per_seed))
        for k, v in out["over_seeds"].items():
            d = v["worst_minus_D65_alone"]
            print(
                f"{k}: worst light {v['worst']['mean']:.3f} ± {v['worst']['stderr'] or 0:.3f}; "
                f"minus D65 alone {d['mean']:+.3f} ± {d['stderr'] or 0:.3f}"
            )
        name = "spectral_lights_seeds.json"
    else:
        out.update(seed=a.seed, **per_seed[str(a.seed)])
        name = f"spectral_lights_seed{a.seed}.json" if a.seed else "spectral_lights.json"
    out.update(wall_s=time.perf_counter() - t0, threads=a.threads, **machine())
    print("wrote", write(name, out))


if __name__ == "__main__":
    main()
