"""The run driver: one optimisation run of any scene, from start (or resume) to report (docs/run-dir.md).

``run_optimisation(scene, out_dir, cfg)``: write scene.npz, optimise with checkpoints (``resume`` continues
exactly), save volume.npz, then the final figures: the optimised and the initial volume rendered with seeds from
``2**62 + cfg.seed`` (never used by the optimisation) at ``eval_spp`` samples per texel if given, else adaptively
(``evaluation.noise.adaptive_render``: enough that the Monte Carlo noise adds at most ~0.5 to the mean ΔE76 and
SSIM's and the mottle's noise correction is accurate, at most 4096), compared with the target by
``evaluation.metrics.prediction_metrics``; the scene's pictures, loss.png and report.json
(``evaluation.results.Report``). The scene comes from user inputs through a spec (``scenes.spec``:
``SlabSpec(...).build(inks)``, ``MeshSpec(...).build(inks)``).
"""

from __future__ import annotations

import resource
import time

import numpy as np

from .distributed import renderer_factory
from .evaluation.baselines import baseline_mixture
from .evaluation.metrics import delta_e76_map, prediction_metrics
from .evaluation.noise import EVAL_SEED_OFFSET, adaptive_render
from .evaluation.results import Report
from .io import file_digest
from .lighting import Lighting, load_lighting
from .optim import Optimization, OptimizeConfig
from .pictures import loss_figure
from .rundir import Predictions, RunDir
from .scenes import Scene


def peak_rss_gb() -> float:
    """Peak resident memory of this process so far, GiB (Linux reports ru_maxrss in KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def run_optimisation(
    scene: Scene,
    out_dir,
    cfg: OptimizeConfig,
    *,
    resume: bool = False,
    eval_spp: int | None = None,
    threads: int | None = None,
    progress: bool = False,
    lighting: Lighting | str | None = None,
    ray: str | None = None,
    log=print,
) -> Report:
    """Optimise ``scene`` into run directory ``out_dir`` under the display ``lighting`` (default uniform; the
    final figures are rendered under it too); returns the report (also report.json). ``ray``: "auto" or a Ray
    cluster's address: every render is split into texel shards on Ray workers (``inkopt.distributed``; the
    results are bit-identical), ``threads`` then being each worker's."""
    with renderer_factory(ray, threads) as make_renderer:
        return _optimise(
            scene, out_dir, cfg, resume, eval_spp, threads, progress, load_lighting(lighting), log, make_renderer
        )


def _optimise(scene, out_dir, cfg, resume, eval_spp, threads, progress, lighting, log, make_renderer) -> Report:
    t_start = time.perf_counter()
    log(scene.describe())

    def baseline(kind: str) -> np.ndarray:  # a print-shop start (cfg.init "surface" or "extrusion")
        return baseline_mixture(
            kind, scene.volume, scene.texels, scene.target_rgb, scene.fixed_share, progress=progress
        )

    run = Optimization(
        scene.volume,
        scene.texels,
        scene.target_rgb,
        cfg,
        fixed_share=scene.fixed_share,
        threads=threads,
        baseline=baseline,
        lighting=lighting,
        renderer_factory=make_renderer,
        kind=scene.kind,
    )
    rd = RunDir.create(out_dir)
    if resume:
        run.resume(rd.checkpoint_path, log)
    rd.save_scene(scene.record())
    run.run(rd.checkpoint_path, progress=progress)
    run.release_renderer()  # not beside the writing of the result
    rd.save_volume_slabs(run.base, run.mixture_slabs(), run.base.inks)  # a slab of layers at a time

    # Final figures with seeds unused by the optimisation, adaptive spp unless given; the start is reconstructed
    # from the configuration (identical to the first iterate whether or not the run was resumed). The run's own
    # renderer (built again), set to the final then to the starting mixture (only the free voxels change: no
    # grid-sized volume), renders exactly what a renderer built from the result volume would.
    spp = int(eval_spp) if eval_spp else None  # None: adaptive
    seed = EVAL_SEED_OFFSET + cfg.seed
    renderer = run.renderer()

    def render(n: int, s: int):
        r = renderer.render(scene.texels, n, s, cfg.include_specular, progress)
        return r.rgb, r.var_mean, n

    res = adaptive_render(render, run.loss.target_lab, seed, spp, log=log)
    metrics = prediction_metrics(run.loss, res.rgb, res.var)
    run.renderer(run.initial_variables())
    res0 = adaptive_render(render, run.loss.target_lab, seed, spp, log=log)
    renderer = None  # the evaluation's renderer goes before the run's is released
    run.release_renderer()
    init = prediction_metrics(run.loss, res0.rgb, res0.var)
    de = delta_e76_map(run.loss, res.rgb)
    scene.write_pictures(rd, res.rgb, de)
    rd.save_predictions(
        Predictions(
            {"continuous": res.rgb},
            "optimisation",
            {"continuous": res.spp},
            file_digest(rd.volume_path),
            lighting.describe(),
        )
    )
    loss_figure(rd.loss_picture_path, run.history.loss, run.history.delta_e76)
    h = run.history
    n = max(len(h.seconds), 1)
    report = Report(
        metrics=metrics,
        initial_delta_e76_mean=init.delta_e76_mean,
        initial_ssim=init.ssim,
        initial_delta_e76_mean_corrected=init.delta_e76_mean_corrected,
        delta_e76_max=float(de.max()),
        iterations=run.iteration,
        spp=cfg.spp,
        eval_spp=res.spp,
        spp_adaptive=spp is None,
        eval_spp_passes=res.passes,
        initial_eval_spp=res0.spp,
        # this invocation's wall time (set-up, the iterations it ran, the evaluation); a resumed run's earlier
        # iterations are in the history, so seconds_iterations covers all of them
        seconds=time.perf_counter() - t_start,
        seconds_iterations=float(np.sum(h.seconds)),
        seconds_per_iteration=float(np.sum(h.seconds) / n),
        time_split={k: float(np.sum(getattr(h, k)) / n) for k in ("render_s", "gradient_s", "loss_s", "step_s")},
        scene=scene.report_fields(),
        inks=list(scene.volume.inks.names),
        gamma=list(cfg.gamma),
        lr=cfg.step_size,
        optimizer=cfg.optimizer,
        param=cfg.param,
        init=cfg.init,
        seed=cfg.seed,
        decay=cfg.decay,
        smooth=run.cfg.smooth,
        adjoint_ema=run.cfg.adjoint_ema,
        gradient=cfg.grad_method,
        threads=threads,
        peak_rss_gb=peak_rss_gb(),
        lighting=lighting.describe(),
    )
    rd.write_report(report.to_json())
    return report
