"""Benchmark of the mesh pipeline on Spot: voxelization time, seconds per optimisation iteration, peak memory.

    python bench/bench_mesh.py [HEIGHT_MM=40] [--iterations 3] [--spp 4] [--threads 2] [--shell-mm D] [--core C]
        [--smooth S] [--dpi 300] [--figure-metrics] [--baseline] [--renderer] [--code PYTHON_DIR] [--out JSON]

Writes bench/results/mesh_<height>mm.json (``--dpi`` other than 300: mesh_<height>mm_<dpi>dpi.json; the folder is
created if missing). Peak memory is the process's
resident-set high-water mark (getrusage), recorded after each stage; run one height per process.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# --code DIR: the package measured (another tree's python/, as bench_stages.py compares two); default this tree's
_CODE = sys.argv[sys.argv.index("--code") + 1] if "--code" in sys.argv[:-1] else str(ROOT / "python")
sys.path.insert(0, _CODE)
sys.path.insert(0, str(ROOT / "bench"))

SPOT = Path(__file__).resolve().parents[2] / "shared" / "data" / "spot" / "spot.obj"  # ../shared beside the repo
if not SPOT.is_file():  # a clone without ../shared: the copy the package ships
    SPOT = ROOT / "python" / "inkopt" / "data" / "spot" / "spot.obj"


def main(argv=None) -> dict:
    import numpy as np
    from common import provenance

    from inkopt.io import atomic_write_bytes
    from inkopt.model import InkTable
    from inkopt.optim import Optimization, OptimizeConfig
    from inkopt.run import peak_rss_gb
    from inkopt.scenes.mesh import build_mesh_scene
    from inkopt.scenes.spec import MeshSpec

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("height_mm", type=float, nargs="?", default=40.0)
    ap.add_argument("--mesh", default=str(SPOT))
    ap.add_argument("--iterations", type=int, default=3)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--shell-mm", type=float)
    ap.add_argument("--core", help="the fixed mixture below --shell-mm (as inkopt optimize --core; default: white)")
    ap.add_argument("--inks", default="vero-cmykw")
    ap.add_argument("--dpi", type=float, default=300.0, help="optimisation grid (a coarse-to-fine run's first stage)")
    ap.add_argument("--smooth", type=float, help="step smoothing width (default: the optimiser's default)")
    ap.add_argument("--out", help="JSON path (default bench/results/mesh_<height>mm.json)")
    ap.add_argument("--code", default=_CODE, help="python/ directory whose inkopt is measured (default this tree's)")
    ap.add_argument(
        "--figure-metrics",
        action="store_true",
        help="before the iterations, as a run's start figures: the figures' metrics of the target with a variance "
        "of 1e-4 (the loss's window and Sobel operators, SSIM with its noise correction, the mottle): their peak "
        "and seconds",
    )
    ap.add_argument(
        "--baseline",
        action="store_true",
        help="before the iterations, as a run's baseline guard: the extrusion baseline's variables (its nearest "
        "texel of every inside voxel): their peak and seconds",
    )
    ap.add_argument(
        "--renderer",
        action="store_true",
        help="after the set-up, build the run's renderer as its first iteration does (geometry, signed distances, "
        "medium): its peak and CPU seconds",
    )
    args = ap.parse_args(argv)

    import resource

    def cpu_s() -> float:  # user + system seconds of this process, all threads
        r = resource.getrusage(resource.RUSAGE_SELF)
        return r.ru_utime + r.ru_stime

    load0 = os.getloadavg()[0]
    rss = {"start": peak_rss_gb()}
    cpu = {"start": cpu_s()}
    t0 = time.perf_counter()
    core = {} if args.core is None else {"core": args.core}
    spec = MeshSpec(args.mesh, height_mm=args.height_mm, shell_mm=args.shell_mm, dpi=args.dpi, **core)
    scene = build_mesh_scene(spec, InkTable.parse(args.inks))
    build_s = time.perf_counter() - t0
    rss["after_voxelize"] = peak_rss_gb()
    cpu["after_voxelize"] = cpu_s()
    cfg = OptimizeConfig(
        iterations=args.iterations, spp=args.spp, **({} if args.smooth is None else {"smooth": args.smooth})
    )
    t0 = time.perf_counter()
    run = Optimization(scene, cfg.for_scene(scene.kind), threads=args.threads)
    setup_s = time.perf_counter() - t0
    rss["after_setup"] = peak_rss_gb()
    cpu["after_setup"] = cpu_s()
    print(f"set-up done: {scene.describe()}; peaks so far (GiB) {rss}", file=sys.stderr, flush=True)
    if args.renderer:
        run.renderer()
        rss["after_renderer"] = peak_rss_gb()
        cpu["after_renderer"] = cpu_s()
        print(f"renderer built; peaks so far (GiB) {rss}", file=sys.stderr, flush=True)
    figure_s = None
    if args.figure_metrics:  # as the start's figures, before the iterations
        from inkopt.evaluation.metrics import prediction_metrics

        t0 = time.perf_counter()
        target = run.loss.target_rgb
        prediction_metrics(run.loss, target, np.full_like(target, 1e-4))
        run.release_unread_operators()  # as a run does after its start's figures
        figure_s = time.perf_counter() - t0
        rss["after_figure_metrics"] = peak_rss_gb()
        cpu["after_figure_metrics"] = cpu_s()
        print(f"figure metrics in {figure_s:.1f} s; peaks so far (GiB) {rss}", file=sys.stderr, flush=True)
    baseline_s = None
    if args.baseline:  # as a run's baseline guard: the extrusion baseline's variables (its nearest texels)
        t0 = time.perf_counter()
        x_baseline = run.initial_variables("extrusion")
        del x_baseline
        baseline_s = time.perf_counter() - t0
        rss["after_baseline"] = peak_rss_gb()
        print(f"extrusion baseline in {baseline_s:.1f} s; peaks so far (GiB) {rss}", file=sys.stderr, flush=True)
    cpu0 = resource.getrusage(resource.RUSAGE_SELF)
    passes, iteration_cpu = [], []
    for i in range(args.iterations):
        c0 = cpu_s()
        info = run.step()
        iteration_cpu.append(cpu_s() - c0)
        passes.append(run.last_passes)
        h = run.history
        print(
            f"iteration {i + 1}: {h.seconds[-1]:.1f} s (render {h.render_s[-1]:.1f}, gradient "
            f"{h.gradient_s[-1]:.1f}), ΔE76 {info['delta_e76']:.2f}, peak {peak_rss_gb():.2f} GiB",
            file=sys.stderr,
        )
    rss["after_iterations"] = peak_rss_gb()
    media = medium_bytes(scene.volume)  # after the peak is read: its layer temporaries are not the run's
    cpu1 = resource.getrusage(resource.RUSAGE_SELF)
    cpu_per_iteration = (cpu1.ru_utime + cpu1.ru_stime - cpu0.ru_utime - cpu0.ru_stime) / max(args.iterations, 1)
    h = run.history
    nz, ny, nx = scene.volume.shape
    result = {
        "mesh": args.mesh,
        "height_mm": args.height_mm,
        "dpi": args.dpi,
        "grid_zyx": [nz, ny, nx],
        "voxels": nz * ny * nx,
        "inside_voxels": scene.vox.inside.count,
        "free_voxels": int(scene.free.sum()),
        "texels": len(scene.vox.texels),
        "shell_mm": args.shell_mm,
        "core": None if args.shell_mm is None else spec.core,
        "voxelize_seconds": scene.voxelize_seconds,
        "build_seconds": build_s,
        "setup_seconds": setup_s,
        # CPU seconds (user + system, all threads) of loading and voxelizing (with the scene's other arrays) and of
        # the optimiser's set-up
        "build_cpu_seconds": cpu["after_voxelize"] - cpu["start"],
        "setup_cpu_seconds": cpu["after_setup"] - cpu["after_voxelize"],
        "code": str(Path(args.code).resolve()),
        "iterations": args.iterations,
        "spp": args.spp,
        "threads": args.threads,
        "smooth": run.cfg.smooth,
        "adjoint_ema": run.cfg.adjoint_ema,
        "seconds_per_iteration": float(np.mean(h.seconds)) if h.seconds else None,
        "cpu_seconds_per_iteration": cpu_per_iteration,
        # CPU seconds (user + system, all threads) of each iteration, of the start's figures (--figure-metrics)
        "iteration_cpu_seconds": iteration_cpu,
        "figure_metrics_cpu_seconds": cpu["after_figure_metrics"] - cpu.get("after_renderer", cpu["after_setup"])
        if args.figure_metrics
        else None,
        # CPU seconds of building the run's renderer (--renderer)
        "renderer_cpu_seconds": cpu["after_renderer"] - cpu["after_setup"] if args.renderer else None,
        # the core's signed distances stored by bricks, once a renderer is built (None: not built, or code without it)
        "distance_storage": getattr(getattr(run, "_renderer", None), "distance_storage", None),
        # the machine's 1-minute load average (runnable threads, this process's included) at start and end
        "load_average_1min": {"start": load0, "end": os.getloadavg()[0]},
        "time_split": {
            k: float(np.mean(getattr(h, k))) if h.seconds else None
            for k in ("render_s", "gradient_s", "loss_s", "step_s")
        },
        "delta_e76_training": h.delta_e76,
        # events per path (free-flight collisions, real and null, plus boundary events) of the forward renders and
        # of the gradient passes' forward walks, summed over the iterations
        "events_per_path": {
            k: float(sum(p[k]["events"] for p in passes if p[k]) / max(sum(p[k]["paths"] for p in passes if p[k]), 1))
            for k in ("forward", "gradient")
        },
        "band_voxels": None if scene.volume.band is None else len(scene.volume.band.index),
        # bytes the core's medium holds in each form (sizes of its arrays, from the inside mask and the band)
        "medium_bytes": media,
        "peak_rss_gb": rss["after_iterations"],
        "peak_rss_gb_by_stage": rss,
        "figure_metrics_seconds": figure_s,
        "baseline_seconds": baseline_s,
        "machine": {"cpu": platform.processor() or platform.machine(), "python": platform.python_version()},
        "note": "CPU may be shared with other processes: wall-clock times are upper bounds; "
        "cpu_seconds_per_iteration (user + system, all threads) is not affected",
    }
    stem = f"mesh_{args.height_mm:g}mm" + ("" if args.dpi == 300 else f"_{args.dpi:g}dpi")
    out = Path(args.out) if args.out else ROOT / "bench" / "results" / f"{stem}.json"
    atomic_write_bytes(out, (json.dumps({**result, **provenance()}, indent=2) + "\n").encode())
    print(
        json.dumps(
            {
                k: result[k]
                for k in (
                    "grid_zyx",
                    "texels",
                    "voxelize_seconds",
                    "seconds_per_iteration",
                    "cpu_seconds_per_iteration",
                    "peak_rss_gb",
                    "events_per_path",
                )
            }
        )
    )
    return result


def medium_bytes(volume) -> dict:
    """Bytes of the core's medium for ``volume`` (inside mask and optional band) in the sparse form (16 per grid row,
    24 per voxel of each row's span from its first to its last inside voxel, 1 bit per such voxel) and, with a band,
    the band form (24 per band voxel, 12 per run of band or core voxels in a row, 4 per row); counted a layer at a
    time."""
    import numpy as np

    nz, ny, nx = volume.shape
    span = runs = 0
    band = None if volume.band is None else volume.band.index
    for z in range(nz):
        ins = volume.inside[z]
        cols = np.arange(nx)
        first = np.where(ins.any(1), np.argmax(ins, 1), nx)
        last = np.where(ins.any(1), nx - np.argmax(ins[:, ::-1], 1), nx)
        span += int((last - first).sum())
        if band is not None:
            cls = ins.astype(np.int8)
            lo, hi = np.searchsorted(band, [z * ny * nx, (z + 1) * ny * nx])
            cls.reshape(-1)[band[lo:hi] - z * ny * nx] = 2
            starts = (cls != 0) & ((cols == 0) | (np.roll(cls, 1, axis=1) != cls))
            runs += int(starts.sum())
    rows = nz * ny
    out = {"sparse": 16 * rows + 24 * span + span // 8}
    if band is not None:
        out["band"] = 24 * len(band) + 12 * runs + 4 * (rows + 1)
        out["band_runs"] = runs
    return out


if __name__ == "__main__":
    main()
