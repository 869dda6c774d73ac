"""An extended ink set end to end. The same target (the colour chart on a 6 x 4 x 1 mm slab) optimised,
quantized, exported and evaluated with CMYKW and with CMYKW + orange, same settings and seed. Writes
experiments/results/extended_inks.json and prints a markdown table.

    .venv/bin/python experiments/extended_inks.py [--iterations 100] [--out bench-out/extended_inks]
"""

import argparse
import json
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import machine  # noqa: E402
from common import write_study as write

from inkopt import charts  # noqa: E402

INKOPT = [sys.executable, "-m", "inkopt.cli"]
INK_SETS = {"cmykw": "vero-cmykw", "cmykw+orange": "vero-cmykw+orange"}


def run(args, capture=False):
    print("$ inkopt " + " ".join(args), flush=True)
    res = subprocess.run(INKOPT + args, check=True, capture_output=capture, text=True)
    return res.stdout


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--iterations", type=int, default=100)
    ap.add_argument("--out", default="bench-out/extended_inks")
    ap.add_argument("--printer", default="j850", help="printer profile for the export (slot check, materials)")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    top = charts.save(charts.colour_chart(288, 192), out / "chart.png")
    result = {
        "target": "colour chart, 6 x 4 x 1 mm slab, top face",
        "iterations": a.iterations,
        "printer": a.printer,
        "sets": {},
    }
    for name, inks in INK_SETS.items():
        d = out / name
        run(
            [
                "slab",
                str(top),
                "--size-mm",
                "6x4x1",
                "--out",
                str(d),
                "--inks",
                inks,
                "--iterations",
                str(a.iterations),
                "--seed",
                "0",
            ]
        )
        run(["quantize", str(d)])
        run(["export", str(d), "--printer", a.printer])
        ev = json.loads(run(["evaluate", str(d), "--json"], capture=True))
        manifest = json.loads((d / "slices" / "manifest.json").read_text())
        result["sets"][name] = {
            "inks": inks,
            "continuous": ev["continuous"],
            "quantized": ev["quantized"],
            "baselines": ev.get("baselines", {}),
            "gamut_floor_delta_e76": ev.get("gamut_floor_delta_e76"),
            "materials": [
                {k: m.get(k) for k in ("ink", "material", "hex", "voxel_count")} for m in manifest["materials"]
            ],
            "slices": manifest["layer_count"],
        }
    result["machine"] = machine()
    print("wrote", write("extended_inks.json", result))
    keys = ("delta_e76_mean_corrected", "delta_e2000_mean", "ssim")
    print("| ink set | gamut floor ΔE76 | continuous ΔE76 / ΔE2000 / SSIM | quantized ΔE76 / ΔE2000 / SSIM |")
    print("|---|---|---|---|")
    for name, r in result["sets"].items():
        c, q = (" / ".join(f"{r[k][m]:.3g}" for m in keys) for k in ("continuous", "quantized"))
        print(f"| {name} | {r['gamut_floor_delta_e76']:.2f} | {c} | {q} |")


if __name__ == "__main__":
    main()
