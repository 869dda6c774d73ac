"""Display lighting: does optimising under the lighting a print will be seen in pay off?

A colour-chart slab is optimised twice with the same seeds and settings, once under the uniform white light and
once under a display map (a warm key light low on the +x side, a cool sky, a dark floor; written to
OUT/display.hdr and read back as `--lighting` reads it). Both results (continuous and quantized) are then
evaluated under both lightings with the same render seeds (``evaluate_run``, fixed spp). Writes
experiments/results/lighting.json and experiments/results/lighting.png (target | optimised under uniform |
optimised under the map, both seen under the map) and prints a table.

    .venv/bin/python experiments/lighting_compare.py [--out bench-out/lighting] [--iterations 300] [--eval-spp 1024]
        [--depth-mm 1]

The same runs from the command line:

    inkopt slab CHART.png --size-mm 2.71x1.78x1 --out A --iterations 300
    inkopt slab CHART.png --size-mm 2.71x1.78x1 --out B --iterations 300 --lighting OUT/display.hdr
    inkopt evaluate A --lighting OUT/display.hdr --no-baselines;  inkopt evaluate B --lighting OUT/display.hdr ...
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import STUDY_RESULTS as RESULTS  # noqa: E402
from common import machine
from common import write_study as write


def display_map(h: int = 64) -> np.ndarray:
    """Warm key light (elevation 30 degrees, towards +x, ~20 degrees wide), cool sky, dark floor; scaled so
    that the irradiance of an upward face is that of the uniform light (pi) in luminance."""
    theta = (np.arange(h) + 0.5) * np.pi / h
    phi = (np.arange(2 * h) + 0.5) * np.pi / h
    st = np.sin(theta)[:, None]
    d = np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)[:, None] + 0 * phi], -1)
    key_dir = np.array([np.cos(np.radians(30)), 0.0, np.sin(np.radians(30))])
    key = np.exp((d @ key_dir - 1) / 0.06)[..., None] * np.array([1.0, 0.62, 0.3])
    up = d[..., 2:] > 0
    sky = np.where(up, np.array([0.35, 0.5, 0.85]) * (0.6 + 0.4 * d[..., 2:]), np.array([0.08, 0.07, 0.06]))
    env = 4.0 * key + sky
    # luminance irradiance of the +z face (solid angle of a cell: sin(theta) dtheta dphi)
    lum = env @ np.array([0.2126, 0.7152, 0.0722])
    cell = (np.pi / h) ** 2 * st
    e_up = float(np.sum(lum * np.clip(d[..., 2], 0, None) * cell))
    return (env * (np.pi / e_up)).astype(np.float32)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="bench-out/lighting")
    ap.add_argument("--iterations", type=int, default=300)
    ap.add_argument("--depth-mm", type=float, default=1.0)
    ap.add_argument("--eval-spp", type=int, default=1024)
    ap.add_argument("--seed", type=int, default=0, help="optimisation seed (render seeds are fixed)")
    ap.add_argument("--threads", type=int)
    a = ap.parse_args()

    from inkopt import charts
    from inkopt.evaluation.evaluate import evaluate_run
    from inkopt.evaluation.options import EvaluateOptions
    from inkopt.lighting import load_lighting, write_map
    from inkopt.model import InkTable
    from inkopt.optim import OptimizeConfig
    from inkopt.pictures import panels
    from inkopt.run import RunOptions, run_optimisation
    from inkopt.rundir import RunDir
    from inkopt.scenes import build_scene
    from inkopt.scenes.spec import SlabSpec
    from inkopt.units import OPT_DPI

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    chart = charts.save(charts.colour_chart(32, 21), out / "chart.png")
    size = (32 * 25.4 / OPT_DPI, 21 * 25.4 / OPT_DPI, a.depth_mm)
    lights = {
        "uniform": load_lighting("uniform"),
        "display": load_lighting(write_map(out / "display.hdr", display_map())),
    }
    inks = InkTable.parse("vero-cmykw")
    runs, t0 = {}, time.perf_counter()
    for name, light in lights.items():
        d = out / f"optimised_{name}"
        cfg = OptimizeConfig(iterations=a.iterations, seed=a.seed)
        if not (d / "report.json").is_file():
            run_optimisation(
                build_scene(SlabSpec(chart, size), inks),
                d,
                cfg,
                RunOptions(eval_spp=a.eval_spp, threads=a.threads, lighting=light, log=lambda m: None),
            )
        runs[name] = d
    table, colours = {}, {}
    for run_name, d in runs.items():
        for light_name, light in lights.items():
            options = EvaluateOptions(spp=a.eval_spp, baselines=False, threads=a.threads, lighting=light, write=False)
            ev = evaluate_run(d, options).to_json()
            table[f"optimised_{run_name}/seen_{light_name}"] = {
                k: {
                    m: ev[k][m]
                    for m in (
                        "delta_e76_mean",
                        "delta_e76_mean_corrected",
                        "delta_e2000_mean",
                        "delta_e76_p95",
                        "ssim",
                        "spp",
                    )
                }
                for k in ("continuous", "quantized")
            }
            if light_name == "display":
                from inkopt.render import Renderer

                rec = RunDir(d).load_scene()
                colours[run_name] = (
                    Renderer(RunDir(d).load_volume(), a.threads, light).render(rec.texels, a.eval_spp, 2**62).rgb
                )
    rec = RunDir(runs["uniform"]).load_scene()
    img = panels(
        [
            ("target", rec.target_rgb),
            ("optimised uniform, seen under map", colours["uniform"]),
            ("optimised under map, seen under map", colours["display"]),
        ],
        rec.pix["top"],
    )
    img.save(RESULTS / "lighting.png")
    res = {
        "machine": machine(),
        "iterations": a.iterations,
        "seed": a.seed,
        "eval_spp": a.eval_spp,
        "slab_mm": list(size),
        "inks": "vero-cmykw",
        "map": "display_map() in experiments/lighting_compare.py, 64 x 128",
        "seconds": time.perf_counter() - t0,
        "results": table,
    }
    path = write("lighting.json", res)
    print(f"{'optimised under':<16}{'seen under':<12}{'ΔE76':>8}{'ΔE2000':>8}{'ΔE76 quantized':>16}{'ΔE2000 q.':>11}")
    for key, v in table.items():
        run_name, seen = key.split("/")
        c, q = v["continuous"], v["quantized"]
        print(
            f"{run_name[10:]:<16}{seen[5:]:<12}{c['delta_e76_mean']:8.2f}{c['delta_e2000_mean']:8.2f}"
            f"{q['delta_e76_mean']:16.2f}{q['delta_e2000_mean']:11.2f}"
        )
    print(f"wrote {path} and {RESULTS / 'lighting.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
