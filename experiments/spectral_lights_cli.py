"""Two lights on Spot through the command line: is a print optimised with ``--illuminants D65,A`` better under its
worse light than one optimised for D65 alone?

Spot (python/inkopt/data/spot) 20 mm high, ``--inks vero-cmykw@spectral`` (the library's spectral form), the same
settings for every run (``--iterations N --stop-gain 0``, the default optimiser): ``--illuminants D65``,
``--illuminants D65,A`` (the mean of the two losses) and ``--illuminants D65,A --combine worst``, each optimised
with every optimisation seed of ``--seeds`` (``inkopt optimize --seed N``: the run's render and gradient noise).
Each result is then scored at two render seeds (0 and 1) at ``--spp`` samples per texel: the run's continuous
result (volume.npz) rendered on its scene texels with its spectral table and band plan at the seed
``noise.EVAL_SEED_OFFSET + seed`` (the seed ``inkopt evaluate --seed s`` renders with, in one pass of ``--spp``
samples; the printed result and the baselines are left out: they cost most of an evaluation) and scored under D65
and A (``evaluation.lights.light_figures``). The two render seeds' difference gives each figure's Monte Carlo noise
(standard error of their average = |difference| / 2, a one-pair estimate); the optimisation seeds' spread gives the
optimisation's own randomness.

    nice -n 10 python experiments/spectral_lights_cli.py [--dpi 75] [--iterations 40] [--spp 128] [--seeds 0,1,2]
        [--variants D65,D65_A,worst] [--work DIR] [--out NAME.json]

A run directory under ``--work`` that already holds a report.json is reused, and so is a score file (an
interrupted study resumes; optimisation seed 0 keeps the directory names D65, D65_A and worst, seed N adds
``_seedN``). Each variant's entry keeps its keys (``by_light``, ``worst_light``, ``inconstancy_delta_e2000_mean``,
``command``, ``seconds_per_iteration``, ``texels``, ``iterations``), now the means over the optimisation seeds,
and adds ``per_seed`` (each seed's own entry), ``worst_delta_e2000_mean`` with ``worst_stderr_over_seeds``, and
``paired_over_D65`` (the worst light's mean ΔE2000 minus that of the D65-alone run of the same seed: mean, standard
error over the seeds, each seed's). Writes experiments/results/spectral_lights_spot20mm.json (``--out``) and prints
the table.
"""

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import machine  # noqa: E402
from common import write_study as write  # noqa: E402

SPOT = Path(__file__).resolve().parents[1] / "python" / "inkopt" / "data" / "spot" / "spot.obj"
#: run directory name -> (lights, how their losses combine)
VARIANTS = {"D65": ("D65", "mean"), "D65_A": ("D65,A", "mean"), "worst": ("D65,A", "worst")}
LIGHTS = ("D65", "A")


def run_name(variant: str, seed: int) -> str:
    return variant if seed == 0 else f"{variant}_seed{seed}"


def optimise(work: Path, variant: str, seed: int, a) -> list[str]:
    lights, combine = VARIANTS[variant]
    out = work / run_name(variant, seed)
    cmd = [sys.executable, "-m", "inkopt", "optimize", str(SPOT), "--height-mm", "20", "--dpi", str(a.dpi)]
    cmd += ["--iterations", str(a.iterations), "--stop-gain", "0", "--inks", "vero-cmykw@spectral"]
    cmd += ["--illuminants", lights, "--combine", combine, "--eval-spp", "16", "--threads", str(a.threads)]
    cmd += ["--seed", str(seed), "--out", str(out)]
    if not (out / "report.json").is_file():
        subprocess.run(cmd, check=True)
    return cmd


def score(run: Path, seed: int, a) -> dict:
    """The continuous result of ``run`` rendered at ``a.spp`` with render seed ``seed`` and scored under D65 and A
    (``light_figures``' dict), cached in ``run``/score_<spp>_s<seed>.json."""
    path = run / f"score_{a.spp}_s{seed}.json"
    if path.is_file():
        return json.loads(path.read_text())
    from inkopt.evaluation.lights import light_figures
    from inkopt.evaluation.noise import EVAL_SEED_OFFSET
    from inkopt.model.inks import read_ink_file
    from inkopt.model.spectral import spectral_from_data
    from inkopt.render import Renderer
    from inkopt.rundir import RunDir
    from inkopt.spectral.allocation import BandPlan
    from inkopt.spectral.lights import parse_lights
    from inkopt.spectral.viewing import Viewing

    d = RunDir(run)
    view = d.read_report()["viewing"]
    table = spectral_from_data(read_ink_file(d.spectral_inks_path), d.spectral_inks_path)
    plan = BandPlan.from_json(view["plan"]) if "plan" in view else None
    viewing = Viewing(table, parse_lights(",".join(LIGHTS)), plan=plan)
    rec, vol = d.load_scene(), d.load_volume()
    renderer = viewing.renderer_factory(Renderer, shared=True)(vol, a.threads, None)
    res = renderer.render(rec.texels, a.spp, seed=EVAL_SEED_OFFSET + seed)
    loss = viewing.loss(rec.target_rgb.astype(np.float64), rec.texels.pos_vox, (1.0, 0.0, 0.0))
    fig = light_figures(loss, res.rgb, res.var_mean, LIGHTS)
    path.write_text(json.dumps(fig))
    return fig


def row(evals: list[dict]) -> dict:
    """Per light the mean ΔE2000 of the two render seeds' scores and its standard error, the worst light, SSIM."""
    out = {}
    for light in LIGHTS:
        v = [e["by_light"][light]["delta_e2000_mean"] for e in evals]
        out[light] = {
            "delta_e2000_mean": sum(v) / 2,
            "stderr": abs(v[0] - v[1]) / 2,
            "per_seed": v,
            "ssim": sum(e["by_light"][light]["ssim"] for e in evals) / 2,
            "delta_e76_noise": evals[0]["by_light"][light]["delta_e76_noise"],
        }
    worst = max(LIGHTS, key=lambda n: out[n]["delta_e2000_mean"])
    inconstancy = sum(e["inconstancy_delta_e2000_mean"]["D65-A"] for e in evals) / 2
    return {
        "by_light": out,
        "worst_light": worst,
        "worst_delta_e2000_mean": out[worst]["delta_e2000_mean"],
        "inconstancy_delta_e2000_mean": inconstancy,
    }


def mean_se(v) -> tuple[float, float | None]:
    """Mean and its standard error over the optimisation seeds (None with one seed)."""
    v = np.asarray(v, np.float64)
    return float(v.mean()), (float(v.std(ddof=1) / np.sqrt(len(v))) if len(v) > 1 else None)


def over_seeds(rows: dict[int, dict]) -> dict:
    """A variant's entry: its per-seed rows' means (the single-seed keys), the standard error of the worst light's
    mean ΔE2000 over the seeds and ``per_seed``."""
    first = next(iter(rows.values()))
    by = {}
    for light in LIGHTS:
        v = [r["by_light"][light] for r in rows.values()]
        m, se = mean_se([x["delta_e2000_mean"] for x in v])
        by[light] = {
            "delta_e2000_mean": m,
            "stderr_over_seeds": se,
            "stderr": float(np.mean([x["stderr"] for x in v])),
            "ssim": float(np.mean([x["ssim"] for x in v])),
            "delta_e76_noise": float(np.mean([x["delta_e76_noise"] for x in v])),
        }
    worst, worst_se = mean_se([r["worst_delta_e2000_mean"] for r in rows.values()])
    return {
        "by_light": by,
        "worst_light": max(LIGHTS, key=lambda n: by[n]["delta_e2000_mean"]),
        "worst_delta_e2000_mean": worst,
        "worst_stderr_over_seeds": worst_se,
        "inconstancy_delta_e2000_mean": float(np.mean([r["inconstancy_delta_e2000_mean"] for r in rows.values()])),
        "seconds_per_iteration": float(np.mean([r["seconds_per_iteration"] for r in rows.values()])),
        "command": first["command"],
        "texels": first["texels"],
        "iterations": first["iterations"],
        "seeds": list(rows),
        "per_seed": {str(s): r for s, r in rows.items()},
    }


def paired(entry: dict, base: dict) -> dict:
    """The worst light's mean ΔE2000 of ``entry`` minus ``base``'s, seed by seed (the seeds both have)."""
    seeds = [s for s in entry["per_seed"] if s in base["per_seed"]]
    d = [entry["per_seed"][s]["worst_delta_e2000_mean"] - base["per_seed"][s]["worst_delta_e2000_mean"] for s in seeds]
    m, se = mean_se(d)
    return {"mean": m, "stderr": se, "per_seed": dict(zip(seeds, d))}


def key_of(variant: str) -> str:
    lights, combine = VARIANTS[variant]
    return f"optimised_for_{lights}" + ("" if combine == "mean" else f"_{combine}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--dpi", type=float, default=75.0)
    ap.add_argument("--iterations", type=int, default=40)
    ap.add_argument("--spp", type=int, default=128, help="samples per texel of each scoring render")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seeds", default="0", help="optimisation seeds, comma-separated (inkopt optimize --seed)")
    ap.add_argument("--variants", default=",".join(VARIANTS), help=f"of {', '.join(VARIANTS)}")
    ap.add_argument("--work", default="spectral_lights_spot", help="folder of the run directories")
    ap.add_argument("--out", default="spectral_lights_spot20mm.json", help="results file in experiments/results")
    a = ap.parse_args()
    work, seeds = Path(a.work), [int(s) for s in a.seeds.split(",")]
    work.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    out = {"dpi": a.dpi, "iterations": a.iterations, "spp": a.spp, "height_mm": 20, "inks": "vero-cmykw@spectral"}
    out["optimisation_seeds"] = seeds
    for variant in a.variants.split(","):
        rows = {}
        for seed in seeds:
            cmd = optimise(work, variant, seed, a)
            run = work / run_name(variant, seed)
            rep = json.loads((run / "report.json").read_text())
            r = row([score(run, s, a) for s in (0, 1)])
            r.update(command=" ".join(cmd[1:]), seconds_per_iteration=rep["seconds_per_iteration"])
            rows[seed] = {**r, "texels": rep.get("texels"), "iterations": rep["iterations"]}
        out[key_of(variant)] = entry = over_seeds(rows)
        by, se = entry["by_light"], entry["worst_stderr_over_seeds"]
        print(
            f"{variant:6s}: mean ΔE2000 under D65 {by['D65']['delta_e2000_mean']:.3f}, under A "
            f"{by['A']['delta_e2000_mean']:.3f}; worst {entry['worst_delta_e2000_mean']:.3f} ± {se or 0:.3f} over "
            f"{len(seeds)} seeds; inconstancy D65-A {entry['inconstancy_delta_e2000_mean']:.2f}"
        )
    base = out.get(key_of("D65"))
    for variant in a.variants.split(","):
        if base is not None and variant != "D65":
            out[key_of(variant)]["paired_over_D65"] = p = paired(out[key_of(variant)], base)
            print(f"{variant} - D65, worst light's mean ΔE2000: {p['mean']:+.3f} ± {p['stderr'] or 0:.3f}")
    out.update(wall_s=time.perf_counter() - t0, threads=a.threads, **machine())
    print("wrote", write(a.out, out))


if __name__ == "__main__":
    main()
