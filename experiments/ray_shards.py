"""Beyond one machine: seconds per optimisation iteration of a small slab in one process and on
local Ray workers (1 worker x 2 threads, 2 workers x 1 thread), the results checked bit-identical, and the bytes
each iteration moves between the driver and the workers. Writes experiments/results/ray_shards.json.

    .venv/bin/python experiments/ray_shards.py [--texels-x 96] [--iterations 6]

The figures are a local machine's: workers share its cores, so they show the overhead of sharding, not a
cluster's speed-up (which a cluster gets by adding nodes: each iteration's work splits in proportion to threads).
"""

import argparse
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import machine  # noqa: E402
from common import write_study as write

from inkopt import charts  # noqa: E402
from inkopt.color import srgb_to_linear  # noqa: E402
from inkopt.distributed import RayShards  # noqa: E402
from inkopt.model import InkTable  # noqa: E402
from inkopt.optim import Optimization, OptimizeConfig  # noqa: E402
from inkopt.scenes.slab import build_slab  # noqa: E402


def bytes_per_iteration(opt: Optimization, workers: int, nodes: int) -> dict:
    """An upper bound of what one iteration moves, from the formulas of the raw-int64 design: the mixture of the
    free voxels out (once per node: int32 index + N float32 shares), the adjoints out (12 bytes per texel),
    per-texel rgb + variance back for two passes, and per worker the int64 gradient sums (2 x 3 x 8 bytes per free
    voxel). Workers now return only their touched slots, compressed; ``bench/bench_ray.py`` counts the bytes
    actually moved (docs/ray.md)."""
    n_tex, free, n_inks = len(opt.texels), opt.param.n_free, len(opt.base.inks)
    return {
        "mixture_out_per_node": free * (4 * n_inks + 4),
        "adjoint_out": 12 * n_tex,
        "renders_back": 2 * 24 * n_tex,
        "gradients_back_per_worker": 48 * free,
        "total": nodes * free * (4 * n_inks + 4) + 12 * n_tex + 48 * n_tex + workers * 48 * free,
        "free_voxels": free,
        "texels": n_tex,
        "inks": n_inks,
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--texels-x", type=int, default=96)
    ap.add_argument("--iterations", type=int, default=6)
    args = ap.parse_args()
    w, h = args.texels_x, args.texels_x * 2 // 3
    top = srgb_to_linear(charts.colour_chart(w * 4, h * 4) / 255.0).astype(np.float32)
    vox = 25.4 / 300
    scene = build_slab(top, None, (w * vox, h * vox, 1.0), InkTable.parse("vero-cmykw"))
    cfg = OptimizeConfig(iterations=args.iterations, spp=8, forward_spp=16)

    def timed(factory=None):
        opt = Optimization(scene, cfg.for_scene(scene.kind), threads=2, renderer_factory=factory)
        opt.run()
        return opt, float(np.mean(opt.history.seconds[1:]))  # the first iteration builds the renderers

    plain, s_plain = timed()
    rows = {"one process, 2 threads": s_plain}
    for workers, threads in ((1, 2), (2, 1)):
        shards = RayShards("auto", workers=workers, threads=threads, num_cpus=2)
        try:
            opt, s = timed(shards.renderer)
        finally:
            shards.close()
        assert np.array_equal(opt.x, plain.x) and opt.history.loss == plain.history.loss, "not bit-identical"
        rows[f"Ray, {workers} worker(s) x {threads} thread(s)"] = s
    rows["one process, 2 threads (again, last)"] = timed()[1]  # the machine is shared: see its drift
    out = {
        "seconds_per_iteration": rows,
        "bit_identical": True,
        "shape": list(scene.volume.shape),
        "spp": cfg.spp,
        "forward_spp": cfg.forward_spp,
        "iterations": cfg.iterations,
        "bytes_per_iteration_2_workers_1_node": bytes_per_iteration(plain, 2, 1),
        "machine": machine(),
        "load_average_1_5_15_min": list(os.getloadavg()),
    }
    print(write("ray_shards.json", out))
    for k, v in rows.items():
        print(f"| {k} | {v:.2f} s |")
    print(out["bytes_per_iteration_2_workers_1_node"])


if __name__ == "__main__":
    main()
