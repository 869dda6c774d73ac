"""Benchmark of the coarse-to-fine transfer on Spot: time and memory of moving a coarse grid's mixture onto the
300-DPI scene's free voxels and writing the start volume (``optim.transfer.write_transferred_volume``).

    python bench/bench_transfer.py [HEIGHT_MM=40] [--coarse-dpi 150] [--out PATH]

The coarse mixture is a seeded random one on the coarse scene's inside voxels (the transfer's cost does not depend
on the values). Writes bench/results/transfer_<height>mm.json. Peak memory is the process's resident-set
high-water mark (getrusage) after each stage; run one height per process.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "bench"))

SPOT = Path(__file__).resolve().parents[2] / "shared" / "data" / "spot" / "spot.obj"  # ../shared beside the repo


def main(argv=None) -> dict:
    import numpy as np
    from common import machine, provenance

    from inkopt.io import atomic_write_bytes
    from inkopt.model import InkTable, Volume
    from inkopt.optim.transfer import write_transferred_volume
    from inkopt.run import peak_rss_gb
    from inkopt.scenes.mesh import build_mesh_scene
    from inkopt.scenes.spec import MeshSpec

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("height_mm", type=float, nargs="?", default=40.0)
    ap.add_argument("--coarse-dpi", type=float, default=150.0)
    ap.add_argument("--out", help="JSON path (default bench/results/transfer_<height>mm.json)")
    a = ap.parse_args(argv)
    inks = InkTable.parse("vero-cmykw")
    rss = {"start": peak_rss_gb()}
    coarse = build_mesh_scene(MeshSpec(SPOT, height_mm=a.height_mm, dpi=a.coarse_dpi), inks)
    mix = np.zeros(coarse.volume.shape + (len(inks),), np.float32)
    inside = coarse.volume.inside
    mix[inside.dense()] = np.random.default_rng(0).dirichlet(np.ones(len(inks)), inside.count)
    src = Volume.from_mixture(
        coarse.volume.voxel_mm, mix, inks, inside=coarse.volume.inside, origin_mm=coarse.volume.origin_mm
    )
    del coarse, mix
    rss["after_coarse"] = peak_rss_gb()
    fine = build_mesh_scene(MeshSpec(SPOT, height_mm=a.height_mm), inks)
    rss["after_fine_scene"] = peak_rss_gb()
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        path = write_transferred_volume(src, fine.volume, fine.fixed_share, Path(tmp) / "start.npz")
        seconds = time.perf_counter() - t0
        rss["after_transfer"] = peak_rss_gb()
        size = path.stat().st_size
    result = {
        "height_mm": a.height_mm,
        "coarse_dpi": a.coarse_dpi,
        "coarse_grid_zyx": list(src.shape),
        "fine_grid_zyx": list(fine.volume.shape),
        "fine_free_voxels": int(fine.free.sum()),
        "transfer_seconds": seconds,
        "start_file_bytes": size,
        "peak_rss_gb_by_stage": rss,
        "machine": machine(),
        "note": "wall time on a machine that may be shared (its load average is in machine)",
    }
    out = Path(a.out) if a.out else ROOT / "bench" / "results" / f"transfer_{a.height_mm:g}mm.json"
    atomic_write_bytes(out, (json.dumps({**result, **provenance()}, indent=2) + "\n").encode())
    print(json.dumps({k: result[k] for k in ("fine_grid_zyx", "transfer_seconds", "peak_rss_gb_by_stage")}))
    return result


if __name__ == "__main__":
    main()
