"""A spectral run's print-shop baselines picked from the RGB colour table (the volume's RGB inks, a print shop
without a spectral model) and from the spectral colour table under the run's lights (``evaluation.spectral_table``),
at equal settings and seeds: what changes in the baselines' figures under each light.

The run is experiments/spectral_evaluate.py's colour-chart slab (2.71 x 1.78 x 1 mm, ``vero-cmykw@spectral``,
optimised for D65 and A), made with the same command if --work holds none (``--reuse`` takes the one there). It is
evaluated twice in one process by ``evaluation.spectral.evaluate_lights`` under D65, A and F11 at ``--eval-spp``
samples per scene texel on every texel, nothing written: once with ``EvaluateOptions.table`` = the RGB colour table
(``colour_table`` of the volume's inks, its g and ior), once with the spectral table under the run's lights (what
``evaluate_lights`` picks by default; built first and timed if not cached), both on the lattice of ``--step``
(default: the tables' own). The gamut floors are those of each table's lights (the RGB table's: sRGB, D65). The
continuous and printed results are the same renders in both (same seeds); only the baselines' mixtures differ.

    nice -n 10 .venv/bin/python experiments/spectral_baselines.py [--iterations 150] [--spp 8] [--eval-spp 1024]
        [--work DIR] [--reuse] [--step 4]

Writes experiments/results/spectral_baselines_slab.json: per light the mean ΔE2000 of every result under both
tables, the gamut floors, the spectral table's build seconds, the commands and the machine's load; prints the table.
"""

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import machine  # noqa: E402
from common import write_study as write  # noqa: E402

from inkopt import charts  # noqa: E402
from inkopt.cli import main as cli  # noqa: E402
from inkopt.evaluation.colour_table import colour_table  # noqa: E402
from inkopt.evaluation.options import EvaluateOptions  # noqa: E402
from inkopt.evaluation.spectral import evaluate_lights  # noqa: E402
from inkopt.evaluation.spectral_table import spectral_patches  # noqa: E402
from inkopt.model.inks import read_ink_file  # noqa: E402
from inkopt.model.spectral import spectral_from_data  # noqa: E402
from inkopt.rundir import RunDir  # noqa: E402
from inkopt.spectral.lights import parse_lights  # noqa: E402
from inkopt.spectral.viewing import Viewing  # noqa: E402

RESULTS = ("continuous", "quantized", "surface", "extrusion")
LIGHTS = "D65,A,F11"


def _make_run(run: Path, a) -> list:
    """The chart slab run of experiments/spectral_evaluate.py (its command)."""
    chart = charts.save(charts.colour_chart(128, 84), run.parent / "chart.png")
    cmd = ["slab", chart, "--size-mm", "2.71x1.78x1", "--out", run, "--iterations", a.iterations, "--spp", a.spp]
    cmd += ["--threads", a.threads, "--inks", "vero-cmykw@spectral", "--illuminants", "D65,A"]
    if cli([str(x) for x in cmd]) != 0:
        raise SystemExit("inkopt slab failed")
    return cmd


def _figures(ev: dict) -> dict:
    """Per light, each result's mean ΔE2000 and its estimated noise contribution to the mean ΔE76."""
    return {
        light: {
            r: {
                "delta_e2000_mean": ev[r]["by_light"][light]["delta_e2000_mean"],
                "delta_e76_noise_contribution": ev[r]["by_light"][light]["delta_e76_noise_contribution"],
            }
            for r in RESULTS
            if r in ev
        }
        for light in LIGHTS.split(",")
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--iterations", type=int, default=150)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--eval-spp", type=int, default=1024)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--work", default="spectral_evaluate_runs", help="folder of the run directory")
    ap.add_argument("--reuse", action="store_true", help="evaluate the run already in --work again")
    ap.add_argument("--step", type=int, default=None, help="both tables' lattice step (default: the tables' own, 8)")
    a = ap.parse_args()
    run = Path(a.work) / "slab"
    run.parent.mkdir(parents=True, exist_ok=True)
    reuse = a.reuse and (run / "volume.npz").is_file()
    make = None if reuse else _make_run(run, a)
    d = RunDir(run)
    table = spectral_from_data(read_ink_file(d.spectral_inks_path), d.spectral_inks_path)
    options = EvaluateOptions(spp=a.eval_spp, texel_sample=0, threads=a.threads, write=False)
    vol = d.load_volume()
    t0 = time.perf_counter()
    patches = spectral_patches(table, vol.g, vol.ior, step=a.step, threads=a.threads)
    table_seconds = time.perf_counter() - t0
    run_lights = Viewing(table, parse_lights(",".join(d.read_report()["viewing"]["illuminants"])))
    spectral_table = patches.under(run_lights.colours())  # what evaluate_lights picks the baselines from
    rgb_table = colour_table(vol.inks, vol.g, vol.ior, step=a.step, threads=a.threads)
    del vol
    out, seconds = {}, {}
    for kind, t in (("rgb_table", rgb_table), ("spectral_table", spectral_table)):
        t0 = time.perf_counter()
        ev = evaluate_lights(run, replace(options, table=t), LIGHTS, print)
        seconds[kind] = time.perf_counter() - t0
        out[kind] = {
            "figures": _figures(ev),
            "gamut_floor": ev["gamut_floor"],
            "colour_table": ev["colour_table"],
            "print_beats_baselines": ev["print_beats_baselines"],
        }
    result = {
        "scene": "colour-chart slab 2.71 x 1.78 x 1 mm, vero-cmykw@spectral, optimised for D65,A",
        "optimisation_reused": reuse,
        "commands": [
            "python experiments/spectral_baselines.py " + " ".join(sys.argv[1:]),
            *([] if make is None else ["inkopt " + " ".join(str(x) for x in make)]),
        ],
        "eval_spp": a.eval_spp,
        "step": patches.step,
        "lights": LIGHTS.split(","),
        **out,
        "spectral_table_build": {
            "patches": len(patches.mixtures),
            "cached": patches.cached,
            "build_seconds": patches.seconds,
            "seconds_here": table_seconds,
            "rgb_table_build_seconds": rgb_table.seconds,
        },
        "seconds": seconds,
        "threads": a.threads,
        **machine(),
    }
    print("light | result | RGB table | spectral table")
    for light in LIGHTS.split(","):
        for r in RESULTS:
            x, y = (out[k]["figures"][light][r]["delta_e2000_mean"] for k in ("rgb_table", "spectral_table"))
            print(f"{light} | {r} | {x:.2f} | {y:.2f}")
    name = "spectral_baselines_slab" + ("" if a.step is None else f"_step{a.step}") + ".json"
    print("wrote", write(name, result))


if __name__ == "__main__":
    main()
