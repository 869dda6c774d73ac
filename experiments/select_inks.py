"""Successive halving vs brute force for ink-set selection, on the paper's setup (candidates cyan,
cyan2, magenta, magenta2, yellow, yellow2 choose 4, always black and white: 15 sets) on small slabs (6 x 4 x 1 mm
at 300 DPI: 71 x 47 x 12 voxels, 3337 top-face texels). Both strategies run every set with the same settings and
seed; halving's final runs are resumed and continue exactly, so its winner's loss equals brute force's run of the
same set. Halving's rule is ``inkopt.inksets.search.RULE`` (recorded in the results; rung evaluations at 16 spp).
Writes experiments/results/select_inks.json and prints a markdown table.

    .venv/bin/python experiments/select_inks.py [--charts colour,astronaut] [--iterations 80] [--workers 2]
        [--out bench-out/select_inks] [--suffix _NAME]

Work is counted in texel-samples (iterations x texels x (spp + forward spp) + evaluation renders).
"""

import argparse
import shutil
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import machine  # noqa: E402
from common import write_study as write

from inkopt import charts  # noqa: E402
from inkopt.inksets import Selection, make_backend, run_selection  # noqa: E402
from inkopt.inksets.search import RULE  # noqa: E402
from inkopt.optim import OptimizeConfig  # noqa: E402
from inkopt.scenes.spec import SlabSpec  # noqa: E402

CANDIDATES = "cyan,cyan2,magenta,magenta2,yellow,yellow2"
PAPER_WINNER = ["cyan", "magenta", "magenta2", "yellow", "black", "white"]
SIZE_MM, W, H = [6.0, 4.0, 1.0], 71, 47


def chart_picture(name: str, out: Path) -> Path:
    if name == "colour":
        img = charts.colour_chart(W, H)
    elif name == "zebra":
        img = charts.zebra(W, H)
    elif name == "astronaut":
        from skimage import data
        from skimage.transform import resize

        img = (resize(data.astronaut()[:341], (H, W), anti_aliasing=True) * 255).astype(np.uint8)
    else:
        raise SystemExit(f"unknown chart {name}")
    return charts.save(img, out / f"{name}.png")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--charts", default="colour,astronaut")
    ap.add_argument("--iterations", type=int, default=80)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="bench-out/select_inks")
    ap.add_argument("--suffix", default="", help="results file experiments/results/select_inks{SUFFIX}.json")
    args = ap.parse_args()
    out = Path(args.out)
    results = {
        "machine": machine(),
        "candidates": CANDIDATES,
        "choose": 4,
        "always": ["black", "white"],
        "size_mm": SIZE_MM,
        "iterations": args.iterations,
        "workers": args.workers,
        "rule": RULE,
        "charts": {},
    }
    backend = make_backend(args.workers)
    rows = []
    try:
        for name in args.charts.split(","):
            pic = chart_picture(name, out)
            target = SlabSpec(str(pic), tuple(SIZE_MM), dpi=300.0)
            res, secs = {}, {}
            for strategy in ("brute", "halving"):
                d = out / name / strategy
                shutil.rmtree(d, ignore_errors=True)
                sel = Selection(
                    target, CANDIDATES, 4, ["black", "white"], OptimizeConfig(iterations=args.iterations), strategy
                )
                t0 = time.perf_counter()
                res[strategy] = run_selection(sel, d, backend, log=lambda m: print(m, flush=True))
                secs[strategy] = time.perf_counter() - t0
            brute, halv = res["brute"], res["halving"]
            loss_of = {tuple(c["inks"]): c["loss"] for c in brute["candidates"]}
            best = brute["winner"]["loss"]
            gap = 100 * (loss_of[tuple(halv["winner"]["inks"])] - best) / best
            ratio = halv["texel_samples"] / brute["texel_samples"]
            ranked = [c["inks"] for c in brute["candidates"]]
            paper_rank = ranked.index(PAPER_WINNER) + 1
            results["charts"][name] = {
                "brute": brute,
                "halving": halv,
                "seconds": secs,
                "loss_gap_percent": gap,
                "work_ratio": ratio,
                "same_winner": brute["winner"]["inks"] == halv["winner"]["inks"],
                "halving_winner_loss_equals_brute_run": halv["winner"]["loss"]
                == loss_of[tuple(halv["winner"]["inks"])],
                "paper_set_rank": paper_rank,
                "paper_set_gap_percent": 100 * (loss_of[tuple(PAPER_WINNER)] - best) / best,
            }
            rows.append(
                f"| {name} | {','.join(brute['winner']['inks'][:4])} ({best:.5f}) | "
                f"{','.join(halv['winner']['inks'][:4])} ({halv['winner']['loss']:.5f}) | {gap:.2f} % | "
                f"{ratio:.2f} | {paper_rank} / 15 ({results['charts'][name]['paper_set_gap_percent']:+.1f} %) "
                f"| {secs['brute']:.0f} / {secs['halving']:.0f} |"
            )
            write(f"select_inks{args.suffix}.json", results)
    finally:
        backend.close()
    print(
        "| chart | brute-force winner (loss) | halving winner (loss) | loss gap | work ratio | paper's set: rank "
        "(gap) | seconds brute / halving |"
    )
    print("|---|---|---|---|---|---|---|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
