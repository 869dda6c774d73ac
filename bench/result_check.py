"""A run's result rendered again after its job, with enough samples for figures a short time budget's own report
cannot give (its final evaluation gets the little time left): the benchmarks' quality figure for a deadline run.

``result_check(scene, cfg, run_dir, spp)`` renders ``run_dir/volume.npz`` on ``scene``'s texels at ``spp`` samples
per texel (seeds disjoint from the run's and its evaluation's) and returns its noise-corrected figures. Not part of
any timed job.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from inkopt.evaluation.metrics import prediction_metrics
from inkopt.evaluation.noise import EVAL_SEED_OFFSET
from inkopt.optim import Optimization, OptimizeConfig

#: seed of the check render, beside the snapshots' (EVAL_SEED_OFFSET + 17 + iteration)
CHECK_SEED = EVAL_SEED_OFFSET + 11


def result_check(scene, cfg: OptimizeConfig, run_dir: Path, spp: int, threads: int = 2) -> dict:
    """Figures of ``run_dir``'s result (its volume.npz as a start is exactly its mixture, up to the softmax's
    floor of 1e-6) on ``scene`` (the run's own, built again): noise-corrected mean ΔE76 with its noise contribution,
    mean ΔE2000, SSIM, at ``spp`` samples per texel."""
    run = Optimization(
        scene, replace(cfg, init=str(Path(run_dir) / "volume.npz")).for_scene(scene.kind), threads=threads
    )
    r = run.renderer(run.x).render(scene.texels, spp, CHECK_SEED)
    m = prediction_metrics(run.loss, r.rgb, r.var_mean)
    return {
        "spp": spp,
        "delta_e76_mean_corrected": m.delta_e76_mean_corrected,
        "delta_e76_noise_contribution": m.delta_e76_noise_contribution,
        "delta_e2000_mean": m.delta_e2000_mean,
        "ssim": m.ssim,
    }
