"""What `--shell-mm D` does to time, memory and quality. Optimises Spot at 20 mm with
every voxel free and with shells of 1 and 0.5 mm (same seeds and settings), then measures each result's
high-frequency structure ("mottle") against the target's. Writes experiments/results/shell_mm.json and prints a table.

    .venv/bin/python experiments/shell_compare.py [--out bench-out/shell] [--iterations 20] [--shells none,1,0.5]
        [--smooth S]

``--smooth S`` runs the same with that step smoothing (``inkopt optimize --smooth S``; without it, the mesh
default); its results are keyed ``SHELL+smoothS``, the default's ``SHELL``. Entries record ``adjoint_ema`` and
``smooth`` where the report had them; entries without them ran at other defaults (their "note",
docs/experiments.md). The final figures are inkopt's adaptive evaluation (``--eval-spp 0``; entries with 64 spp
have a noise-corrected SSIM ~0.03 low on Spot). Results of shells not run this time are kept from the previous
shell_mm.json.

Runs whose report.json exists are not re-run (delete the folder to redo one). Mottle: with two renders a, b of
independent seeds, each texel's deviation from the mean of its 6 nearest texels (in L*) is formed in both; the
mean of their products estimates the noise-free high-frequency power (the renders' noise is independent, so it
drops out). Compared with the target's own high-frequency power it tells whether a result has texture the
target has not, which the SSIM of `report.json` penalises.
"""

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import STUDY_RESULTS as RESULTS  # noqa: E402
from common import machine
from common import write_study as write

SPOT = Path(__file__).resolve().parents[2] / "shared" / "data" / "spot" / "spot.obj"  # ../shared beside the repo


def high_frequency_power(tex, target_rgb, a_rgb, b_rgb, k: int = 6) -> dict:
    """Noise-free high-frequency power of the prediction (from two independent renders) and of the target, in
    (ΔL*)², over all texels and over the target's flat half (texels whose target power is below the median)."""
    from scipy.spatial import cKDTree

    from inkopt.color import linear_to_lab

    pos = tex.pos_vox.astype(np.float64)
    _, nb = cKDTree(pos).query(pos, k + 1)
    nb = nb[:, 1:]

    def dev(rgb):
        lum = linear_to_lab(np.asarray(rgb, np.float64))[:, 0]
        return lum - lum[nb].mean(1)

    t, a, b = dev(target_rgb), dev(a_rgb), dev(b_rgb)
    flat = t * t <= np.median(t * t)
    return {
        "prediction": float(np.mean(a * b)),
        "target": float(np.mean(t * t)),
        "prediction_flat": float(np.mean((a * b)[flat])),
        "target_flat": float(np.mean((t * t)[flat])),
    }


def structure(run_dir: Path, spp: int, threads: int) -> dict:
    from inkopt.render import Renderer
    from inkopt.rundir import RunDir

    rd = RunDir(run_dir)
    rec = rd.load_scene()
    tex = rec.texels
    target = np.asarray(rec.target_rgb, np.float64)
    vol = rd.load_volume()
    r = Renderer(vol, threads)
    a, b = r.render(tex, spp, seed=2**61 + 1), r.render(tex, spp, seed=2**61 + 2)
    out = high_frequency_power(tex, target, a.rgb, b.rgb)
    # The all-white start for reference (97 % white in every inside voxel, as --init white).
    m = np.zeros(vol.mixture.shape, np.float32)
    n = m.shape[-1]
    m[..., :] = 0.03 / (n - 1)
    m[..., vol.inks.index("white")] = 0.97
    m[~vol.inside_mask()] = 0.0
    r0 = Renderer(vol.with_mixture(m), threads)
    a0, b0 = r0.render(tex, spp, seed=2**61 + 1), r0.render(tex, spp, seed=2**61 + 2)
    out["prediction_start"] = high_frequency_power(tex, target, a0.rgb, b0.rgb)["prediction"]
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="bench-out/shell")
    ap.add_argument("--iterations", type=int, default=20)
    ap.add_argument("--shells", default="none,1,0.5")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--structure-spp", type=int, default=64)
    ap.add_argument("--smooth", type=float)
    ap.add_argument(
        "--eval-spp",
        type=int,
        default=0,
        help="samples of the final evaluation (0, the default: adaptive, as inkopt's own default; 64 spp "
        "biases SSIM low by ~0.03 on Spot)",
    )
    a = ap.parse_args()
    out = Path(a.out)
    previous = RESULTS / "shell_mm.json"
    results = json.loads(previous.read_text())["results"] if previous.is_file() else {}
    tag = f"+smooth{a.smooth:g}" if a.smooth is not None else ""
    for s in a.shells.split(","):
        d = out / f"shell_{s}{tag}"
        if not (d / "report.json").is_file():
            cmd = [
                sys.executable,
                "-m",
                "inkopt",
                "optimize",
                str(SPOT),
                "--height-mm",
                "20",
                "--out",
                str(d),
                "--iterations",
                str(a.iterations),
                "--spp",
                "4",
                "--threads",
                str(a.threads),
                "--seed",
                "0",
                "--resume",
            ] + ([] if s == "none" else ["--shell-mm", s])
            cmd += ["--smooth", str(a.smooth)] if a.smooth is not None else []
            cmd += ["--eval-spp", str(a.eval_spp)] if a.eval_spp else []
            print("$ inkopt " + " ".join(cmd[3:]), flush=True)
            subprocess.run(cmd, check=True)
        rep = json.loads((d / "report.json").read_text())
        results[s + tag] = {
            k: rep[k]
            for k in (
                "free_voxels",
                "inside_voxels",
                "seconds_per_iteration",
                "time_split",
                "peak_rss_gb",
                "initial_delta_e76_mean",
                "delta_e76_mean",
                "delta_e76_p95",
                "delta_e2000_mean",
                "initial_ssim",
                "ssim",
                "iterations",
                "eval_spp",
                "initial_eval_spp",
            )
        }
        # the report's own figures where it has them: noise-corrected mean ΔE76 and mottle (metrics.py)
        results[s + tag].update(
            {
                k: rep[k]
                for k in (
                    "delta_e76_mean_corrected",
                    "mottle_l2",
                    "mottle_l2_target",
                    "flat_texels",
                    "adjoint_ema",
                    "smooth",
                )
                if k in rep
            }
        )
        results[s + tag]["high_frequency_power"] = structure(d, a.structure_spp, a.threads)
    write("shell_mm.json", {"results": results, "mesh": "spot, 20 mm", **machine()})
    print(
        "| shell | free voxels | s/iteration | peak GB | ΔE76 start → end | p95 | ΔE2000 | SSIM start → end "
        "| HF power pred / target (flat half) |\n|---|---|---|---|---|---|---|---|---|"
    )
    for s, r in results.items():
        h = r["high_frequency_power"]
        print(
            f"| {s} | {r['free_voxels']:,} | {r['seconds_per_iteration']:.1f} | {r['peak_rss_gb']:.2f} | "
            f"{r['initial_delta_e76_mean']:.1f} → {r['delta_e76_mean']:.1f} | {r['delta_e76_p95']:.1f} | "
            f"{r['delta_e2000_mean']:.1f} | {r['initial_ssim']:.3f} → {r['ssim']:.3f} | "
            f"{h['prediction_flat']:.2f} / {h['target_flat']:.2f} |"
        )


if __name__ == "__main__":
    main()
