"""Memory of the extrusion baseline's nearest texels (a run's baseline guard, an extrusion start, `inkopt evaluate`'s
baseline): the plane-at-a-time exact feature transform (``evaluation.baselines._nearest_centred``) against scipy's
whole-grid ``distance_transform_edt(return_indices=True)``, which it replaces (12 B of indices per grid voxel and
2 B of masks), on Spot with a 1 mm shell (every inside voxel filled, as a run's baseline does).

    python bench/bench_baseline_memory.py 20 40 [--out mesh_60mm_baseline_nearest.json]   # into bench/results/

Peaks are tracemalloc's (numpy's allocations, scipy's index array included) above the scene; both answers are
compared (``identical``).
"""

from __future__ import annotations

import argparse
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "bench"))

from common import SPOT, machine, write  # noqa: E402


def whole_grid(texels, fill: np.ndarray, vmm: np.ndarray):
    """The nearest texel of every ``fill`` voxel by scipy's whole-grid feature transform (the code before)."""
    from scipy import ndimage

    shape = fill.shape
    feature = np.ones(shape, bool)
    feature[tuple(texels.voxel.T)] = False
    idx = ndimage.distance_transform_edt(feature, sampling=vmm[::-1], return_distances=False, return_indices=True)
    flat_t = np.ravel_multi_index(tuple(texels.voxel.T), shape)
    order = np.argsort(flat_t)
    counts = fill.reshape(shape[0], -1).sum(1)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    near = np.empty(int(offsets[-1]), np.int32)
    for z in range(shape[0]):
        f = fill[z]
        hit = np.ravel_multi_index((idx[0, z][f], idx[1, z][f], idx[2, z][f]), shape)
        near[offsets[z] : offsets[z + 1]] = order[np.searchsorted(flat_t, hit, sorter=order)]
    return near, offsets


def measure(height_mm: float) -> dict:
    from inkopt.evaluation.baselines import _nearest_centred
    from inkopt.model import InkTable
    from inkopt.scenes import build_scene
    from inkopt.scenes.spec import MeshSpec

    scene = build_scene(MeshSpec(str(SPOT), height_mm=height_mm, shell_mm=1.0), InkTable.parse("vero-cmykw"))
    vmm = np.asarray(scene.volume.voxel_mm, np.float64)
    inside = scene.volume.inside.dense()  # the input both versions read
    row = {"grid_voxels": int(inside.size), "inside_voxels": int(inside.sum()), "texels": len(scene.texels)}
    answers = {}
    for name, fn in (("plane_at_a_time", _nearest_centred), ("whole_grid", whole_grid)):
        tracemalloc.start()
        t = time.process_time()
        answers[name] = fn(scene.texels, inside, vmm)
        row[f"{name}_cpu_s"] = time.process_time() - t
        row[f"{name}_peak_gib"] = tracemalloc.get_traced_memory()[1] / 2**30
        tracemalloc.stop()
    a, b = answers.values()
    row["identical"] = all(np.array_equal(x, y) for x, y in zip(a, b))
    row["whole_grid_bytes_per_grid_voxel"] = row["whole_grid_peak_gib"] * 2**30 / row["grid_voxels"]
    return row


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("heights", type=float, nargs="+")
    ap.add_argument("--out", default="mesh_60mm_baseline_nearest.json", help="file name in bench/results")
    args = ap.parse_args(argv)
    entries = {}
    for h in args.heights:
        entries[f"{h:g}mm_shell1"] = measure(h)
        print(h, entries[f"{h:g}mm_shell1"], file=sys.stderr, flush=True)
    result = {"entries": entries, "machine": machine()}
    write(args.out, result)
    return result


if __name__ == "__main__":
    main()
