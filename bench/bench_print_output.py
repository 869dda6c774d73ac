"""Printer-resolution output of Spot at 40 mm: time and peak memory of ``inkopt quantize``, ``inkopt export`` (PNG
slices, GCVF, the volumetric 3MF of the mixture and of the labels) and ``inkopt inspect`` (of the GCVF with
``--run``, and of the labels 3MF), each a separate process measured by ``/usr/bin/time -v``.

    .venv/bin/python bench/bench_print_output.py [HEIGHT_MM=40] [--dir /tmp/inkopt_print_bench] [--reuse]

The run directory is made first in its own process (not measured): the mesh scene (``build_mesh_scene``,
vero-cmykw), a seeded random mixture (Dirichlet, alpha 1) on every inside voxel (white outside; a worse case
for the PNG encoder than an optimised object's white core) saved as volume.npz with the scene record, no
optimisation. ``--reuse`` keeps an existing one. Writes bench/results/print_output.json.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
SPOT = ROOT.parent / "shared" / "data" / "spot" / "spot.obj"


def build(out: Path, height_mm: float, mesh: str) -> None:
    import numpy as np

    from inkopt.model import InkTable
    from inkopt.rundir import RunDir
    from inkopt.scenes.mesh import build_mesh_scene
    from inkopt.scenes.spec import MeshSpec

    inks = InkTable.parse("vero-cmykw")
    scene = build_mesh_scene(MeshSpec(mesh, height_mm=height_mm), inks)
    vol = scene.volume
    mix = np.zeros(vol.shape + (len(inks),), np.float32)
    mix[..., inks.index("white")] = 1.0
    rng = np.random.default_rng(0)
    for z in range(vol.shape[0]):  # layer by layer: bounded temporaries
        ins = vol.inside[z]
        mix[z][ins] = rng.dirichlet(np.ones(len(inks)), size=int(ins.sum())).astype(np.float32)
    d = RunDir.create(out)
    d.save_volume(vol.with_mixture(mix))
    d.save_scene(scene.record())
    print(f"built {out}: grid {vol.shape}, {vol.inside.count} inside voxels")


def timed(args: list[str]) -> dict:
    """Run ``python -m inkopt.cli ARGS`` under /usr/bin/time -v: seconds, peak RSS (GB), stdout."""
    proc = subprocess.run(
        ["/usr/bin/time", "-v", sys.executable, "-m", "inkopt.cli", *args],
        capture_output=True,
        text=True,
        env={"PYTHONPATH": str(ROOT / "python"), "PATH": "/usr/bin:/bin"},
    )
    if proc.returncode:
        raise SystemExit(f"inkopt {' '.join(args)} failed:\n{proc.stdout}\n{proc.stderr}")
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", proc.stderr).group(1)
    secs = sum(float(p) * 60**i for i, p in enumerate(reversed(wall.split(":"))))
    rss_kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", proc.stderr).group(1))
    cpu = sum(float(re.search(rf"{k} time \(seconds\): (\S+)", proc.stderr).group(1)) for k in ("User", "System"))
    return {"seconds": secs, "cpu_seconds": cpu, "peak_rss_gb": rss_kb / 2**20, "stdout": proc.stdout.strip()}


def main() -> dict:
    from common import machine, write

    from inkopt.rundir import RunDir

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("height_mm", type=float, nargs="?", default=40.0)
    ap.add_argument("--dir", default="/tmp/inkopt_print_bench")
    ap.add_argument("--reuse", action="store_true")
    ap.add_argument("--mesh", default=str(SPOT))
    ap.add_argument("--build-only", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    out = Path(args.dir)
    if args.build_only:
        build(out, args.height_mm, args.mesh)
        return {}
    if not (args.reuse and RunDir.create(out).volume_path.is_file()):
        subprocess.run(
            [sys.executable, __file__, str(args.height_mm), "--dir", str(out), "--mesh", args.mesh, "--build-only"],
            check=True,
        )
    q = timed(["quantize", str(out)])
    e = timed(["export", str(out)])
    g = timed(["export", str(out), "--format", "gcvf"])
    t = timed(["export", str(out), "--format", "3mf"])
    tl = timed(["export", str(out), "--format", "3mf", "--labels"])
    ig = timed(["inspect", str(out / "slices.gcvf"), "--run", str(out)])
    it = timed(["inspect", str(out / "quantized.3mf")])
    import numpy as np

    d = RunDir(out)
    meta = np.load(d.quantized_path)
    shape = [int(v) for v in meta["labels_shape"]]
    res = {
        "mesh": Path(args.mesh).name,
        "height_mm": args.height_mm,
        "printer_grid_zyx": shape,
        "printer_voxels": int(np.prod(shape)),
        "ink_voxels": int(meta["label_counts"][:255].sum()),
        "quantize_seconds": q["seconds"],
        "quantize_cpu_seconds": q["cpu_seconds"],
        "quantize_peak_rss_gb": q["peak_rss_gb"],
        "export_seconds": e["seconds"],
        "export_cpu_seconds": e["cpu_seconds"],
        "export_peak_rss_gb": e["peak_rss_gb"],
        "gcvf_seconds": g["seconds"],
        "gcvf_cpu_seconds": g["cpu_seconds"],
        "gcvf_peak_rss_gb": g["peak_rss_gb"],
        **{
            f"{name}_{key}": r[k]
            for name, r in (("threemf", t), ("threemf_labels", tl), ("inspect_gcvf", ig), ("inspect_threemf", it))
            for key, k in (("seconds", "seconds"), ("cpu_seconds", "cpu_seconds"), ("peak_rss_gb", "peak_rss_gb"))
        },
        "labels_file_gb": d.quantized_labels_path.stat().st_size / 2**30,
        "slices_gb": sum(p.stat().st_size for p in d.slices_path.iterdir()) / 2**30,
        "gcvf_gb": d.gcvf_path.stat().st_size / 2**30,
        "threemf_gb": d.threemf_path().stat().st_size / 2**30,
        "threemf_labels_gb": d.threemf_path(labels=True).stat().st_size / 2**30,
        "output": {
            "quantize": q["stdout"],
            "export": e["stdout"],
            "gcvf": g["stdout"],
            "threemf": t["stdout"],
            "threemf_labels": tl["stdout"],
            "inspect_gcvf": ig["stdout"],
            "inspect_threemf": it["stdout"],
        },
        "targets": {"seconds": 120, "peak_rss_gb": 2, "inspect_peak_rss_gb": 1},
        **machine(),
        "note": "random mixture on every inside voxel (no optimisation); wall-clock times on a shared 2-core "
        "machine are upper bounds",
    }
    print({k: v for k, v in res.items() if k != "output"})
    print("wrote", write("print_output.json", res))
    return res


if __name__ == "__main__":
    main()
