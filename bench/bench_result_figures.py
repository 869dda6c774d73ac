"""Time and accuracy of a mesh run's result figures (``runfigures.RunFigures.choose_finish`` and ``final``) on a
texel sample and on every texel, within the time a run's budget gives them: what a run does after its iterations.

    python bench/bench_result_figures.py [HEIGHT_MM=20] [--mesh spot.obj] [--only sample|every] [--name NAME]
        [-- OPTIONS ...]

``OPTIONS`` after ``--``: ``inkopt optimize``'s, read as the command line reads them (default ``--init white
--time-budget 1h``: the run's budget gives the result's figures ``runfigures.BUDGET_FINAL_FIGURES`` of what the
set-up leaves; a coarse-to-fine job's fine stage: ``--init DIR/coarse/fine_start.npz --shell-mm 1 --core white
--time-budget 2h``). The scene and the run's set-up are built once; the mixture of ``--init`` stands for the
result. Per way, from that mixture: a fresh ``RunFigures`` takes the way's texels (the sample as the run's start
chooses it, by its pilot: its seconds reported apart, its cost per sample standing for the start's figures'; or
every texel), then chooses the finishing smoothing and
measures the result's figures, timed together as a run spends them. Reported per way: those seconds, the figures,
their uncertainty as the baseline guard takes it (``error``), the samples per texel of the figures and of the
pictures' render, the finishing decision; and the difference of the two corrected mean ΔE76s against their combined
uncertainty. Writes the entry NAME (default ``spot<H>``) of bench/results/result_figures.json.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from types import SimpleNamespace

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "bench"))

RESULTS_FILE = "result_figures.json"
WAYS = ("sample", "every")


def measure(run, scene, cfg, way: str) -> dict:
    """The result's figures of ``run``'s current mixture measured ``way`` by a fresh ``RunFigures``, with their
    seconds (the finishing choice's and the figures'; the sample's pilot apart)."""
    from inkopt.evaluation.choice import SamplingChoice
    from inkopt.evaluation.noise import PILOT_SPP
    from inkopt.run import RunOptions
    from inkopt.runfigures import RunFigures

    options = RunOptions(log=lambda m: print(f"  {m}", flush=True))
    figures = RunFigures(SimpleNamespace(run=run, scene=scene, cfg=cfg, options=options))
    t = time.perf_counter()
    if way == "sample":
        figures._choose_sample(run.renderer(), PILOT_SPP)  # the run's choice before its start's figures
        cost = figures.choice.cost  # the seconds per sample the start's figures would measure: the pilot's
        figures.per_spp = None if cost is None else cost.seconds_per_texel_sample * len(scene.texels)
    else:
        figures.choice = SamplingChoice(None, True)
    pilot = time.perf_counter() - t
    t = time.perf_counter()
    choice = figures.choose_finish()
    chosen = time.perf_counter() - t
    result = figures.final()
    m = result.metrics
    return {
        "pilot_seconds": pilot,
        "choice_seconds": chosen,
        "seconds": time.perf_counter() - t,
        "final_budget": figures.final_budget,
        "finish": choice.to_json(),
        "delta_e76_mean_corrected": m.delta_e76_mean_corrected,
        "delta_e76_mean": m.delta_e76_mean,
        "ssim": m.ssim,
        "delta_e76_noise_contribution": m.delta_e76_noise_contribution,
        "error": result.error,
        "eval_spp": result.render.spp,
        "pictures_spp": result.pictures.spp,
        "first_pass_spp": result.render.passes[0],
        "texel_sample": result.sample,
    }


def main(argv=None) -> dict:
    from bench_start_figures import entry, record, set_up

    a, extra, scene, run, setup = set_up(argv, __doc__, ["--init", "white", "--time-budget", "1h"])
    x0, ways = run.x.copy(), {}
    for way in [a.only] if a.only else list(WAYS):
        run.x[:] = x0  # the finishing choice leaves the result smoothed or not
        ways[way] = measure(run, scene, run.cfg, way)
        run.release_renderer()
        print(f"{way}: {json.dumps(ways[way])}", flush=True)
    return record(RESULTS_FILE, a, entry(a, extra, scene, run, setup, ways, "error"))


if __name__ == "__main__":
    main()
