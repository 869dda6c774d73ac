"""How close the run estimate (``inkopt.estimate``: time per iteration, peak memory, disk, logged before a long run
and printed by ``--dry-run``) comes to what the run then takes: ``inkopt optimize`` of Spot in its own process;
its report.json holds both the estimate (made just before the iterations) and the measured figures.

    python bench/bench_estimate.py 10 [--iterations 6] [--threads 2]   -> bench/results/estimate_10mm.json
"""

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from common import ROOT, machine, write


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("height_mm", type=float)
    ap.add_argument("--iterations", type=int, default=6)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--mesh", default=str(ROOT.parent / "shared" / "data" / "spot" / "spot.obj"))
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        cmd = [sys.executable, "-m", "inkopt.cli", "optimize", a.mesh, "--height-mm", str(a.height_mm)]
        cmd += ["--out", str(out), "--iterations", str(a.iterations), "--threads", str(a.threads), "--eval-spp", "4"]
        subprocess.run(cmd, check=True, capture_output=True)
        rep = json.loads((out / "report.json").read_text())
        files = {p.name: p.stat().st_size for p in out.iterdir() if p.is_file()}
    est = rep["estimate"]
    run_disk = sum(files.get(n, 0) for n in ("volume.npz", "checkpoint.npz", "scene.npz"))
    data = {
        "height_mm": a.height_mm,
        "iterations": a.iterations,
        "threads": a.threads,
        "texels": rep["texels"],
        "free_voxels": rep["free_voxels"],
        "estimate": est,
        "measured": {
            "seconds_per_iteration": rep["seconds_per_iteration"],
            "peak_rss_gb_whole_run": rep["peak_rss_gb"],
            "disk_bytes_volume_checkpoint_scene": run_disk,
        },
        "ratio_time_estimate_to_measured": est["seconds_per_iteration"] / rep["seconds_per_iteration"],
        "ratio_disk_estimate_to_measured": est["disk_bytes"] / run_disk,
        "machine": machine(),
    }
    print(json.dumps(data, indent=1))
    write(f"estimate_{a.height_mm:g}mm.json", data)


if __name__ == "__main__":
    main()
