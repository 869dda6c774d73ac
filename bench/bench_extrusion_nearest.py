"""The extrusion baseline's mixture of an optimised mesh run: time and peak memory of ``BaselineLayers("extrusion")``
(the nearest texel of every inside voxel by the distance transform, then every layer), and, on three layers, the
k-d tree search it replaces: its time per voxel, and how the two choices compare (distance, ties, mixtures).

    .venv/bin/python bench/bench_extrusion_nearest.py RUN_DIR [--name NAME]

RUN_DIR: a mesh run directory (``inkopt optimize MESH --out RUN_DIR``). Writes bench/results/extrusion_nearest.json
(``--name`` for another name). Wall-clock times on the shared 2-core machine are upper bounds.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "python"))
sys.path.insert(0, str(Path(__file__).resolve().parent))


def main() -> dict:
    from common import machine, write
    from scipy.spatial import cKDTree

    from inkopt.evaluation.baselines import BaselineLayers
    from inkopt.evaluation.colour_table import colour_table
    from inkopt.rundir import RunDir

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run")
    ap.add_argument("--name", default="extrusion_nearest.json")
    args = ap.parse_args()
    d = RunDir(args.run)
    vol, rec = d.load_volume(), d.load_scene()
    table = colour_table(vol.inks, vol.g, vol.ior)
    fixed = rec.fixed_share(vol.inks, vol.shape)
    t = time.perf_counter()
    src = BaselineLayers("extrusion", vol, rec.texels, rec.target_rgb, fixed, table)
    t_init = time.perf_counter() - t
    t = time.perf_counter()
    for z in range(vol.shape[0]):
        src[z]
    t_layers = time.perf_counter() - t
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    pos_t = rec.texels.position_mm(vol.voxel_mm)
    tree, vmm = cKDTree(pos_t), np.asarray(vol.voxel_mm, np.float64)
    layers = []
    for z in (vol.shape[0] // 4, vol.shape[0] // 2, 3 * vol.shape[0] // 4):
        flat = np.flatnonzero(src.fill[z].ravel())
        yx = np.stack(np.unravel_index(flat, vol.shape[1:]), 1)
        pos = (np.column_stack([yx[:, ::-1], np.full(len(flat), z)]) + 0.5) * vmm
        t = time.perf_counter()
        dist_tree, near_tree = tree.query(pos, workers=-1)
        t_tree = time.perf_counter() - t
        near = src.nearest_texels(z, flat)
        dist = np.linalg.norm(pos - pos_t[near], axis=1)
        layers.append(
            {
                "z": z,
                "voxels": len(flat),
                "tree_seconds": t_tree,
                "tree_microseconds_per_voxel": 1e6 * t_tree / max(len(flat), 1),
                "max_distance_difference_mm": float(np.abs(dist - dist_tree).max()),
                "other_equidistant_texel": int((near != near_tree).sum()),
                "mean_largest_mixture_difference": float(np.abs(src.mix_t[near] - src.mix_t[near_tree]).max(1).mean()),
            }
        )
    inside = int(src.fill.sum())
    per_voxel = sum(r["tree_seconds"] for r in layers) / sum(r["voxels"] for r in layers)
    res = {
        "run": str(args.run),
        "grid_zyx": list(vol.shape),
        "inside_voxels": inside,
        "texels": len(rec.texels),
        "distance_transform": src.near is not None,
        "init_seconds": t_init,
        "layers_seconds": t_layers,
        "peak_rss_gb": peak,
        "tree_seconds_estimated_for_all_inside_voxels": per_voxel * inside,
        "layers_compared": layers,
        **machine(),
        "note": "peak_rss_gb includes the run's volume and scene as loaded",
    }
    print(res)
    print("wrote", write(args.name, res))
    return res


if __name__ == "__main__":
    main()
