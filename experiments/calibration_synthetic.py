"""The calibration on its own synthetic ground truth: does ``inkopt calibrate`` recover an ink table it never sees
well enough to predict held-out patches within mean ΔE2000 0.5, from measurements with 0.3 ΔE76 noise?

Per trial: the true table is the paper's CMYKW table (``vero-cmykw``) with every σs and σa (per ink and channel)
multiplied by its own random factor in [0.6, 1.6] (albedos stay in [0, 1]); g is 0.4 unless ``--g-true``. The
chart is ``inkopt calibration-chart --inks vero-cmykw``; every patch is rendered by inkopt's Monte Carlo renderer
(the patch's stack as a periodic voxel column under light from the upper hemisphere, ``calibration.stack``,
``--spp`` paths), converted to CIELAB D50 and given Gaussian noise of RMS length 0.3 ΔE76 (0.3/sqrt(3) per
component); then ``inkopt calibrate measured.txt --out fitted.json`` (start: the paper's table, 20 % held out) runs
as a user would run it, timed. Reported: the held-out mean and p95 ΔE2000 against the noisy measurements (what
the command reports) and against the noise-free renders, the fit's residual, the fitted g, the wall time and the
machine's load, and the Monte Carlo noise of the renders in ΔE76.

    .venv/bin/python experiments/calibration_synthetic.py [--trials 3] [--spp 500000] [--g-true 0.4] [--name N]
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import machine  # noqa: E402
from common import write_study as write

from inkopt.calibration import cgats  # noqa: E402
from inkopt.calibration.chart import chart_from_table  # noqa: E402
from inkopt.calibration.measure import rgb_to_lab, rgb_to_lab_jacobian  # noqa: E402
from inkopt.calibration.stack import reflectance_mc  # noqa: E402
from inkopt.color import delta_e2000  # noqa: E402
from inkopt.model import InkTable  # noqa: E402

INKOPT = [sys.executable, "-m", "inkopt.cli"]
NOISE_DE76 = 0.3


def run(args):
    print("$ inkopt " + " ".join(args), flush=True)
    return subprocess.run(INKOPT + args, check=True, capture_output=True, text=True).stdout


def truth_table(seed: int, g: float) -> InkTable:
    paper = InkTable.parse("vero-cmykw")
    rng = np.random.default_rng(1000 + seed)
    fs, fa = rng.uniform(0.6, 1.6, paper.sigma_s.shape), rng.uniform(0.6, 1.6, paper.sigma_a.shape)
    return InkTable(paper.names, paper.sigma_s * fs, paper.sigma_a * fa, g)


def trial(seed: int, out: Path, spp: int, g_true: float) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    run(["calibration-chart", "--inks", "vero-cmykw", "--out", str(out / "chart")])
    table = cgats.read(out / "chart" / "chart.txt")
    chart = chart_from_table(table)
    truth = truth_table(seed, g_true)
    t0 = time.perf_counter()
    mc = [reflectance_mc(st, truth, spp=spp, seed=seed * 1000 + k) for k, st in enumerate(chart.stacks())]
    render_s = time.perf_counter() - t0
    rgb, se = np.array([m for m, _ in mc]), np.array([s for _, s in mc])
    lab = rgb_to_lab(rgb, "D50")
    mc_de = np.sqrt(np.einsum("pij,pj->pi", rgb_to_lab_jacobian(rgb, "D50") ** 2, se**2).sum(1))
    rng = np.random.default_rng(2000 + seed)
    noisy = lab + rng.normal(0.0, NOISE_DE76 / np.sqrt(3), lab.shape)
    col = {f: table.fields.index(f) for f in ("LAB_L", "LAB_A", "LAB_B")}
    for k, row in enumerate(table.rows):
        for c, f in enumerate(("LAB_L", "LAB_A", "LAB_B")):
            row[col[f]] = float(round(noisy[k, c], 3))
    cgats.write(out / "measured.txt", table)
    t0, cpu0 = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
    log = run(["calibrate", str(out / "measured.txt"), "--out", str(out / "fitted.json")])
    wall, cpu1 = time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
    rep = json.loads((out / "fitted.report.json").read_text())
    held = [k for k, p in enumerate(rep["patches"]) if p["held_out"]]
    hold_lab = np.array([rep["patches"][k]["holdout_lab"] for k in held])
    de_true = delta_e2000(hold_lab, lab[held])
    fitted = InkTable.parse(str(out / "fitted.json"))
    return {
        "seed": seed,
        "g_true": g_true,
        "patches": len(chart),
        "held_out": len(held),
        "holdout_mean_de2000_vs_measured": rep["holdout_mean_delta_e2000"],
        "holdout_p95_de2000_vs_measured": rep["holdout_p95_delta_e2000"],
        "holdout_mean_de2000_vs_truth": float(de_true.mean()),
        "holdout_p95_de2000_vs_truth": float(np.percentile(de_true, 95)),
        "fit_mean_de2000": rep["fit_mean_delta_e2000"],
        "g_fitted": rep["g"],
        "calibrate_wall_s": wall,
        "calibrate_cpu_s": cpu,
        "calibrate_fit_s": rep["seconds"],
        "model_evaluations": rep["iterations"],
        "load_average_1min_after": float(os.getloadavg()[0]),
        "render_s": render_s,
        "spp": spp,
        "mc_noise_de76_mean": float(mc_de.mean()),
        "mc_noise_de76_max": float(mc_de.max()),
        "noise_rms_de76": float(np.sqrt(((noisy - lab) ** 2).sum(1).mean())),
        "sigma_ratio_median_abs_log": float(
            np.median(np.abs(np.log(np.concatenate([fitted.sigma_s / truth.sigma_s, fitted.sigma_a / truth.sigma_a]))))
        ),
        "log": log.strip().splitlines(),
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--spp", type=int, default=500_000)
    ap.add_argument("--g-true", type=float, default=0.4)
    ap.add_argument("--out", default="bench-out/calibration_synthetic")
    ap.add_argument("--name", default="calibration_synthetic")
    a = ap.parse_args()
    res = [trial(s, Path(a.out) / f"{a.name}_{s}", a.spp, a.g_true) for s in range(a.trials)]
    for r in res:
        print(
            f"seed {r['seed']}: held-out mean ΔE2000 {r['holdout_mean_de2000_vs_measured']:.3f} (vs measured), "
            f"{r['holdout_mean_de2000_vs_truth']:.3f} (vs truth), p95 {r['holdout_p95_de2000_vs_measured']:.3f}; "
            f"g {r['g_fitted']:.3f}; calibrate {r['calibrate_wall_s']:.0f} s"
        )
    summary = {
        "question": "held-out ΔE2000 of inkopt calibrate on synthetic Monte Carlo measurements with 0.3 ΔE76 noise",
        "machine": machine(),
        "target": "held-out mean ΔE2000 <= 0.5; calibrate <= 600 s on 2 cores",
        "max_holdout_mean_de2000_vs_measured": max(r["holdout_mean_de2000_vs_measured"] for r in res),
        "max_calibrate_wall_s": max(r["calibrate_wall_s"] for r in res),
        "trials": res,
    }
    print(f"wrote {write(a.name + '.json', summary)}")


if __name__ == "__main__":
    main()
