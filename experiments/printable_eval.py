"""Printable output: optimise the zebra chart (1 mm slab, stripes of 30/15/10/5/3/1 voxels), a colour
picture (scikit-image's astronaut) and the reference slab (15 x 10 x 2.5 mm, colour chart on top, zebra
below), quantize each with blue-noise and with random draws, and evaluate against the surface and extrusion
baselines. Writes experiments/results/printable.json and prints a markdown table.

    .venv/bin/python experiments/printable_eval.py [--iterations N] [--spp 0] [--out bench-out]
        [--cases zebra,astronaut,reference] [--init white|surface|extrusion] [--lr X] [--smooth S] [--grad-spp N]
        [--decay F] [--adjoint-ema W]

``--spp 0`` (the default) evaluates noise-free: ``inkopt evaluate`` without ``--spp`` renders adaptively until
the Monte Carlo noise adds at most 0.5 to each result's mean ΔE76; ``--spp N`` renders exactly N spp. Every case
records its mode (``eval_mode``, ``eval_spp``). A run directory's evaluations are reused only if made in the
requested mode.

A start other than the default all-white one, or an iteration count, step size, smoothing, gradient spp, step
decay or adjoint average given explicitly, is recorded as its own case ("zebra@extrusion", "zebra@extrusion,lr1",
"zebra@smooth0.7,spp8", "zebra@200it,decay0"); cases not run keep their earlier entries in printable.json.
"""

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import STUDY_RESULTS as RESULTS  # noqa: E402
from common import machine
from common import write_study as write

from inkopt import charts  # noqa: E402
from inkopt.optim import OptimizeConfig  # noqa: E402

INKOPT = [sys.executable, "-m", "inkopt.cli"]
VOX = 25.4 / 300


def run(args):
    print("$ inkopt " + " ".join(args), flush=True)
    subprocess.run(INKOPT + args, check=True)


def eval_mode(ev: dict) -> str:
    """'adaptive' or 'fixed N spp', from an evaluation.json."""
    return "adaptive" if ev.get("spp_adaptive") else f"fixed {ev.get('spp')} spp"


def de76(m: dict) -> float:
    """The noise-corrected mean ΔE76 where the evaluation has it, else the plain mean."""
    v = m.get("delta_e76_mean_corrected")
    return m["delta_e76_mean"] if v is None else v


def verdict(name: str, bn: dict) -> str:
    """Does the blue-noise quantized print beat both baselines in ΔE76 (noise-corrected), ΔE2000 and SSIM, and is
    it within 1 ΔE76 of the continuous result?"""
    q, c = bn["quantized"], bn["continuous"]
    lines, met = [], True
    for b in ("surface", "extrusion"):
        m = bn["baselines"][b]
        won = [de76(q) < de76(m), q["delta_e2000_mean"] < m["delta_e2000_mean"], q["ssim"] > m["ssim"]]
        figs = (
            f"ΔE76 {de76(q):.2f} vs {de76(m):.2f}, ΔE2000 {q['delta_e2000_mean']:.2f} vs "
            f"{m['delta_e2000_mean']:.2f}, SSIM {q['ssim']:.3f} vs {m['ssim']:.3f}"
        )
        lines.append(f"{b}: {'beats' if all(won) else 'does NOT beat'} ({sum(won)}/3; {figs})")
        met = met and all(won)
    gap = de76(q) - de76(c)
    lines.append(f"{'within' if gap <= 1.0 else 'NOT within'} 1 ΔE76 of the continuous result ({gap:+.2f})")
    met = met and gap <= 1.0
    return f"- {name} [{eval_mode(bn)}]: target {'met' if met else 'NOT met'}: quantized (blue-noise) " + "; ".join(
        lines
    )


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--iterations", type=int, help="(default: the CLI's)")
    ap.add_argument(
        "--spp",
        type=int,
        default=0,
        help="evaluation spp, used exactly; 0 (default): adaptive, noise adds at most 0.5 to mean ΔE76",
    )
    ap.add_argument("--out", default="bench-out")
    ap.add_argument("--cases", default="zebra,astronaut,reference")
    ap.add_argument("--init", default="white", help="the optimisation's start (inkopt slab --init)")
    ap.add_argument("--lr", type=float, help="step size (inkopt slab --lr; default: the optimiser's)")
    ap.add_argument("--smooth", type=float, help="step smoothing width (inkopt slab --smooth; default: the CLI's)")
    ap.add_argument("--grad-spp", type=int, help="gradient samples per texel (inkopt slab --spp; default: the CLI's)")
    ap.add_argument("--decay", type=float, help="step decay fraction (inkopt slab --decay; default: the CLI's)")
    ap.add_argument(
        "--adjoint-ema",
        type=float,
        help="adjoint running-average weight (inkopt slab --adjoint-ema; default: the CLI's)",
    )
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(exist_ok=True)
    from skimage import data
    from skimage.transform import resize

    cases = {
        # 180 x 60 texels at 300 DPI: every stripe width in voxels exactly, 1 mm thick (the paper's zebra slab).
        "zebra": lambda: (
            charts.save(charts.zebra(180, 60), out / "zebra.png"),
            f"{180 * 25.4 / 300:.4f}x{60 * 25.4 / 300:.4f}x1.0",
            [],
        ),
        "astronaut": lambda: (
            charts.save(
                (resize(data.astronaut(), (236, 236), anti_aliasing=True) * 255).astype(np.uint8), out / "astronaut.png"
            ),
            "10x10x2",
            [],
        ),
        # The reference slab (bench/bench_optimize.py): 177 x 118 x 30 voxels, colour chart on top (4 px
        # per voxel), zebra below.
        "reference": lambda: (
            charts.save(charts.colour_chart(708, 472), out / "reference_top.png"),
            f"{177 * VOX:.4f}x{118 * VOX:.4f}x{30 * VOX:.4f}",
            ["--bottom", str(charts.save(charts.zebra(177, 118), out / "reference_bottom.png"))],
        ),
    }
    mode = "adaptive" if a.spp == 0 else f"fixed {a.spp} spp"
    previous = RESULTS / "printable.json"
    results = json.loads(previous.read_text())["results"] if previous.is_file() else {}
    for r in results.values():  # entries that do not record the mode
        if "blue-noise" in r:
            r.setdefault("eval_mode", eval_mode(r["blue-noise"]))
            r.setdefault("eval_spp", None if r["blue-noise"].get("spp_adaptive") else r["blue-noise"].get("spp"))
    for case in a.cases.split(","):
        img, size, extra = cases[case]()
        tags = (
            ([f"{a.iterations}it"] if a.iterations is not None else [])
            + ([a.init] if a.init != "white" else [])
            + ([f"lr{a.lr:g}"] if a.lr is not None else [])
            + ([f"smooth{a.smooth:g}"] if a.smooth is not None else [])
            + ([f"spp{a.grad_spp}"] if a.grad_spp is not None else [])
            + ([f"decay{a.decay:g}"] if a.decay is not None else [])
            + ([f"ema{a.adjoint_ema:g}"] if a.adjoint_ema is not None else [])
        )
        name = case + ("@" + ",".join(tags) if tags else "")
        d = out / name.replace("@", "-").replace(",", "-")
        if not (d / "report.json").is_file():
            run(
                ["slab", str(img)]
                + extra
                + ["--size-mm", size, "--out", str(d), "--resume", "--init", a.init]
                + (["--iterations", str(a.iterations)] if a.iterations is not None else [])
                + (["--lr", str(a.lr)] if a.lr is not None else [])
                + (["--smooth", str(a.smooth)] if a.smooth is not None else [])
                + (["--spp", str(a.grad_spp)] if a.grad_spp is not None else [])
                + (["--decay", str(a.decay)] if a.decay is not None else [])
                + (["--adjoint-ema", str(a.adjoint_ema)] if a.adjoint_ema is not None else [])
            )
        results[name] = {
            "report": json.loads((d / "report.json").read_text()),
            "eval_mode": mode,
            "eval_spp": a.spp or None,
        }
        for method in ("blue-noise", "random"):
            done = d / f"evaluation_{method}.json"
            if done.is_file() and eval_mode(json.loads(done.read_text())) == mode:  # an earlier, interrupted run
                results[name][method] = json.loads(done.read_text())
                continue
            run(["quantize", str(d), "--method", method])
            run(["evaluate", str(d), "--method", method] + (["--spp", str(a.spp)] if a.spp else []))
            ev = json.loads((d / "evaluation.json").read_text())
            shutil.copy(d / "evaluation.json", done)
            results[name][method] = ev
        results[name] = {k: results[name][k] for k in ("report", "random", "blue-noise", "eval_mode", "eval_spp")}
        results[name]["iterations"] = results[name]["report"].get("iterations")
        write(
            "printable.json",
            {
                "results": results,
                "iterations": a.iterations or OptimizeConfig().iterations,
                "eval_spp": a.spp,
                "eval_mode": mode,
                **machine(),
            },
        )
    keys = ("delta_e76_mean", "delta_e76_mean_corrected", "delta_e76_p95", "delta_e2000_mean", "ssim", "mottle_l2")

    def fmt(m, k):
        v = m.get(k)
        return "–" if v is None else f"{v:.3f}" if k == "ssim" else f"{v:.2f}"

    print(
        "| case | result | ΔE76 mean | ΔE76 (noise-corrected) | ΔE76 p95 | ΔE2000 mean | SSIM | mottle (ΔL*)² |"
        "\n|---|---|---|---|---|---|---|---|"
    )
    for name, r in results.items():
        bn, rnd = r["blue-noise"], r["random"]
        rows = [
            ("optimised (continuous)", bn["continuous"]),
            ("optimised, blue-noise quantized", bn["quantized"]),
            ("optimised, random quantized", rnd["quantized"]),
            ("surface baseline (blue-noise)", bn["baselines"]["surface"]),
            ("extrusion baseline (blue-noise)", bn["baselines"]["extrusion"]),
        ]
        for label, m in rows:
            print(f"| {name} [{eval_mode(bn)}] | {label} | " + " | ".join(fmt(m, k) for k in keys) + " |")
    print()
    for name, r in results.items():
        floor = r["blue-noise"].get("gamut_floor_delta_e76")
        print(verdict(name, r["blue-noise"]) + (f"; gamut floor {floor:.2f} ΔE76" if floor is not None else ""))


if __name__ == "__main__":
    main()
