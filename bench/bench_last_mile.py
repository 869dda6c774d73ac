"""What comes after the optimisation of a shell run: ``inkopt quantize``, ``export`` (GCVF and PNG slices),
``evaluate`` and ``report``, each its own process under ``/usr/bin/time -v``: wall and CPU seconds, peak resident
memory, bytes written (the file system's output blocks) and the size of what it leaves in the run folder, beside
the grid's counts (grid, inside and free voxels, texels, printer voxels and printed printer voxels).

    python bench/bench_last_mile.py run RUN_DIR HEIGHT_MM [--code CHECKOUT] [--name NAME] [--eval-spp N]
        [--stages quantize,export_gcvf,...]
    python bench/bench_last_mile.py extrapolate A.json B.json [--to-mm 100] [--name NAME]
    python bench/bench_last_mile.py size LABELS.npy --name NAME.json [--note TEXT]

``run``: RUN_DIR is an optimised run (e.g. ``inkopt optimize spot.obj --height-mm 40 --shell-mm 1 --iterations 1
--out RUN_DIR``); its earlier last-mile outputs are removed first. ``--code``: the checkout whose Python package
runs the stages (default this one), so two code trees can be measured on one run in one session. ``evaluate`` runs
with ``--spp N`` (default 16: its memory is the printer renderer's build, not the samples). Writes
bench/results/last_mile_<H>mm.json (``--name`` for another name).

``extrapolate``: two results of one code tree at two sizes fit each stage's peak memory, CPU seconds and bytes
written as a + b × printer voxels (exact through both points) and give them at ``--to-mm`` (printer voxels
scaled by the size ratio cubed from the larger one). Wall-clock times on the shared 2-core machine are upper
bounds; CPU seconds, memory and bytes do not depend on the load.

``size``: an existing version-1 labels file (quantized_labels.npy) written again as version 2 (a temporary file
beside this checkout's bench-out/): both sizes, the CPU seconds of writing and of reading it back whole, whether
the labels read back are the same, and bytes per printed printer voxel.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

STAGES = ("quantize", "export_gcvf", "export_png", "evaluate", "report")
#: what each stage holds per printer voxel or per grid voxel, from reading the code (kept beside the figures)
TERMS = {
    "quantize": "per printer layer only (a few (N, Y, X) float32 layers); writes 1 B per printer voxel "
    "(quantized_labels.npy) or the compressed layers; shading normals 20 B per printer voxel of a surface voxel",
    "export_gcvf": "per layer (labels, RGBA image, PNG); the labels file memory-mapped (its pages count as "
    "resident once read: 1 B per printer voxel) or decoded a layer at a time",
    "export_png": "as export_gcvf",
    "evaluate": "the run's mixture by its band (28 B per band voxel) and the band medium; the printer renderer's "
    "labels and distances by 8^3 bricks (a table entry per brick of one value), the labels read a layer at a time, "
    "the baselines through temporary layered files; per printer texel its texel and map",
    "report": "per scene texel and per predictions entry; nothing per voxel",
}


def timed(args: list[str], code: Path) -> dict:
    """``python -m inkopt ARGS`` with ``code``/python first on the path, under /usr/bin/time -v: seconds,
    CPU seconds, peak RSS (GiB), bytes written (GiB), stdout."""
    env = {**os.environ, "PYTHONPATH": str(code / "python")}
    proc = subprocess.run(
        ["/usr/bin/time", "-v", sys.executable, "-m", "inkopt", *args], capture_output=True, text=True, env=env
    )
    if proc.returncode:
        raise SystemExit(f"inkopt {' '.join(args)} failed:\n{proc.stdout}\n{proc.stderr[-3000:]}")
    err = proc.stderr
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", err).group(1)
    secs = sum(float(p) * 60**i for i, p in enumerate(reversed(wall.split(":"))))
    rss_kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", err).group(1))
    cpu = sum(float(re.search(rf"{k} time \(seconds\): (\S+)", err).group(1)) for k in ("User", "System"))
    blocks = int(re.search(r"File system outputs: (\d+)", err).group(1))
    return {
        "seconds": round(secs, 2),
        "cpu_seconds": round(cpu, 2),
        "peak_rss_gb": rss_kb / 2**20,
        "written_gb": blocks * 512 / 2**30,
        "stdout": proc.stdout.strip()[-2000:],
    }


def folder_bytes(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def counts(run: Path) -> dict:
    """The run's grid counts (volume.npz, scene.npz) and its printer grid's (quantized.npz)."""
    import numpy as np

    from inkopt.model.mixturefile import MixtureSource
    from inkopt.rundir import RunDir

    d = RunDir(run)
    with MixtureSource(d.volume_file()) as src:
        shape = [int(s) for s in src.shape[:3]]
        inside = None if src.inside is None else int(np.count_nonzero(src.inside))
    rec = d.load_scene()
    with np.load(d.quantized_path) as q:
        pshape = [int(s) for s in q["labels_shape"]]
        printed = int(q["label_counts"][:255].sum())
    free = None if rec.free_mask is None else int(np.count_nonzero(rec.free_mask))
    return {
        "grid_zyx": shape,
        "grid_voxels": int(np.prod(shape)) if shape else None,
        "inside_voxels": inside,
        "free_voxels": free,
        "texels": len(rec.texels),
        "printer_grid_zyx": pshape,
        "printer_voxels": int(np.prod(pshape)),
        "printed_printer_voxels": printed,
    }


def run_stages(run: Path, code: Path, eval_spp: int, stages=STAGES) -> dict:
    """Each of ``stages`` on ``run`` in order (its earlier outputs removed first): its ``timed`` figures and the
    bytes it left in the folder (``output_gb``)."""
    for name in ("quantized.npz", "quantized_labels.npy", "quantized_labels.layers", "slices.gcvf", "report.html"):
        (run / name).unlink(missing_ok=True)
    shutil.rmtree(run / "slices", ignore_errors=True)
    commands = {
        "quantize": ["quantize", str(run)],
        "export_gcvf": ["export", str(run), "--format", "gcvf"],
        "export_png": ["export", str(run)],
        "evaluate": ["evaluate", str(run), "--spp", str(eval_spp)],
        "report": ["report", str(run)],
    }
    out = {}
    for stage in stages:
        before = folder_bytes(run)
        res = timed(commands[stage], code)
        res["output_gb"] = (folder_bytes(run) - before) / 2**30
        res["command"] = "inkopt " + " ".join(commands[stage])
        out[stage] = res
        print(stage, {k: v for k, v in res.items() if k != "stdout"}, flush=True)
    return out


def git_commit(code: Path) -> str | None:
    proc = subprocess.run(["git", "rev-parse", "HEAD"], cwd=code, capture_output=True, text=True)
    return proc.stdout.strip() or None


def main_run(args) -> dict:
    from common import machine, write

    run, code = Path(args.run).resolve(), Path(args.code).resolve()
    load_before = os.getloadavg()[0]
    stages = run_stages(run, code, args.eval_spp, args.stages.split(","))
    res = {
        "run": str(run),
        "height_mm": args.height_mm,
        "code": str(code),
        "code_commit": git_commit(code),
        **counts(run),
        "stages": stages,
        "terms": TERMS,
        "eval_spp": args.eval_spp,
        "load_average_before": load_before,
        **machine(),
    }
    name = args.name or f"last_mile_{res['height_mm']:g}mm.json"
    print("wrote", write(name, res))
    return res


def fit(a: dict, b: dict, key: str, stage: str, n: float) -> float:
    """a + b × printer voxels through the two results' ``stage`` ``key``, at ``n`` printer voxels."""
    xa, xb = a["printer_voxels"], b["printer_voxels"]
    ya, yb = a["stages"][stage][key], b["stages"][stage][key]
    slope = (yb - ya) / (xb - xa)
    return ya + slope * (n - xa)


def main_extrapolate(args) -> dict:
    from common import machine, write

    a, b = (json.loads(Path(p).read_text()) for p in args.results)
    if a["printer_voxels"] > b["printer_voxels"]:
        a, b = b, a
    n = b["printer_voxels"] * (args.to_mm / b["height_mm"]) ** 3
    keys = ("peak_rss_gb", "cpu_seconds", "written_gb", "output_gb")
    common = [s for s in STAGES if s in a["stages"] and s in b["stages"]]
    est = {s: {k: fit(a, b, k, s, n) for k in keys} for s in common}
    dn = b["printer_voxels"] - a["printer_voxels"]
    per_voxel = {
        s: {f"{k}_per_printer_voxel": (b["stages"][s][k] - a["stages"][s][k]) / dn for k in keys} for s in common
    }
    for k in ("peak_rss_gb", "written_gb", "output_gb"):  # bytes per printer voxel read more easily
        for s in common:
            per_voxel[s][k.replace("_gb", "_bytes") + "_per_printer_voxel"] = (
                per_voxel[s].pop(f"{k}_per_printer_voxel") * 2**30
            )
    res = {
        "from": [str(p) for p in args.results],
        "heights_mm": [a["height_mm"], b["height_mm"]],
        "to_mm": args.to_mm,
        "printer_voxels_at_target": n,
        "per_printer_voxel": per_voxel,
        "estimate": est,
        "model": "each figure = a + b * printer voxels through the two measured sizes",
        **machine(),
    }
    name = args.name or f"last_mile_extrapolated_{args.to_mm:g}mm.json"
    print(json.dumps(est, indent=1))
    print("wrote", write(name, res))
    return res


def main_size(args) -> dict:
    import tempfile
    import time

    import numpy as np
    from common import machine, write

    from inkopt.model.labelfile import LabelLayersWriter, load_label_file

    src = Path(args.labels).resolve()
    lab = load_label_file(src)
    (ROOT / "bench-out").mkdir(exist_ok=True)
    with tempfile.TemporaryDirectory(dir=ROOT / "bench-out") as tmp:
        path = Path(tmp) / "labels.layers"
        t0 = time.process_time()
        w = LabelLayersWriter(path, lab.shape)
        for k in range(lab.shape[0]):
            w[k] = lab[k]
        w.commit()
        t1 = time.process_time()
        back = load_label_file(path)
        t2 = time.process_time()
        same = bool(np.array_equal(back, lab))
        size = path.stat().st_size
    printed = int(w.counts[:255].sum())
    res = {
        "labels_file": str(src),
        "shape_zyx": list(lab.shape),
        "printer_voxels": int(lab.size),
        "printed_printer_voxels": printed,
        "version1_bytes": src.stat().st_size,
        "version2_bytes": size,
        "ratio": src.stat().st_size / size,
        "version2_bytes_per_printed_voxel": size / printed,
        "write_cpu_seconds": t1 - t0,
        "read_cpu_seconds": t2 - t1,
        "labels_identical": same,
        "note": args.note,
        **machine(),
    }
    print(res)
    print("wrote", write(args.name, res))
    return res


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("run")
    r.add_argument("height_mm", type=float, help="the run's height (names the results file)")
    r.add_argument("--code", default=str(ROOT))
    r.add_argument("--name")
    r.add_argument("--eval-spp", type=int, default=16)
    r.add_argument("--stages", default=",".join(STAGES), help="comma list of the stages to run (default all)")
    e = sub.add_parser("extrapolate")
    e.add_argument("results", nargs=2)
    e.add_argument("--to-mm", type=float, default=100.0)
    e.add_argument("--name")
    z = sub.add_parser("size")
    z.add_argument("labels")
    z.add_argument("--name", required=True)
    z.add_argument("--note", default="")
    args = ap.parse_args()
    return {"run": main_run, "extrapolate": main_extrapolate, "size": main_size}[args.cmd](args)


if __name__ == "__main__":
    main()
