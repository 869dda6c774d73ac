"""Translucency: an orange-like slab whose pulp is constrained to 80 % transparent ink (as the
paper), beside an unconstrained run of the same target.

A procedural orange slice (rind, pith, ten pulp segments with pale membranes, on a leaf-green ground) is the top
picture of a W x W x D mm slab (vero-cmykwt); the mask is 0.8 on the pulp disc, 0 elsewhere, through the whole
slab. Both runs use the same seed and settings; the constrained run is then evaluated (fixed spp, no baselines)
with ``--translucency-compare`` the unconstrained one. Writes experiments/results/translucency.json,
docs/translucency.png (target | constrained | unconstrained under the uniform light, then both lit only from
behind: what shines through) and prints the table.

    .venv/bin/python experiments/translucency_example.py [--out bench-out/translucency] [--iterations 150] [--px 48]

The same from the command line:

    inkopt slab orange.png --size-mm 4.06x4.06x1.5 --inks vero-cmykwt --translucency pulp.png --out T
    inkopt slab orange.png --size-mm 4.06x4.06x1.5 --inks vero-cmykwt --out U
    inkopt evaluate T --translucency-compare U --no-baselines --spp 256
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import machine  # noqa: E402
from common import write_study as write

DOCS = Path(__file__).resolve().parents[1] / "docs"


def orange(px: int) -> tuple[np.ndarray, np.ndarray]:
    """(sRGB uint8 (px, px, 3) picture, float mask (px, px)) of an orange slice."""
    y, x = (np.mgrid[0:px, 0:px] + 0.5) / px * 2 - 1
    r, a = np.hypot(x, y), np.arctan2(y, x)
    img = np.empty((px, px, 3), np.float64)
    img[:] = (70, 120, 40)  # leaf green
    img[r < 0.95] = (230, 110, 20)  # rind
    img[r < 0.86] = (250, 225, 170)  # pith
    pulp = r < 0.78
    seg = np.abs(((a / (2 * np.pi) * 10) % 1) - 0.5) * 2  # 1 at a segment's middle, 0 on a membrane
    shade = np.clip(0.55 + 0.45 * seg, 0, 1)[..., None]
    img[pulp] = (shade * np.array([255, 150, 20]) + (1 - shade) * np.array([250, 215, 160]))[pulp]
    img[r < 0.08] = (250, 225, 170)  # the core
    mask = np.where(pulp, 0.8, 0.0)
    return img.round().astype(np.uint8), mask


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="bench-out/translucency")
    ap.add_argument("--iterations", type=int, default=150)
    ap.add_argument("--px", type=int, default=48, help="texels per side (300 DPI: 48 = 4.06 mm)")
    ap.add_argument("--depth-mm", type=float, default=1.5)
    ap.add_argument("--eval-spp", type=int, default=256)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int)
    a = ap.parse_args()

    from PIL import Image

    from inkopt.evaluation.evaluate import evaluate_run
    from inkopt.evaluation.options import EvaluateOptions
    from inkopt.evaluation.translucency import back_light
    from inkopt.model import InkTable
    from inkopt.optim import OptimizeConfig
    from inkopt.pictures import panels
    from inkopt.render import Renderer
    from inkopt.run import RunOptions, run_optimisation
    from inkopt.rundir import RunDir
    from inkopt.scenes.slab import build_slab_scene
    from inkopt.scenes.spec import SlabSpec
    from inkopt.units import OPT_DPI

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    pic, mask = orange(a.px)
    Image.fromarray(pic).save(out / "orange.png")
    Image.fromarray((mask * 255).round().astype(np.uint8)).save(out / "pulp.png")
    side = a.px * 25.4 / OPT_DPI
    size = (side, side, a.depth_mm)
    inks = InkTable.parse("vero-cmykwt")
    t0 = time.perf_counter()
    runs = {"constrained": out / "constrained", "unconstrained": out / "unconstrained"}
    for name, d in runs.items():
        if (d / "report.json").is_file():
            continue
        translucency = out / "pulp.png" if name == "constrained" else None
        scene = build_slab_scene(SlabSpec(out / "orange.png", size, translucency=translucency), inks)
        run_optimisation(
            scene,
            d,
            OptimizeConfig(iterations=a.iterations, seed=a.seed),
            RunOptions(eval_spp=a.eval_spp, threads=a.threads, log=lambda m: print(m, flush=True)),
        )
    optimise_s = time.perf_counter() - t0
    ev = {
        name: evaluate_run(
            d,
            EvaluateOptions(
                spp=a.eval_spp,
                baselines=False,
                threads=a.threads,
                translucency=name == "constrained",
                translucency_compare=runs["unconstrained"] if name == "constrained" else None,
            ),
        ).to_json()
        for name, d in runs.items()
    }
    tr = ev["constrained"]["translucency"]

    rec = RunDir(runs["constrained"]).load_scene()
    front, back = {}, {}
    for name, d in runs.items():
        vol = RunDir(d).load_volume()
        front[name] = Renderer(vol, a.threads).render(rec.texels, a.eval_spp, 2**62).rgb
        back[name] = Renderer(vol, a.threads, back_light(5)).render(rec.texels, a.eval_spp, 2**62).rgb
    img = panels(
        [
            ("target", rec.target_rgb),
            ("80 % clear pulp", front["constrained"]),
            ("unconstrained", front["unconstrained"]),
            ("80 % clear pulp, lit from behind", back["constrained"]),
            ("unconstrained, lit from behind", back["unconstrained"]),
        ],
        rec.pix["top"],
    )
    img.save(DOCS / "translucency.png")

    def row(t: dict, e: dict) -> dict:
        reg, whole = t["regions"][0], t["whole"]
        return {
            "delta_e76_mean": e["continuous"]["delta_e76_mean"],
            "delta_e2000_mean": e["continuous"]["delta_e2000_mean"],
            "delta_e76_quantized": e["quantized"]["delta_e76_mean"],
            "pulp_delta_e76": reg["delta_e76_mean"],
            "pulp_transmittance": reg["transmittance"],
            "pulp_transmittance_stderr": reg["transmittance_stderr"],
            "pulp_spread_mm": reg["spread_mm"],
            "pulp_spread_stderr_mm": reg["spread_stderr_mm"],
            "whole_transmittance": whole["transmittance"],
            "whole_spread_mm": whole["spread_mm"],
        }

    table = {"constrained": row(tr, ev["constrained"]), "unconstrained": row(tr["compare"], ev["unconstrained"])}
    res = {
        "machine": machine(),
        "iterations": a.iterations,
        "seed": a.seed,
        "eval_spp": a.eval_spp,
        "slab_mm": list(size),
        "texels_per_side": a.px,
        "inks": "vero-cmykwt",
        "pulp_share": 0.8,
        "pulp_texels": tr["regions"][0]["texels"],
        "optimise_seconds": optimise_s,
        "seconds": time.perf_counter() - t0,
        "results": table,
        "translucency": tr,
    }
    path = write("translucency.json", res)
    print(
        f"{'run':<15}{'ΔE76':>7}{'ΔE2000':>8}{'ΔE76 q.':>9}{'pulp ΔE76':>11}{'pulp T':>9}{'pulp spread':>13}"
        f"{'whole T':>9}{'whole spread':>14}"
    )
    for name, v in table.items():
        print(
            f"{name:<15}{v['delta_e76_mean']:7.2f}{v['delta_e2000_mean']:8.2f}{v['delta_e76_quantized']:9.2f}"
            f"{v['pulp_delta_e76']:11.2f}{v['pulp_transmittance']:9.3f}{v['pulp_spread_mm']:10.3f} mm"
            f"{v['whole_transmittance']:9.3f}{v['whole_spread_mm']:11.3f} mm"
        )
    print(f"wrote {path} and {DOCS / 'translucency.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
