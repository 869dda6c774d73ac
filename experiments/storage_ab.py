"""A/B of the compact storage of big objects against the per-grid-voxel forms it replaced, on Spot.

    python experiments/storage_ab.py [HEIGHT_MM=20] [--reps 3] [--threads 2]

(1) a forward render (4 spp, the 97 %-white start) with the coefficients stored per grid voxel (``DenseMedium``)
against the inside voxels only (``SparseMedium``, what ``Renderer`` uses for masked volumes); (2) a gradient pass
(4 spp) into slots given by a (z, y, x) int32 map against the free voxels' list (ranked per row in the core, what
the optimiser passes). The forms are interleaved, repeated ``--reps`` times; renders and gradients must be
identical (checked). Writes experiments/results/medium_storage_<height>mm.json: per form the seconds of every
repetition and their mean.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "bench"))
SPOT = Path(__file__).resolve().parents[2] / "shared" / "data" / "spot" / "spot.obj"


def main(argv=None) -> dict:
    import numpy as np
    from common import write_study

    from inkopt import _core
    from inkopt.model import InkTable, mix
    from inkopt.render import Renderer
    from inkopt.scenes.mesh import build_mesh_scene
    from inkopt.scenes.spec import MeshSpec

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("height_mm", type=float, nargs="?", default=20.0)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args(argv)

    sc = build_mesh_scene(MeshSpec(SPOT, height_mm=args.height_mm), InkTable.parse("vero-cmykw"))
    vol, inks, tex = sc.volume, sc.volume.inks, sc.texels
    free = np.flatnonzero(sc.free)
    rows = np.full((len(free), len(inks)), 0.03 / (len(inks) - 1), np.float32)
    rows[:, inks.index("white")] = 0.97
    sparse = Renderer(vol, args.threads)
    sparse.set_mixture(free, rows)
    s, a = mix(rows, inks)
    dense_s = np.zeros(vol.shape + (3,), np.float32)
    dense_a = np.zeros_like(dense_s)
    dense_s.reshape(-1, 3)[free], dense_a.reshape(-1, 3)[free] = s, a
    dense = _core.Scene(
        vol.shape,
        tuple(float(v) for v in vol.voxel_mm),
        _core.Medium.dense(dense_s, dense_a),
        inside=vol.inside.dense().view(np.uint8),
        normal_index=vol.normals.index,
        normal_vectors=vol.normals.vectors,
        threads=args.threads,
    )
    del dense_s, dense_a
    slot_map = np.full(vol.shape, -1, np.int32)
    slot_map.reshape(-1)[free] = np.arange(len(free), dtype=np.int32)
    adj = np.random.default_rng(0).normal(size=(len(tex), 3)).astype(np.float32)
    core_tex = _core.Texels(tex.voxel, tex.face, tex.normal)
    times = {k: [] for k in ("render_dense", "render_sparse", "gradient_slot_map", "gradient_voxel_list")}
    for rep in range(args.reps):
        t = time.perf_counter()
        d_rgb = dense.render(core_tex, spp=4, seed=rep, first_texel=0, include_specular=True)[0]
        times["render_dense"].append(time.perf_counter() - t)
        t = time.perf_counter()
        s_rgb = sparse.render(tex, 4, rep).rgb
        times["render_sparse"].append(time.perf_counter() - t)
        assert np.array_equal(d_rgb, s_rgb), "the two media rendered differently"
        grads = []
        for key, gi in (("gradient_slot_map", slot_map), ("gradient_voxel_list", free)):
            t = time.perf_counter()
            grads.append(sparse.gradient(tex, adj, 4, 100 + rep, grad_index=gi)[1])
            times[key].append(time.perf_counter() - t)
        assert np.array_equal(grads[0], grads[1]), "the two slot forms accumulated differently"
        print(f"rep {rep + 1}: " + ", ".join(f"{k} {v[-1]:.2f} s" for k, v in times.items()), file=sys.stderr)
    result = {
        "height_mm": args.height_mm,
        "grid_zyx": list(vol.shape),
        "free_voxels": int(len(free)),
        "texels": len(tex),
        "threads": args.threads,
        "reps": args.reps,
        "seconds": times,
        "mean_seconds": {k: float(np.mean(v)) for k, v in times.items()},
    }
    write_study(f"medium_storage_{args.height_mm:g}mm.json", result)
    print(json.dumps(result["mean_seconds"]))
    return result


if __name__ == "__main__":
    main()
