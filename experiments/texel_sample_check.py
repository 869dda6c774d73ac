"""Do the figures of a texel-sampled evaluation agree with the full evaluation within their standard errors?

    .venv/bin/python experiments/texel_sample_check.py RUN_DIR [--spp 32] [--seeds 8] [--texel-sample 2000]
        [--sample-windows 40] [--name NAME]

One full evaluation of RUN_DIR (every texel, ``--spp`` fixed, seed 0) and ``--seeds`` sampled ones (seeds 0, 1,
...: each its own texel sample and render seeds) at the same spp (``evaluation.sample``). For each result and
figure: every seed's z = (sampled - full) / its standard error, and the same for the paired differences (``a - b``
against the full evaluation's a minus b). If the standard errors are right, z is about standard normal: its mean
near 0, its RMS near 1, |z| > 2 in ~5 % of cases. Writes experiments/results/texel_sample_check_NAME.json (NAME:
the run folder's name).
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import machine  # noqa: E402
from common import write_study as write

from inkopt.evaluation.evaluate import evaluate_run  # noqa: E402
from inkopt.evaluation.options import EvaluateOptions  # noqa: E402

FIGURES = ("delta_e76_mean", "delta_e76_mean_corrected", "delta_e2000_mean", "delta_e76_p95", "ssim", "mottle_l2")
PAIRED = ("delta_e76_mean", "delta_e76_mean_corrected", "delta_e2000_mean", "ssim")


def rows(ev: dict) -> dict:
    return {"continuous": ev["continuous"], "quantized": ev["quantized"], **(ev.get("baselines") or {})}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run")
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--texel-sample", type=int, default=2000)
    ap.add_argument("--sample-windows", type=int, default=40)
    ap.add_argument("--threads", type=int)
    ap.add_argument("--name")
    args = ap.parse_args()
    t0 = time.perf_counter()
    full = evaluate_run(
        args.run, EvaluateOptions(spp=args.spp, texel_sample=0, threads=args.threads, write=False)
    ).to_json()
    full_seconds = time.perf_counter() - t0
    f = rows(full)
    z = {name: {k: [] for k in FIGURES} for name in f}
    zp, runs = {}, []
    for seed in range(args.seeds):
        t0 = time.perf_counter()
        options = EvaluateOptions(
            spp=args.spp,
            seed=seed,
            texel_sample=args.texel_sample,
            sample_windows=args.sample_windows,
            threads=args.threads,
            write=False,
        )
        ev = evaluate_run(args.run, options).to_json()
        runs.append({"seed": seed, "seconds": time.perf_counter() - t0, "texel_sample": ev["texel_sample"]})
        for name, r in rows(ev).items():
            for k in FIGURES:
                se = r["stderr"].get(k)
                if r.get(k) is not None and f[name].get(k) is not None and se:
                    z[name][k].append((r[k] - f[name][k]) / se)
        for pair, figs in ev["differences"].items():
            a, b = pair.split(" - ")
            for k in PAIRED:
                zp.setdefault(pair, {}).setdefault(k, []).append(
                    (figs[k]["value"] - (f[a][k] - f[b][k])) / figs[k]["stderr"]
                )
        print(seed, {n: np.round([v[-1] for v in z[n].values() if v], 2).tolist() for n in z}, flush=True)
    every = np.array([v for d in (*z.values(), *zp.values()) for vs in d.values() for v in vs])
    res = {
        "run": str(Path(args.run).resolve()),
        "spp": args.spp,
        "seeds": args.seeds,
        "texel_sample": args.texel_sample,
        "sample_windows": args.sample_windows,
        "population": full["texels"],
        "full": {name: {k: r.get(k) for k in FIGURES} for name, r in f.items()},
        "full_seconds": full_seconds,
        "z": z,
        "z_paired": zp,
        "summary": {
            "count": len(every),
            "mean": float(every.mean()),
            "rms": float(np.sqrt(np.mean(every**2))),
            "share_above_2": float(np.mean(np.abs(every) > 2)),
            "max_abs": float(np.abs(every).max()),
        },
        "sampled_runs": runs,
        **machine(),
    }
    print(res["summary"])
    print("wrote", write(f"texel_sample_check_{args.name or Path(args.run).name}.json", res))


if __name__ == "__main__":
    main()
