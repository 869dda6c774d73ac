"""Bytes per iteration between the driver and 2 local Ray workers, counted in the code
(``ShardedRenderer.traffic``), with the sharded run checked bit-identical to one process; peak memory of the driver
and of each worker.

    python bench/bench_ray.py [--scenes chart,sphere] [--iterations 2] [--out ray_bytes.json]
    python bench/bench_ray.py --scenes spot --spot-mm 20 --shell-mm 1 [--only plain|ray] [--out NAME]

Scenes: ``chart`` (the Ray tests' 12 x 8-texel colour-chart slab, 0.3 mm deep), ``sphere`` (the Ray tests'
icosphere of radius 0.6 mm with a 0.2 mm shell), ``spot`` (Spot ``--spot-mm`` high, ``--shell-mm``, ``--dpi``).
Each runs ``--iterations`` optimisation iterations in one process (2 threads) and sharded over 2 Ray workers
(1 thread each) on a local Ray instance of 2 CPUs; the variables and loss history must agree bit for bit.
``--only`` runs one of the two in this process (for clean peak memory of a big scene): the results file's entry
keeps the variables' SHA-256 and the losses of each, and the bit-identity is checked when both are there.
Writes (adds its entries to) bench/results/``--out``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import RESULTS, SPOT, machine, write  # noqa: E402

from inkopt import charts  # noqa: E402
from inkopt.color import srgb_to_linear  # noqa: E402
from inkopt.model import InkTable  # noqa: E402
from inkopt.optim import Optimization, OptimizeConfig  # noqa: E402


def chart_scene():
    from inkopt.scenes.slab import build_slab

    w, h = 12, 8
    top = srgb_to_linear(charts.colour_chart(w * 4, h * 4) / 255.0).astype(np.float32)
    vox = 25.4 / 300
    return build_slab(top, None, (w * vox, h * vox, 0.3), InkTable.parse("vero-cmykw"))


def mesh_scene(spec):
    from inkopt.scenes.mesh import build_mesh_scene

    return build_mesh_scene(spec, InkTable.parse("vero-cmykw"))


def sphere_spec(folder: Path):
    import trimesh

    from inkopt.scenes.spec import MeshSpec

    sph = trimesh.creation.icosphere(subdivisions=3, radius=0.6)
    colours = np.where(sph.vertices[:, 2:3] > 0, [[0, 200, 230, 255]], [[230, 0, 160, 255]]).astype(np.uint8)
    path = folder / "ball.ply"
    trimesh.Trimesh(sph.vertices, sph.faces, vertex_colors=colours, process=False).export(path)
    return MeshSpec(path, scale=1.0, up="z", shell_mm=0.2)


def peak_gb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def run(scene, cfg, iterations: int, shards=None) -> dict:
    """``iterations`` steps in one process (``shards`` None) or on ``shards``: per step the traffic counted by the
    sharded renderer, the seconds, and at the end the variables' hash and the losses."""
    made = []

    def factory(*args):
        made.append(shards.renderer(*args))
        return made[-1]

    opt = Optimization(scene, cfg, threads=2, renderer_factory=None if shards is None else factory)
    steps, before = [], {}
    for _ in range(iterations):
        t0 = time.perf_counter()
        opt.step()
        step = {"seconds": time.perf_counter() - t0}
        if made:
            now = dict(made[-1].traffic)
            step["bytes"] = {k: v - before.get(k, 0) for k, v in sorted(now.items())}
            before = now
        steps.append(step)
    out = {
        "steps": steps,
        "x_sha256": hashlib.sha256(np.ascontiguousarray(opt.x).tobytes()).hexdigest(),
        "loss": [float(v) for v in opt.history.loss],
        "free_voxels": int(opt.param.n_free),
        "texels": len(opt.texels),
        "inks": len(opt.base.inks),
        "driver_peak_rss_gb": peak_gb(),
    }
    if shards is not None:
        out["worker_peak_rss_gb"] = shards.peak_rss_gb()
    return out


def measure(scene, cfg, iterations: int, only: str | None) -> dict:
    from inkopt.distributed import RayShards

    entry = {"grid_zyx": list(scene.volume.shape)}
    if only != "ray":
        entry["plain"] = run(scene, cfg, iterations)
    if only != "plain":
        shards = RayShards("auto", workers=2, threads=1, num_cpus=2)
        try:
            entry["ray"] = run(scene, cfg, iterations, shards)
        finally:
            shards.close()
    return entry


def identical(entry: dict) -> bool | None:
    if "plain" not in entry or "ray" not in entry:
        return None
    p, r = entry["plain"], entry["ray"]
    return p["x_sha256"] == r["x_sha256"] and p["loss"] == r["loss"]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="chart,sphere")
    ap.add_argument("--iterations", type=int, default=2)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--forward-spp", type=int, default=16)
    ap.add_argument("--spot-mm", type=float, default=20.0)
    ap.add_argument("--shell-mm", type=float, default=1.0)
    ap.add_argument("--dpi", type=float, default=300.0)
    ap.add_argument("--only", choices=["plain", "ray"])
    ap.add_argument("--out", default="ray_bytes.json")
    args = ap.parse_args(argv)
    import tempfile

    from inkopt.scenes.spec import MeshSpec

    path = RESULTS / args.out
    results = json.loads(path.read_text()).get("results", {}) if path.is_file() else {}
    for name in args.scenes.split(","):
        with tempfile.TemporaryDirectory() as tmp:
            if name == "chart":
                scene = chart_scene()
            elif name == "sphere":
                scene = mesh_scene(sphere_spec(Path(tmp)))
            else:
                spec = MeshSpec(SPOT, height_mm=args.spot_mm, shell_mm=args.shell_mm, dpi=args.dpi)
                scene = mesh_scene(spec)
                name = f"spot{args.spot_mm:g}mm_shell{args.shell_mm:g}_{args.dpi:g}dpi"
            cfg = OptimizeConfig(iterations=args.iterations, spp=args.spp, forward_spp=args.forward_spp)
            entry = measure(scene, cfg.for_scene(scene.kind), args.iterations, args.only)
        key = f"{name}_{args.iterations}it_spp{args.spp}"
        old = results.get(key, {})
        entry = {**{k: v for k, v in old.items() if k in ("plain", "ray")}, **entry}
        entry["bit_identical"] = identical(entry)
        entry["load_average_1_5_15_min"] = list(os.getloadavg())
        results[key] = entry
        print(key, "bit-identical:", entry["bit_identical"])
        for step in entry.get("ray", {}).get("steps", []):
            print("  ", {k: v for k, v in step["bytes"].items()})
        assert entry["bit_identical"] is not False, f"{key}: the sharded run differs from one process"
    print(write(args.out, {"results": results, "machine": machine()}))


if __name__ == "__main__":
    main()
