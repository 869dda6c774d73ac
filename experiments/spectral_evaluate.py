"""A spectral run judged under each light: its continuous result, its print and both print-shop baselines, through
the command line (``inkopt slab|optimize``, ``inkopt evaluate``, ``inkopt report``).

Slab (default): the colour chart on a 2.71 x 1.78 x 1 mm slab (as experiments/spectral_lights.py), inks
``vero-cmykw@spectral``, optimised for D65 and A (the mean of their losses). ``--spot-mm H``: Spot
(python/inkopt/data/spot) H mm high instead (``--dpi D``: on a D DPI optimisation grid). The run is evaluated with
``inkopt evaluate RUN --spp N --texel-sample 0`` (every result rendered band by band on every texel at N samples per
scene texel with the evaluation's seeds; the baselines from the cached colour table of the volume's RGB inks) under
D65, A and F11, and its soft-proof page written; the page's size is also measured without its light switch (the same
predictions without band values) to give the growth per light.

    nice -n 5 .venv/bin/python experiments/spectral_evaluate.py [--spot-mm 10] [--dpi 75] [--iterations 40]
        [--spp 8] [--eval-spp 256] [--work DIR] [--reuse]

Writes experiments/results/spectral_evaluate_slab.json (``--spot-mm H``: spectral_evaluate_spot<H>mm.json, with
``--dpi D`` spectral_evaluate_spot<H>mm_<D>dpi.json): the table per light, the commands, the times and the
machine's load; prints the table.
"""

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import machine  # noqa: E402
from common import write_study as write  # noqa: E402

from inkopt import charts  # noqa: E402
from inkopt.cli import main as cli  # noqa: E402
from inkopt.rundir import RunDir  # noqa: E402

SPOT = Path(__file__).resolve().parents[1] / "python" / "inkopt" / "data" / "spot" / "spot.obj"
RESULTS = ("continuous", "quantized", "surface", "extrusion")
LIGHTS = "D65,A,F11"


def _run(argv: list) -> float:
    """One inkopt command (its arguments as strings); its wall seconds."""
    t0 = time.perf_counter()
    argv = [str(a) for a in argv]
    print("$ inkopt " + " ".join(argv), flush=True)
    if cli(argv) != 0:
        raise SystemExit(f"inkopt {argv[0]} failed")
    return time.perf_counter() - t0


def _page_growth(run: Path) -> dict:
    """The page's size with its light switch and without (a copy of the run whose predictions have no band values),
    and the growth per light beyond the first."""
    page = (run / "report.html").stat().st_size
    plain = run.parent / (run.name + "_plain")
    shutil.rmtree(plain, ignore_errors=True)
    shutil.copytree(run, plain)
    d = RunDir(plain)
    pred = d.load_predictions()
    lights = len(pred.bands.lights) + sum(n not in pred.bands.lights for n in ("D65", "A"))
    pred.bands = None
    d.save_predictions(pred)
    _run(["report", plain])
    one = (plain / "report.html").stat().st_size
    shutil.rmtree(plain)
    return {
        "lights": lights,
        "bytes": page,
        "bytes_one_light": one,
        "bytes_per_extra_light": (page - one) / (lights - 1),
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--spot-mm", type=float, default=None, help="Spot this high instead of the slab")
    ap.add_argument("--dpi", type=float, default=None, help="Spot's optimisation grid (default 300 DPI)")
    ap.add_argument("--iterations", type=int, default=40)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--eval-spp", type=int, default=256)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--work", default="spectral_evaluate_runs", help="folder of the run directory")
    ap.add_argument("--reuse", action="store_true", help="evaluate the run already in --work (same settings) again")
    a = ap.parse_args()
    work = Path(a.work)
    work.mkdir(parents=True, exist_ok=True)
    name = "slab" if a.spot_mm is None else f"spot{a.spot_mm:g}mm" + (f"_{a.dpi:g}dpi" if a.dpi else "")
    run = work / name
    reuse = a.reuse and (run / "volume.npz").is_file()
    if not reuse:
        shutil.rmtree(run, ignore_errors=True)
    common = ["--out", run, "--iterations", a.iterations, "--spp", a.spp, "--threads", a.threads]
    common += ["--inks", "vero-cmykw@spectral", "--illuminants", "D65,A"]
    if a.spot_mm is None:
        chart = charts.save(charts.colour_chart(128, 84), work / "chart.png")
        make = ["slab", chart, "--size-mm", "2.71x1.78x1", *common]
    else:
        make = ["optimize", SPOT, "--height-mm", a.spot_mm, *common, *(["--dpi", a.dpi] if a.dpi else [])]
    evaluate = [
        "evaluate",
        run,
        "--spp",
        a.eval_spp,
        "--texel-sample",
        0,
        "--threads",
        a.threads,
        "--illuminants",
        LIGHTS,
    ]
    seconds = {"optimise": None if reuse else _run(make)}
    seconds.update(evaluate=_run(evaluate), report=_run(["report", run]))
    ev = json.loads((run / "evaluation_lights.json").read_text())
    table = {
        light: {r: ev[r]["by_light"][light]["delta_e2000_mean"] for r in RESULTS if r in ev}
        for light in LIGHTS.split(",")
    }
    noise = {r: ev[r]["by_light"]["D65"]["delta_e76_noise"] for r in RESULTS if r in ev}
    out = {
        "scene": name,
        "optimisation_reused": reuse,
        "commands": ["inkopt " + " ".join(str(x) for x in c) for c in (make, evaluate, ["report", run])],
        "delta_e2000_mean": table,
        "delta_e76_noise_per_texel_d65": noise,
        "inconstancy_delta_e2000_mean": {r: ev[r]["inconstancy_delta_e2000_mean"] for r in RESULTS if r in ev},
        "print_beats_baselines": ev["print_beats_baselines"],
        "printer_texels": ev["printer_texels"],
        "page": _page_growth(run),
        "seconds": seconds,
        "threads": a.threads,
        **machine(),
    }
    print("light | " + " | ".join(RESULTS))
    for light, row in table.items():
        print(f"{light} | " + " | ".join(f"{row[r]:.2f}" for r in RESULTS if r in row))
    print("wrote", write(f"spectral_evaluate_{name}.json", out))


if __name__ == "__main__":
    main()
