"""Two lights on Spot through the command line: is a print optimised with ``--illuminants D65,A`` better under its
worse light than one optimised for D65 alone?

Spot (python/inkopt/data/spot) 20 mm high, ``--inks vero-cmykw@spectral`` (the library's spectral form), the same
seed and settings for every run (``--iterations N --stop-gain 0``, the default optimiser): ``--illuminants D65``,
``--illuminants D65,A`` (the mean of the two losses) and ``--illuminants D65,A --combine worst``; each result then
scored by ``inkopt evaluate --illuminants D65,A --spp S`` at two render seeds (0 and 1): the two seeds' difference
gives the Monte Carlo noise of each mean ΔE2000 (standard error of their average = |difference| / 2, a one-pair
estimate).

    nice -n 5 python experiments/spectral_lights_cli.py [--dpi 75] [--iterations 40] [--spp 128] [--work DIR]

A run directory under ``--work`` that already holds a report.json of the same command is reused (so an interrupted
study resumes). Writes experiments/results/spectral_lights_spot20mm.json and prints the table.
"""

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import machine  # noqa: E402
from common import write_study as write  # noqa: E402

SPOT = Path(__file__).resolve().parents[1] / "python" / "inkopt" / "data" / "spot" / "spot.obj"
#: (lights, how their losses combine, the run directory's name)
VARIANTS = (("D65", "mean", "D65"), ("D65,A", "mean", "D65_A"), ("D65,A", "worst", "worst"))


def optimise(work: Path, lights: str, combine: str, name: str, a) -> list[str]:
    out = work / name
    cmd = [sys.executable, "-m", "inkopt", "optimize", str(SPOT), "--height-mm", "20", "--dpi", str(a.dpi)]
    cmd += ["--iterations", str(a.iterations), "--stop-gain", "0", "--inks", "vero-cmykw@spectral"]
    cmd += ["--illuminants", lights, "--combine", combine, "--eval-spp", "16", "--threads", str(a.threads)]
    cmd += ["--out", str(out)]
    if not (out / "report.json").is_file():
        subprocess.run(cmd, check=True)
    return cmd


def evaluate(work: Path, name: str, seed: int, a) -> dict:
    run = work / name
    path = work / f"eval_{run.name}_s{seed}.json"
    if not path.is_file():
        cmd = [sys.executable, "-m", "inkopt", "evaluate", str(run), "--illuminants", "D65,A", "--spp", str(a.spp)]
        cmd += ["--seed", str(seed), "--threads", str(a.threads), "--json"]
        path.write_text(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
    return json.loads(path.read_text())["continuous"]


def row(evals: list[dict]) -> dict:
    """Per light the mean ΔE2000 of the two seeds' renders and its standard error, the worst light, SSIM."""
    out = {}
    for light in ("D65", "A"):
        v = [e["by_light"][light]["delta_e2000_mean"] for e in evals]
        out[light] = {
            "delta_e2000_mean": sum(v) / 2,
            "stderr": abs(v[0] - v[1]) / 2,
            "per_seed": v,
            "ssim": sum(e["by_light"][light]["ssim"] for e in evals) / 2,
            "delta_e76_noise": evals[0]["by_light"][light]["delta_e76_noise"],
        }
    worst = max(("D65", "A"), key=lambda n: out[n]["delta_e2000_mean"])
    inconstancy = sum(e["inconstancy_delta_e2000_mean"]["D65-A"] for e in evals) / 2
    return {"by_light": out, "worst_light": worst, "inconstancy_delta_e2000_mean": inconstancy}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--dpi", type=float, default=75.0)
    ap.add_argument("--iterations", type=int, default=40)
    ap.add_argument("--spp", type=int, default=128, help="samples per texel of each scoring render")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--work", default="spectral_lights_spot", help="folder of the run directories")
    a = ap.parse_args()
    work = Path(a.work)
    work.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    out = {"dpi": a.dpi, "iterations": a.iterations, "spp": a.spp, "height_mm": 20, "inks": "vero-cmykw@spectral"}
    for lights, combine, name in VARIANTS:
        cmd = optimise(work, lights, combine, name, a)
        rep = json.loads((work / name / "report.json").read_text())
        entry = row([evaluate(work, name, s, a) for s in (0, 1)])
        entry.update(command=" ".join(cmd[1:]), seconds_per_iteration=rep["seconds_per_iteration"])
        entry.update(texels=rep.get("texels"), iterations=rep["iterations"])
        key = f"optimised_for_{lights}" + ("" if combine == "mean" else f"_{combine}")
        out[key] = entry
        by = entry["by_light"]
        print(
            f"optimised for {lights:6s} ({combine}): mean ΔE2000 under D65 {by['D65']['delta_e2000_mean']:.2f} ± "
            f"{by['D65']['stderr']:.2f}, under A {by['A']['delta_e2000_mean']:.2f} ± {by['A']['stderr']:.2f}, worst "
            f"{entry['worst_light']}; inconstancy D65-A {entry['inconstancy_delta_e2000_mean']:.2f}"
        )
    out.update(wall_s=time.perf_counter() - t0, threads=a.threads, **machine())
    print("wrote", write("spectral_lights_spot20mm.json", out))


if __name__ == "__main__":
    main()
