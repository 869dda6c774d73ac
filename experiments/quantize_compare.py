"""Compare the quantization methods (blue-noise, random, error-diffusion) on optimised charts.

For each case, optimise a slab (``inkopt slab``, reused when its report exists), then quantize it with every method
under the same settings (600 x 300 DPI, 27 um layers, nearest upsampling, seed 0) and evaluate the printed result
(``evaluate_run``, adaptive noise-free sampling, no baselines: they do not depend on our quantization). Writes
experiments/results/quantize_compare.json and prints a markdown table.

    .venv/bin/python experiments/quantize_compare.py [--iterations 60] [--out bench-out/quantize] [--cases demo,zebra]
        [--methods blue-noise,random,error-diffusion] [--upsample nearest]

Cases: ``demo`` (the demo's 6 x 4 x 1 mm slab: colour chart on top, zebra below), ``zebra`` (the paper's zebra,
180 x 60 texels, 1 mm), ``astronaut`` (scikit-image's astronaut, 10 x 10 x 2 mm). Cases not run keep their
earlier entries.
"""

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import STUDY_RESULTS as RESULTS  # noqa: E402
from common import machine
from common import write_study as write

from inkopt import charts  # noqa: E402
from inkopt.evaluation.evaluate import evaluate_run  # noqa: E402
from inkopt.evaluation.options import EvaluateOptions  # noqa: E402
from inkopt.model import Quantization  # noqa: E402
from inkopt.printing.dithers import METHODS  # noqa: E402
from inkopt.printing.quantize import quantize_volume  # noqa: E402
from inkopt.rundir import RunDir  # noqa: E402

KEYS = ("delta_e76_mean", "delta_e76_mean_corrected", "delta_e2000_mean", "ssim", "mottle_l2")


def cases(out: Path) -> dict:
    """name -> (slab arguments: top image, [--bottom image], size)."""

    def astronaut():
        from skimage import data
        from skimage.transform import resize

        img = (resize(data.astronaut(), (236, 236), anti_aliasing=True) * 255).astype(np.uint8)
        return [str(charts.save(img, out / "astronaut.png")), "--size-mm", "10x10x2"]

    return {
        "demo": lambda: [
            str(charts.save(charts.colour_chart(288, 192), out / "chart.png")),
            "--bottom",
            str(charts.save(charts.zebra(71, 47), out / "zebra_demo.png")),
            "--size-mm",
            "6x4x1",
        ],
        "zebra": lambda: [
            str(charts.save(charts.zebra(180, 60), out / "zebra.png")),
            "--size-mm",
            f"{180 * 25.4 / 300:.4f}x{60 * 25.4 / 300:.4f}x1.0",
        ],
        "astronaut": astronaut,
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--iterations", type=int, default=60)
    ap.add_argument("--out", default="bench-out/quantize")
    ap.add_argument("--cases", default="demo,zebra")
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--upsample", default="nearest")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    previous = RESULTS / "quantize_compare.json"
    results = json.loads(previous.read_text())["results"] if previous.is_file() else {}
    make = cases(out)
    for case in a.cases.split(","):
        d = out / case
        if not (d / "report.json").is_file():
            cmd = [
                sys.executable,
                "-m",
                "inkopt.cli",
                "slab",
                *make[case](),
                "--out",
                str(d),
                "--iterations",
                str(a.iterations),
                "--resume",
            ]
            print("$ inkopt " + " ".join(cmd[3:]), flush=True)
            subprocess.run(cmd, check=True)
        vol = RunDir(d).load_volume()
        res = results.setdefault(case, {})
        res["report"] = {
            k: v for k, v in json.loads((d / "report.json").read_text()).items() if isinstance(v, (int, float, str))
        }
        for method in a.methods.split(","):
            t0 = time.perf_counter()
            q = quantize_volume(vol, Quantization(method, upsample=a.upsample))
            tq = time.perf_counter() - t0
            RunDir(d).save_quantized(q)
            ev = evaluate_run(d, EvaluateOptions(method=method, baselines=False, write=False)).to_json()
            res["continuous"] = {k: ev["continuous"].get(k) for k in KEYS}
            res[method] = {
                **{k: ev["quantized"].get(k) for k in KEYS},
                "quantize_seconds": tq,
                "spp": ev["quantized"].get("spp"),
                "upsample": a.upsample,
            }
            print(
                f"{case} {method}: "
                + ", ".join(f"{k} {res[method][k]:.4f}" for k in KEYS if res[method][k] is not None),
                flush=True,
            )
            write("quantize_compare.json", {"results": results, "iterations": a.iterations, **machine()})
    print_table(results)


def print_table(results: dict) -> None:
    print("| case | result | ΔE76 mean | ΔE76 (noise-corrected) | ΔE2000 mean | SSIM | mottle (ΔL*)² |")
    print("|---|---|---|---|---|---|---|")
    for case, r in results.items():
        for name in ("continuous", *METHODS):
            if name in r:
                f = r[name]
                cells = " | ".join(
                    "-" if f.get(k) is None else f"{f[k]:.3f}" if k == "ssim" else f"{f[k]:.2f}" for k in KEYS
                )
                print(f"| {case} | {name} | {cells} |")


if __name__ == "__main__":
    main()
