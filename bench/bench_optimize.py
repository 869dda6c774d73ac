"""Optimisation-iteration benchmark on the reference slab with two textured faces (colour chart on top,
zebra below), forward + gradient + loss + step, and the cost of the gradient pass against a forward pass.

    .venv/bin/python bench/bench_optimize.py [--spp 16] [--iterations 5] [--method replay]

Writes bench/results/optimize_<method>_spp<spp>.json (seconds per iteration and where the time goes).
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine, reference_slab, write  # noqa: E402

from inkopt import charts  # noqa: E402
from inkopt.color import srgb_to_linear  # noqa: E402
from inkopt.optim import Optimization, OptimizeConfig  # noqa: E402
from inkopt.render import Renderer  # noqa: E402
from inkopt.scenes.slab import build_slab  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--forward-spp", type=int)
    ap.add_argument("--iterations", type=int, default=5)
    ap.add_argument("--method", default="replay", choices=("replay", "li1"))
    ap.add_argument("--threads", type=int)
    a = ap.parse_args()
    fwd = a.forward_spp or a.spp
    lin = lambda im: srgb_to_linear(im / 255.0).astype(np.float32)
    top, bottom = lin(charts.colour_chart(708, 472)), lin(charts.zebra(177, 118))
    vol = reference_slab()
    scene = build_slab(top, bottom, (177 * 25.4 / 300, 118 * 25.4 / 300, 30 * 25.4 / 300), vol.inks)
    assert scene.volume.shape == vol.shape
    # Cost of one gradient pass relative to one forward pass at equal spp, on the random reference mixture.
    r = Renderer(vol, a.threads)
    adj = np.random.default_rng(0).normal(size=(len(scene.texels), 3)).astype(np.float32)
    t0 = time.perf_counter()
    r.render(scene.texels, a.spp, 1)
    t_f = time.perf_counter() - t0
    t0 = time.perf_counter()
    r.gradient(scene.texels, adj, a.spp, 2, method=a.method)
    t_g = time.perf_counter() - t0
    cfg = OptimizeConfig(iterations=a.iterations, spp=a.spp, forward_spp=fwd, grad_method=a.method)
    t0 = time.perf_counter()
    run = Optimization(scene, cfg.for_scene(scene.kind), threads=a.threads)
    setup = time.perf_counter() - t0
    run.run()
    h = run.history
    out = {
        "slab": "177x118x30 voxels, top and bottom textured",
        "texels": len(scene.texels),
        "spp": a.spp,
        "forward_spp": fwd,
        "gradient_method": a.method,
        "threads": r.threads,
        "forward_pass_s": t_f,
        "gradient_pass_s": t_g,
        "gradient_over_forward": t_g / t_f,
        "setup_s": setup,
        "seconds_per_iteration": float(np.mean(h.seconds)),
        "split_s": {k: float(np.mean(getattr(h, k))) for k in ("render_s", "gradient_s", "loss_s", "step_s")},
        **machine(),
    }
    print(
        f"{len(scene.texels)} texels, spp {a.spp} (forward {fwd}): {out['seconds_per_iteration']:.2f} s/iteration "
        f"(render {out['split_s']['render_s']:.2f}, gradient {out['split_s']['gradient_s']:.2f}, loss "
        f"{out['split_s']['loss_s']:.2f}, step {out['split_s']['step_s']:.2f}); gradient pass = "
        f"{out['gradient_over_forward']:.2f} x forward"
    )
    print("wrote", write(f"optimize_{a.method}_spp{a.spp}.json", out))


if __name__ == "__main__":
    main()
