"""The band medium against the sparse one on the same object: render and gradient CPU seconds, alternated in one
process (the renders are bit-identical; only the lookups differ).

    python bench/band_ab.py [HEIGHT_MM=10] [--shell-mm 1] [--spp 4] [--repeats 3] [--threads 2]

Writes bench/results/band_ab_<height>mm_shell<D>.json. CPU seconds (user + system of the process) are reported
beside wall-clock ones because the machine may be shared.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "bench"))

from bench_mesh import SPOT, medium_bytes  # noqa: E402
from common import cpu_seconds as cpu  # noqa: E402


def timed(fn) -> tuple[float, float, object]:
    w, c = time.perf_counter(), cpu()
    out = fn()
    return time.perf_counter() - w, cpu() - c, out


def main(argv=None) -> dict:
    import numpy as np
    from common import provenance

    from inkopt.io import atomic_write_bytes
    from inkopt.model import InkTable
    from inkopt.render import Renderer
    from inkopt.scenes.mesh import build_mesh_scene
    from inkopt.scenes.spec import MeshSpec

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("height_mm", type=float, nargs="?", default=10.0)
    ap.add_argument("--shell-mm", type=float, default=1.0)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args(argv)
    inks = InkTable.parse("vero-cmykw")
    scene = build_mesh_scene(MeshSpec(str(SPOT), height_mm=args.height_mm, shell_mm=args.shell_mm), inks)
    forms = {"band": scene.volume, "sparse": dataclasses.replace(scene.volume, band=None)}
    renderers = {}
    for name, vol in forms.items():  # the same mixtures: the scene's fixed shares, a random free mixture
        r = Renderer(vol, threads=args.threads)
        free = np.flatnonzero(scene.free)
        fs = scene.fixed_share
        held = np.setdiff1d(vol.inside.nonzero(), free)
        r.set_mixture(held, fs.at(held))
        rows = np.random.default_rng(0).dirichlet(np.ones(len(inks)), size=len(free)).astype(np.float32)
        r.set_mixture(free, rows)
        renderers[name] = r
    tex = scene.texels
    adj = np.random.default_rng(1).normal(size=(len(tex), 3)).astype(np.float32)
    times = {name: {"render": [], "gradient": [], "render_cpu": [], "gradient_cpu": []} for name in forms}
    results = {}
    for rep in range(args.repeats):
        for name, r in renderers.items():
            w, c, res = timed(lambda r=r, rep=rep: r.render(tex, spp=args.spp, seed=rep))
            times[name]["render"].append(w)
            times[name]["render_cpu"].append(c)
            w, c, g = timed(lambda r=r, rep=rep: r.gradient(tex, adj, spp=args.spp, seed=rep))
            times[name]["gradient"].append(w)
            times[name]["gradient_cpu"].append(c)
            results.setdefault(rep, []).append((res.rgb.tobytes(), g[0].tobytes(), g[1].tobytes()))
    identical = all(len(set(v)) == 1 for v in results.values())
    mean = {n: {k: float(np.mean(v)) for k, v in t.items()} for n, t in times.items()}
    ratio = {k: mean["band"][k] / mean["sparse"][k] for k in ("render_cpu", "gradient_cpu")}
    out = {
        "height_mm": args.height_mm,
        "shell_mm": args.shell_mm,
        "spp": args.spp,
        "threads": args.threads,
        "texels": len(tex),
        "inside_voxels": scene.vox.inside.count,
        "band_voxels": len(scene.volume.band.index),
        "medium_bytes": medium_bytes(scene.volume),
        "seconds": times,
        "mean_seconds": mean,
        "band_over_sparse_cpu": ratio,
        "bit_identical": identical,
    }
    path = ROOT / "bench" / "results" / f"band_ab_{args.height_mm:g}mm_shell{args.shell_mm:g}.json"
    atomic_write_bytes(path, (json.dumps({**out, **provenance()}, indent=2) + "\n").encode())
    print(json.dumps({k: out[k] for k in ("band_voxels", "medium_bytes", "band_over_sparse_cpu", "bit_identical")}))
    return out


if __name__ == "__main__":
    main()
