"""Coarse to fine: does optimising first on a coarser grid (150 DPI: 8x fewer voxels, 4x fewer texels), then at
300 DPI from its result, reach the quality of a plain 300-DPI run sooner? Writes experiments/results/coarse_to_fine.json
(one entry per NAME, updated in place).

    .venv/bin/python experiments/coarse_to_fine.py NAME (--height-mm H | --slab demo) [--coarse-dpi 150]
        [--coarse-iterations 40] [--fine-iterations 40] [--fine-lr 1] [--method linear] [--plain-iterations P]
        [--set KEY=VALUE ...] [--threads T] [--eval-spp N] [--out DIR]

Stages, each timed (wall seconds; the machine's load average is recorded with them):

1. coarse: the scene at ``--coarse-dpi`` (Spot at ``--height-mm``, or the demo slab: 6 x 4 x 1 mm, colour chart on
   top, zebra below), built and optimised for ``--coarse-iterations`` from the default start (no evaluation of the
   coarse result, which a coarse-to-fine run does not need);
2. transfer: its mixture moved onto the 300-DPI scene's free voxels and written as a start volume
   (``optim.transfer.coarse_start`` does 1 and 2; ``--method``);
3. fine: ``run_optimisation`` of the 300-DPI scene from that start for ``--fine-iterations`` at step ``--fine-lr``
   (a warm start calibrates the step scale on its smaller gradients; docs/experiments.md);
4. plain: ``run_optimisation`` of the 300-DPI scene from the default start for ``--plain-iterations``, by default
   as many as fit in the coarse-to-fine run's time (stages 1-2 plus the fine stage's iterations): first at the
   fine stage's seconds per iteration, then, if the plain run's own iteration times say another count fits (a
   white start's iterations cost more than a warm start's), once more with that count. The fine scene's
   voxelization and the runs' set-up and evaluations are not counted on either side.

Every entry records the final figures of both runs (noise-free corrected mean ΔE76, ΔE2000, SSIM, mottle; the
driver's adaptive evaluation), the start figures of the fine stage (the transferred start's quality), the training
ΔE76 of every iteration with its cumulative wall time, and the command. ``--compare-starts SPP`` also renders the
coarse result on its own scene and the transferred start of each method (after the transfer is timed) at SPP.
``--set`` applies to every stage (OptimizeConfig overrides, JSON values); seed 0 unless set. ``--out DIR`` keeps
the run directories (default: a temporary folder).
"""

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import STUDY_RESULTS as RESULTS  # noqa: E402
from common import machine, provenance
from common import write_study as write
from shell_compare import SPOT  # noqa: E402

from inkopt import charts  # noqa: E402
from inkopt.color import delta_e76, linear_to_lab  # noqa: E402
from inkopt.evaluation.metrics import prediction_metrics  # noqa: E402
from inkopt.evaluation.noise import EVAL_SEED_OFFSET  # noqa: E402
from inkopt.loss import TexelLoss  # noqa: E402
from inkopt.model import InkTable, Volume  # noqa: E402
from inkopt.optim import OptimizeConfig  # noqa: E402
from inkopt.optim.checkpoint import read_checkpoint  # noqa: E402
from inkopt.optim.transfer import coarse_start, write_transferred_volume  # noqa: E402
from inkopt.render import Renderer  # noqa: E402
from inkopt.run import RunOptions, run_optimisation  # noqa: E402
from inkopt.rundir import RunDir  # noqa: E402
from inkopt.scenes import build_scene  # noqa: E402
from inkopt.scenes.spec import MeshSpec, SlabSpec  # noqa: E402

FIGURES = (
    "initial_delta_e76_mean_corrected",
    "initial_ssim",
    "delta_e76_mean_corrected",
    "delta_e2000_mean",
    "ssim",
    "mottle_l2",
    "iterations",
    "seconds_iterations",
    "seconds_per_iteration",
    "eval_spp",
    "lr",
)


def spec_of(a, dpi: float, folder: Path):
    if a.slab == "demo":
        top = charts.save(charts.colour_chart(288, 192), folder / "chart.png")
        bottom = charts.save(charts.zebra(71, 47), folder / "zebra.png")
        return SlabSpec(top, (6.0, 4.0, 1.0), bottom=bottom, dpi=dpi)
    return MeshSpec(SPOT, height_mm=a.height_mm, dpi=dpi)


def curve(run_dir: Path, offset_s: float = 0.0) -> dict:
    """Training ΔE76 of every iteration and the cumulative wall seconds at its end (+ ``offset_s``)."""
    ck = read_checkpoint(RunDir(run_dir).checkpoint_path)
    return {
        "seconds": [round(float(v), 2) for v in offset_s + np.cumsum(ck["hist_seconds"])],
        "delta_e76": [round(float(v), 3) for v in ck["hist_delta_e76"]],
    }


def coarse_stage(a, inks, cfg, fine, folder: Path, log) -> tuple:
    """The coarse scene built and optimised and its result written as the fine run's start
    (``optim.transfer.coarse_start``): (the start's path, the coarse result's path, timings and training curve)."""
    t0 = time.perf_counter()
    scene = build_scene(spec_of(a, a.coarse_dpi, folder), inks)
    build_s = time.perf_counter() - t0
    log(f"coarse: {scene.describe()}")
    res = coarse_start(
        scene,
        fine,
        cfg,
        folder / "start.npz",
        threads=a.threads,
        method=a.method,
        log=log,
        coarse_path=folder / "coarse.npz",
    )
    info = {
        "dpi": a.coarse_dpi,
        "grid_zyx": list(scene.volume.shape),
        "texels": len(scene.texels),
        "iterations": res.iterations,
        "build_seconds": build_s,
        "setup_seconds": res.setup_seconds,
        "run_seconds": res.seconds,
        "seconds_per_iteration": res.seconds / max(res.iterations, 1),
        "training_delta_e76": [round(v, 3) for v in res.delta_e76],
    }
    return Path(res.path), folder / "coarse.npz", res.transfer_seconds, info


def figures(scene, volume, spp: int, threads, seed: int = EVAL_SEED_OFFSET) -> tuple:
    """Noise-corrected mean ΔE76 and SSIM of ``volume`` against ``scene``'s targets, one render at ``spp`` with an
    evaluation seed (a quick look at a start, not the driver's adaptive evaluation), and the render (I, 3)."""
    r = Renderer(volume, threads).render(scene.texels, spp, seed)
    m = prediction_metrics(TexelLoss(scene.target_rgb, scene.texels.pos_vox), r.rgb, r.var_mean)
    return {"delta_e76_mean_corrected": m.delta_e76_mean_corrected, "ssim": m.ssim, "spp": spp}, r.rgb


def nearest_gap(coarse_scene, coarse_rgb, fine, fine_rgb) -> float:
    """Mean ΔE76 between each fine texel's colour and that of the nearest coarse texel (mm) facing the same way:
    how far apart two per-texel colour sets of the two grids are (predictions: the transfer's change of the
    appearance, plus the renders' noise; targets: the detail the coarse grid cannot hold)."""
    from scipy.spatial import cKDTree

    def mm(scene):
        origin = 0.0 if scene.volume.origin_mm is None else scene.volume.origin_mm
        return origin + scene.texels.position_mm(scene.volume.voxel_mm)

    _, k = cKDTree(mm(coarse_scene)).query(mm(fine))
    same = np.sum(fine.texels.normal * coarse_scene.texels.normal[k], axis=1) > 0.5
    de = delta_e76(linear_to_lab(fine_rgb), linear_to_lab(coarse_rgb[k]))
    return float(de[same].mean())


def compare_starts(a, inks, src, fine, folder: Path) -> dict:
    """``--compare-starts``: the coarse result on its own scene and each method's transferred start on the fine
    scene, at ``--compare-starts`` spp; the gap between the fine start's and the coarse result's predictions,
    between two renders of the linear start (the noise floor of that gap) and between the two scenes' targets
    (``nearest_gap``)."""
    coarse_scene = build_scene(spec_of(a, a.coarse_dpi, folder), inks)
    out = {"target_gap_delta_e76": nearest_gap(coarse_scene, coarse_scene.target_rgb, fine, fine.target_rgb)}
    out["coarse_result"], coarse_rgb = figures(coarse_scene, src, a.compare_starts, a.threads)
    for method in ("linear", "nearest"):
        path = write_transferred_volume(src, fine.volume, fine.fixed_share, folder / f"start_{method}.npz", method)
        row, rgb = figures(fine, Volume.load(path), a.compare_starts, a.threads)
        out[f"start_{method}"] = {**row, "prediction_gap_delta_e76": nearest_gap(coarse_scene, coarse_rgb, fine, rgb)}
        if method == "linear":  # the gap's noise floor: two renders of one start with independent seeds
            _, again = figures(fine, Volume.load(path), a.compare_starts, a.threads, EVAL_SEED_OFFSET + 1)
            out["noise_gap_delta_e76"] = nearest_gap(fine, again, fine, rgb)
    print("starts:", json.dumps(out), flush=True)
    return out


def plain_stage(a, fine, folder: Path, iterations: int, kw: dict) -> dict:
    """The plain 300-DPI run of ``iterations`` from the default start: its figures and training curve."""
    cfg = OptimizeConfig(iterations=iterations, **kw)
    options = RunOptions(threads=a.threads, eval_spp=a.eval_spp, log=lambda s: None)
    rep = run_optimisation(fine, folder / "plain", cfg, options)
    row = {k: v for k, v in rep.to_json().items() if k in FIGURES}
    row["training"] = curve(folder / "plain")
    de = row["delta_e76_mean_corrected"]
    print(f"plain: {iterations} iterations, {row['seconds_iterations']:.1f} s, ΔE76 {de:.2f}", flush=True)
    return row


def equal_time_iterations(seconds: list, budget: float) -> int:
    """The iterations whose cumulative wall time (``seconds``, per iteration of a run) fits ``budget``; beyond the
    run's end at the mean time of its last quarter of iterations (the nearest count)."""
    seconds = np.asarray(seconds, np.float64)
    if budget <= seconds[-1]:
        return int(np.argmin(np.abs(seconds - budget))) + 1
    tail = np.diff(np.concatenate([[0.0], seconds]))[-max(1, len(seconds) // 4) :].mean()
    return len(seconds) + int(round((budget - seconds[-1]) / tail))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    what = ap.add_mutually_exclusive_group(required=True)
    what.add_argument("--height-mm", type=float, help="Spot at this height")
    what.add_argument("--slab", choices=("demo",), help="the demo slab")
    ap.add_argument("--coarse-dpi", type=float, default=150.0)
    ap.add_argument("--coarse-iterations", type=int, default=40)
    ap.add_argument("--fine-iterations", type=int, default=40)
    ap.add_argument("--fine-lr", type=float, default=1.0)
    ap.add_argument("--method", choices=("linear", "nearest"), default="linear")
    ap.add_argument("--plain-iterations", type=int, help="default: as many as fit in the coarse-to-fine time")
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="OptimizeConfig overrides (JSON values)")
    ap.add_argument("--threads", type=int)
    ap.add_argument("--eval-spp", type=int, help="final figures at this spp (default: adaptive)")
    ap.add_argument("--out", help="folder for the run directories (default: a temporary one)")
    ap.add_argument("--compare-starts", type=int, metavar="SPP", help="also render the starts of both methods")
    a = ap.parse_args()
    kw = {"seed": 0, **{k: json.loads(v) for k, v in (s.split("=", 1) for s in a.set)}}
    inks = InkTable.parse("vero-cmykw")
    quiet = lambda s: None  # noqa: E731
    load = {"before": os.getloadavg()[0]}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(a.out or tmp)
        folder.mkdir(parents=True, exist_ok=True)
        fine = build_scene(spec_of(a, 300.0, folder), inks)
        print(f"fine: {fine.describe()}", flush=True)

        cfg = OptimizeConfig(iterations=a.coarse_iterations, **kw)
        start, coarse_path, transfer_s, coarse = coarse_stage(a, inks, cfg, fine, folder, print)
        starts = compare_starts(a, inks, Volume.load(coarse_path), fine, folder) if a.compare_starts else None
        load["after_coarse"] = os.getloadavg()[0]
        before_fine = coarse["build_seconds"] + coarse["setup_seconds"] + coarse["run_seconds"] + transfer_s
        print(f"coarse stage and transfer: {before_fine:.1f} s (transfer {transfer_s:.1f} s)", flush=True)

        cfg = OptimizeConfig(iterations=a.fine_iterations, init=str(start), lr=a.fine_lr, **kw)
        options = RunOptions(threads=a.threads, eval_spp=a.eval_spp, log=quiet)
        rep = run_optimisation(fine, folder / "fine", cfg, options)
        fine_row = {k: v for k, v in rep.to_json().items() if k in FIGURES}
        fine_row["training"] = curve(folder / "fine", before_fine)
        total = before_fine + fine_row["seconds_iterations"]
        load["after_fine"] = os.getloadavg()[0]
        print(f"coarse to fine: {total:.1f} s, ΔE76 {fine_row['delta_e76_mean_corrected']:.2f}", flush=True)

        n_plain = a.plain_iterations or max(1, round(total / fine_row["seconds_per_iteration"]))
        plain_row, first = plain_stage(a, fine, folder, n_plain, kw), None
        if a.plain_iterations is None:  # a white start's iterations cost more: fit the count to the time, once
            n_fit = equal_time_iterations(plain_row["training"]["seconds"], total)
            if abs(n_fit - n_plain) > max(1, 0.05 * n_plain):
                first = {k: v for k, v in plain_row.items() if k != "training"}
                plain_row = plain_stage(a, fine, folder, n_fit, kw)
        load["after_plain"] = os.getloadavg()[0]
    row = {
        "scene": f"Spot {a.height_mm:g} mm" if a.slab is None else f"{a.slab} slab",
        "fine_grid_zyx": list(fine.volume.shape),
        "fine_texels": len(fine.texels),
        "method": a.method,
        "settings": kw,
        "coarse": coarse,
        "transfer_seconds": transfer_s,
        "starts": starts,
        "fine": fine_row,
        "coarse_to_fine_seconds": total,
        "plain": plain_row,
        "plain_first_try": first,
        "load_average_1min": load,
        "threads": a.threads,
    }
    for k in ("delta_e76_mean_corrected", "delta_e2000_mean", "ssim", "mottle_l2"):
        print(f"  {k}: coarse to fine {fine_row.get(k)}, plain {plain_row.get(k)}")
    path = RESULTS / "coarse_to_fine.json"
    out = json.loads(path.read_text()) if path.is_file() else {"results": {}}
    out["results"][a.name] = {**row, **provenance()}
    out.update(machine())
    write("coarse_to_fine.json", out)


if __name__ == "__main__":
    main()
