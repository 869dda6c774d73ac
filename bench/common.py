"""Shared set-up of the benchmarks (bench/) and studies (experiments/): the reference slab (177 x 118 x 30 voxels at
300 DPI, 15 x 10 x 2.5 mm, a seeded random CMYKW mixture with 50 % white), the machine description, and writing a
results JSON that records the commit and the command that produced it."""

import json
import os
import platform
import resource
import shlex
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from inkopt.io import atomic_write_bytes
from inkopt.model import InkTable, Volume

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "bench" / "results"
STUDY_RESULTS = ROOT / "experiments" / "results"
# Spot: the shared data set when it is beside the checkout, else the copy the package ships (the same files)
SPOT = ROOT.parent / "shared" / "data" / "spot" / "spot.obj"
if not SPOT.is_file():
    SPOT = ROOT / "python" / "inkopt" / "data" / "spot" / "spot.obj"


def reference_slab(seed: int = 0) -> Volume:
    rng = np.random.default_rng(seed)
    inks = InkTable.parse("vero-cmykw")
    m = np.zeros((30, 118, 177, 5), np.float32)
    m[..., :4] = 0.5 * rng.dirichlet(np.ones(4), size=(30, 118, 177))
    m[..., 4] = 0.5
    return Volume.from_mixture(voxel_mm=(25.4 / 300,) * 3, mixture=m, inks=inks)


def machine() -> dict:
    return {
        "cpus": os.cpu_count(),
        "machine": platform.machine(),
        "processor": platform.processor(),
        "python": platform.python_version(),
        "date": time.strftime("%Y-%m-%d %H:%M"),
        "load_average_1min": os.getloadavg()[0],
    }


def provenance() -> dict:
    """``commit``: the checkout's HEAD (with " + uncommitted changes" when tracked files differ from it, None
    outside git); ``command``: this process's command line, the script path relative to the repository."""

    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()

    try:
        commit = git("rev-parse", "HEAD")
        if git("status", "--porcelain", "--untracked-files=no"):
            commit += " + uncommitted changes"
    except (OSError, subprocess.CalledProcessError):
        commit = None
    script = Path(sys.argv[0]).resolve()
    if script.is_relative_to(ROOT):
        script = script.relative_to(ROOT)
    return {"commit": commit, "command": shlex.join(["python", str(script), *sys.argv[1:]])}


def write(name: str, data: dict, folder: Path = RESULTS) -> Path:
    """Write ``data`` as ``folder/name`` (atomically), adding ``commit`` and ``command`` (``provenance``) unless
    ``data`` has them."""
    path = folder / name
    out = {**data, **{k: v for k, v in provenance().items() if k not in data}}
    atomic_write_bytes(path, (json.dumps(out, indent=2) + "\n").encode())
    return path


def write_study(name: str, data: dict) -> Path:
    """``write`` into experiments/results/."""
    return write(name, data, STUDY_RESULTS)


def add_study_entry(name: str, key: str, entry: dict) -> Path:
    """Set ``results[key]`` of experiments/results/``name`` (made if missing) to ``entry``, keeping the others."""
    path = STUDY_RESULTS / name
    out = json.loads(path.read_text()) if path.is_file() else {"results": {}}
    out["results"][key] = entry
    return write_study(name, out)


def cpu_seconds() -> float:
    """This process's CPU seconds so far (user and system, every thread)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
