"""Issue "printable output": optimise the zebra chart (1 mm slab, stripes of 30/15/10/5/3/1 voxels) and a colour
picture (scikit-image's astronaut), quantize each with blue-noise and with random draws, and evaluate against the
surface and extrusion baselines. Writes bench/results/printable.json and prints a markdown table.

    .venv/bin/python bench/printable_eval.py [--iterations 200] [--spp 256] [--out bench-out]
        [--cases zebra,astronaut] [--init white|surface|extrusion] [--lr X]

A start other than the default all-white one, or a step size other than the default, is recorded as its own case
("zebra@extrusion", "zebra@extrusion,lr1"); cases not run keep their earlier entries in printable.json.
"""
import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import RESULTS, machine, write  # noqa: E402

from inkopt import charts  # noqa: E402

INKOPT = [sys.executable, "-m", "inkopt.cli"]


def run(args):
    print("$ inkopt " + " ".join(args), flush=True)
    subprocess.run(INKOPT + args, check=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--iterations", type=int, default=200)
    ap.add_argument("--spp", type=int, default=256, help="evaluation spp")
    ap.add_argument("--out", default="bench-out")
    ap.add_argument("--cases", default="zebra,astronaut")
    ap.add_argument("--init", default="white", help="the optimisation's start (inkopt slab --init)")
    ap.add_argument("--lr", type=float, help="step size (inkopt slab --lr; default: the optimiser's)")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(exist_ok=True)
    from skimage import data
    from skimage.transform import resize

    cases = {
        # 180 x 60 texels at 300 DPI: every stripe width in voxels exactly, 1 mm thick (the paper's zebra slab).
        "zebra": (charts.save(charts.zebra(180, 60), out / "zebra.png"), f"{180 * 25.4 / 300:.4f}x{60 * 25.4 / 300:.4f}x1.0"),
        "astronaut": (charts.save((resize(data.astronaut(), (236, 236), anti_aliasing=True) * 255).astype(np.uint8),
                                  out / "astronaut.png"), "10x10x2"),
    }
    previous = RESULTS / "printable.json"
    results = json.loads(previous.read_text())["results"] if previous.is_file() else {}
    for case in a.cases.split(","):
        img, size = cases[case]
        tags = ([a.init] if a.init != "white" else []) + ([f"lr{a.lr:g}"] if a.lr is not None else [])
        name = case + ("@" + ",".join(tags) if tags else "")
        d = out / name.replace("@", "-").replace(",", "-")
        if not (d / "report.json").is_file():
            run(["slab", str(img), "--size-mm", size, "--out", str(d), "--iterations", str(a.iterations), "--resume",
                 "--init", a.init] + (["--lr", str(a.lr)] if a.lr is not None else []))
        results[name] = {"report": json.loads((d / "report.json").read_text())}
        for method in ("random", "blue-noise"):
            if (d / f"evaluation_{method}.json").is_file():  # done in an earlier, interrupted run
                results[name][method] = json.loads((d / f"evaluation_{method}.json").read_text())
                continue
            run(["quantize", str(d), "--method", method])
            run(["evaluate", str(d), "--spp", str(a.spp), "--method", method])
            ev = json.loads((d / "evaluation.json").read_text())
            shutil.copy(d / "evaluation.json", d / f"evaluation_{method}.json")
            results[name][method] = ev
    write("printable.json", {"results": results, "iterations": a.iterations, "eval_spp": a.spp, **machine()})
    keys = ("delta_e76_mean", "delta_e76_p95", "delta_e2000_mean", "ssim")
    print("| case | result | ΔE76 mean | ΔE76 p95 | ΔE2000 mean | SSIM |\n|---|---|---|---|---|---|")
    for name, r in results.items():
        bn, rnd = r["blue-noise"], r["random"]
        rows = [("optimised (continuous)", bn["continuous"]), ("optimised, blue-noise quantized", bn["quantized"]),
                ("optimised, random quantized", rnd["quantized"]),
                ("surface baseline (blue-noise)", bn["baselines"]["surface"]),
                ("extrusion baseline (blue-noise)", bn["baselines"]["extrusion"])]
        for label, m in rows:
            print(f"| {name} | {label} | " + " | ".join(f"{m[k]:.3f}" if k == "ssim" else f"{m[k]:.2f}" for k in keys) + " |")


if __name__ == "__main__":
    main()
