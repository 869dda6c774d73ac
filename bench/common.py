"""Shared set-up of the benchmarks: the reference slab of the issues (177 x 118 x 30 voxels at 300 DPI,
15 x 10 x 2.5 mm, a seeded random CMYKW mixture with 50 % white)."""
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

from inkopt.io import atomic_write_bytes
from inkopt.model import InkTable, Volume

RESULTS = Path(__file__).resolve().parent / "results"


def reference_slab(seed: int = 0) -> Volume:
    rng = np.random.default_rng(seed)
    inks = InkTable.parse("vero-cmykw")
    m = np.zeros((30, 118, 177, 5), np.float32)
    m[..., :4] = 0.5 * rng.dirichlet(np.ones(4), size=(30, 118, 177))
    m[..., 4] = 0.5
    return Volume.from_mixture(voxel_mm=(25.4 / 300,) * 3, mixture=m, inks=inks)


def machine() -> dict:
    return {"cpus": os.cpu_count(), "machine": platform.machine(), "processor": platform.processor(),
            "python": platform.python_version(), "date": time.strftime("%Y-%m-%d %H:%M"),
            "load_average_1min": os.getloadavg()[0]}


def write(name: str, data: dict) -> Path:
    path = RESULTS / name
    atomic_write_bytes(path, (json.dumps(data, indent=2) + "\n").encode())
    return path
