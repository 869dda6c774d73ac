"""Time to quality: the noise-corrected mean ΔE76 of a run's result against the run's wall time, for Spot 20 mm,
Spot 40 mm and the reference slab, with the defaults or a variant of the settings.

    python bench/time_to_quality.py CASE NAME [--set KEY=VALUE ...] [--iterations N] [--snapshots 10,20,40]
        [--snap-spp 64] [--out-root bench-out/ttq] [--threads 2]

CASE: ``spot20``, ``spot40`` (Spot at 20 / 40 mm tall, mesh defaults) or ``reference`` (the reference slab,
15 x 10 x 2.5 mm, colour chart on top, zebra below: ``experiments/printable_eval.py``'s). NAME names the variant
(``default`` for the defaults); ``--set`` overrides ``OptimizeConfig`` fields (``--set init=extrusion
forward_spp=0``). One run per invocation through the run driver (``inkopt.run.run_optimisation``, as ``inkopt
optimize`` / ``slab`` run it: set-up, the start's figures, the iterations, the result's figures), into
``OUT_ROOT/CASE/NAME``; ``--resume`` continues it from its checkpoint (a 300-iteration 40 mm reference takes hours).

The variables are kept at the ``--snapshots`` iterations; after the run, each snapshot's mixture is rendered at
``--snap-spp`` samples per texel (seeds disjoint from the optimisation's) and its ΔE76 corrected for the Monte Carlo
noise (``evaluation.noise``; the noise's contribution is recorded beside it: the correction is accurate to ~30 % of
it). A snapshot is a point on the run's trajectory, not a finished run (the step decay has not run there); the
result (the run's end) is the run's own adaptive evaluation (report.json, noise-free unless capped); under a short
time budget that evaluation has few samples, so the result is also rendered after the job (not timed) at
``--final-spp`` samples per texel, seeds disjoint from the run's, and its figures kept as ``result_check``.
``--snap-evaluate`` measures each snapshot as ``--evaluate`` (below) measures a result instead: its mixture written as
the run directory OUT/snapshot_N, its figures noise-free on the texel sample (at 40 mm about the time of a 64-spp
render of every texel, whose figures are good to ±1 ΔE76 there). ``--snap-spp 0`` leaves the snapshots' mixtures on
disk unmeasured (``--snapshots-only`` measures them later) and
``--final-spp 0`` skips the check (a long run's own evaluation has more samples than the check would): a long
reference then ends with its own evaluation. Wall times: ``seconds_job`` from the start (set-up, the start's
figures, iterations), ``seconds_iterations`` the iterations' own. Writes the entry "CASE/NAME" of
``bench/results/time_to_quality.json``.

    python bench/time_to_quality.py CASE NAME --evaluate [--texel-sample 4000] [--sample-windows 400]
        [--eval-time-budget 600]

evaluates a finished run's result as ``inkopt evaluate RUN --no-baselines --time-budget S`` does, on a texel sample
(the same sample and seeds for every run of a case, so two runs' figures compare; each figure with its sampling
standard error), and keeps it as the entry's ``evaluation`` (an earlier evaluation of the same
volume.npz and settings is reused). The continuous result needs less than its share of the time to be noise-free;
the printed one (at printer resolution, several times dearer) gets the rest, its noise corrected and reported. A
long reference run is compared with a deadline's this way.

    python bench/time_to_quality.py --plot docs/time_to_quality.png

draws every entry's snapshots and result (ΔE76 against minutes of the job; of the result's own figure, its
re-render after the job and its evaluation, the least noisy: ``best_figure``; error bars: the noise correction's
accuracy), a panel per case, with the case's reference line where its run is recorded (``REFERENCES``).
"""

import argparse
import json
import shutil
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from common import RESULTS, SPOT, machine, provenance, write
from result_check import result_check

from inkopt import charts
from inkopt.coarse import run_coarse_to_fine
from inkopt.evaluation.metrics import prediction_metrics
from inkopt.evaluation.noise import ESTIMATE_RANGE, EVAL_SEED_OFFSET
from inkopt.evaluation.results import Report
from inkopt.io import file_digest
from inkopt.model import InkTable
from inkopt.optim import Optimization, OptimizeConfig
from inkopt.run import RunOptions, run_optimisation
from inkopt.rundir import RunDir
from inkopt.scenes import build_scene
from inkopt.scenes.spec import MeshSpec, SlabSpec

ROOT = Path(__file__).resolve().parent.parent
VOX = 25.4 / 300
RESULTS_FILE = "time_to_quality.json"
#: how closely a noise-corrected ΔE76 is known, as a fraction of the noise's contribution: the estimated
#: contribution lies within ``ESTIMATE_RANGE`` of the true one (``evaluation.noise``)
CORRECTION_ACCURACY = max(abs(1 - f) for f in ESTIMATE_RANGE)


def spec_of(case: str, out: Path):
    if case.startswith("spot") and case[4:].isdigit():  # spot20, spot40 (any height in mm: spot6 to try it)
        return MeshSpec(str(SPOT), height_mm=float(case[4:]))
    if case == "reference":
        top = charts.save(charts.colour_chart(708, 472), out / "reference_top.png")
        bottom = charts.save(charts.zebra(177, 118), out / "reference_bottom.png")
        return SlabSpec(str(top), (177 * VOX, 118 * VOX, 30 * VOX), bottom=str(bottom))
    raise SystemExit(f"unknown case '{case}': use spot20, spot40 or reference")


def parse_set(items) -> dict:
    fields = OptimizeConfig.__dataclass_fields__
    out = {}
    for item in items:
        key, _, value = item.partition("=")
        if key not in fields:
            raise SystemExit(f"--set {item}: unknown setting '{key}'")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


#: each case's long reference run: (results file under the repository, path of keys to its entry); its noise-free
#: ΔE76 (corrected) is the entry's ``delta_e76_mean_corrected`` (a time-to-quality entry's: ``best_figure``'s). A
#: case whose run has not landed (its entry missing) draws no reference line.
REFERENCES = {
    "spot20": ("experiments/results/mesh_convergence.json", ("results", "spot20_default_300")),
    "spot40": (f"bench/results/{RESULTS_FILE}", ("results", "spot40/reference")),
    "reference": ("experiments/results/reference_converged.json", ("final_450",)),
}
#: the texel sample of ``--evaluate`` (``inkopt evaluate``'s --texel-sample and --sample-windows) and its time for
#: the renders (seconds): Spot 40 mm's continuous result is noise-free in ~70 s of the 2 cores
EVAL_TEXELS, EVAL_WINDOWS, EVAL_SECONDS = 4000, 400, 600.0


def best_figure(entry: dict) -> dict:
    """Of a time-to-quality entry's figures of its result (the run's own, its re-render after the job, its
    evaluation's continuous result), the one whose noise contributes least to its ΔE76."""
    ev = (entry.get("evaluation") or {}).get("continuous")
    figures = [entry["result"], entry.get("result_check"), ev]
    return min(filter(None, figures), key=lambda x: x["delta_e76_noise_contribution"])


def figure_error(fig: dict) -> float:
    """How far a figure's ΔE76 may be off: the noise correction's accuracy and, for a sampled evaluation's, its
    sampling standard error, combined as independent."""
    se = (fig.get("stderr") or {}).get("delta_e76_mean_corrected") or 0.0
    return float(np.hypot(CORRECTION_ACCURACY * fig["delta_e76_noise_contribution"], se))


def reference_value(case: str) -> float | None:
    """The noise-free ΔE76 (corrected) of ``case``'s long reference run, or None (no run recorded)."""
    if case not in REFERENCES:
        return None
    path, keys = REFERENCES[case]
    entry = json.loads((ROOT / path).read_text())
    for k in keys:
        if k not in entry:
            return None
        entry = entry[k]
    return float((best_figure(entry) if "result" in entry else entry)["delta_e76_mean_corrected"])


def plot(path: str) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    results = json.loads((RESULTS / RESULTS_FILE).read_text())["results"]
    cases = sorted({e["case"] for e in results.values()})
    fig, axes = plt.subplots(1, len(cases), figsize=(5.5 * len(cases), 4.2), squeeze=False)
    for ax, case in zip(axes[0], cases):
        for _key, e in sorted(results.items()):
            if e["case"] != case or e["name"] == "reference":  # a case's long reference run is its line
                continue
            # error bars: the noise correction's accuracy and a sampled figure's standard error (figure_error)
            pts = e["snapshots"]
            line = ax.errorbar(
                [p["seconds_job"] / 60 for p in pts],
                [p["delta_e76_mean_corrected"] for p in pts],
                yerr=[figure_error(p) for p in pts],
                fmt="o-",
                ms=3,
                capsize=2,
                label=e["name"],
            ).lines[0]
            r = best_figure(e)
            ax.errorbar(
                [e["result"]["seconds_total"] / 60],
                [r["delta_e76_mean_corrected"]],
                yerr=[figure_error(r)],
                fmt="*",
                ms=12,
                capsize=2,
                color=line.get_color(),
            )
        value = reference_value(case)
        if value is not None:
            ax.axhline(value, color="k", lw=0.8, ls="--", label="long reference")
            ax.axhline(value + 1, color="k", lw=0.8, ls=":", label="reference + 1")
        ax.set_title(case)
        ax.set_xlabel("wall time of the job so far (min; snapshots: dots, result: star)")
        ax.set_ylabel("mean ΔE76, noise-corrected")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")
    return 0


def sampled_evaluation(run_dir: Path, texels: int, windows: int, seconds: float, threads: int):
    """``run_dir``'s result evaluated as ``inkopt evaluate RUN --no-baselines --texel-sample T --sample-windows W
    --time-budget S`` does (``evaluation.Evaluation``), into RUN/ttq_evaluation_T_W_Ss.json; an earlier one of the
    same volume.npz and settings is reused."""
    from inkopt.evaluation.evaluate import evaluate_run
    from inkopt.evaluation.options import EvaluateOptions
    from inkopt.evaluation.results import Evaluation

    out = run_dir / f"ttq_evaluation_{texels}_{windows}_{seconds:g}s.json"
    ev = Evaluation.read(out) if out.is_file() else None
    if ev is None or ev.volume_digest != file_digest(run_dir / "volume.npz"):
        log = lambda m: print(m, file=sys.stderr, flush=True)  # noqa: E731
        options = EvaluateOptions(
            baselines=False,
            threads=threads,
            out=out,
            texel_sample=texels,
            sample_windows=windows,
            time_budget=seconds,
        )
        ev = evaluate_run(run_dir, options, log)
    return ev


def evaluation_entry(ev, run_dir: Path, texels: int, windows: int, seconds: float) -> dict:
    """What an entry keeps of a sampled evaluation (``sampled_evaluation``)."""
    d = ev.to_json()
    return {
        "command": f"inkopt evaluate {run_dir} --no-baselines --texel-sample {texels} --sample-windows {windows} "
        f"--time-budget {seconds:g}",
        **{k: d[k] for k in ("spp", "seconds", "texel_sample", "volume_digest")},
        "continuous": d["continuous"],
        "quantized": d["quantized"],
        "evaluated": {"machine": machine(), **provenance()},
    }


def evaluate(case: str, name: str, run_dir: Path, texels: int, windows: int, seconds: float, threads: int) -> int:
    """``--evaluate``: the entry "CASE/NAME" (its run finished) gets its result's sampled evaluation (module
    docstring)."""
    key, path = f"{case}/{name}", RESULTS / RESULTS_FILE
    results = json.loads(path.read_text())["results"] if path.is_file() else {}
    if key not in results:
        raise SystemExit(f"no entry {key} in {path}: run it first")
    ev = sampled_evaluation(run_dir, texels, windows, seconds, threads)
    results[key]["evaluation"] = evaluation_entry(ev, run_dir, texels, windows, seconds)
    write(RESULTS_FILE, {"results": results})
    m, se = ev.continuous.metrics, ev.continuous.stderr
    print(f"{key}: continuous ΔE76 {m.delta_e76_mean_corrected:.2f} ± {se['delta_e76_mean_corrected']:.2f}")
    return 0


def measure_snapshots(a, out: Path, scene, cfg: OptimizeConfig, times: dict) -> list[dict]:
    """The figures of the run's snapshots (``OUT/x_N.npy``, their times in ``times``): each rendered at
    ``--snap-spp`` with one renderer of the run's problem (geometry and fixed shares; its start does not matter) set
    to the snapshot's variables, or with ``--snap-evaluate`` written as the run directory OUT/snapshot_N and
    evaluated on the texel sample (``sampled_evaluation``)."""
    run = Optimization(scene, replace(cfg, init="white").for_scene(scene.kind), threads=2)
    if a.snap_evaluate:
        run.release_renderer()
    points = []
    for it in sorted(int(k) for k in times):
        path = out / f"x_{it}.npy"
        if not path.is_file():
            continue
        extra = {}
        if a.snap_evaluate:
            d = out / f"snapshot_{it}"
            if not (d / "volume.npz").is_file():
                d.mkdir(exist_ok=True)
                shutil.copyfile(out / "run" / "scene.npz", d / "scene.npz")
                RunDir(d).save_volume_slabs(run.base, run.param.mixture_slabs(np.load(path)), run.base.inks)
            ev = sampled_evaluation(d, a.texel_sample, a.sample_windows, a.eval_time_budget, a.threads)
            m, extra = ev.continuous.metrics, {"spp": ev.continuous.spp, "stderr": ev.continuous.stderr}
        else:
            r = run.renderer(np.load(path)).render(scene.texels, a.snap_spp, EVAL_SEED_OFFSET + 17 + it)
            m = prediction_metrics(run.loss, r.rgb, r.var_mean)
        points.append(
            {
                "iteration": it,
                **times[str(it)],
                "delta_e76_mean_corrected": m.delta_e76_mean_corrected,
                "delta_e76_noise_contribution": m.delta_e76_noise_contribution,
                "delta_e2000_mean": m.delta_e2000_mean,
                "ssim": m.ssim,
                **extra,
            }
        )
        print(f"iteration {it}: ΔE76 {m.delta_e76_mean_corrected:.2f} (noise {m.delta_e76_noise_contribution:.2f})")
    return points


#: the keys of a run's report.json that an entry keeps as its ``result``
RESULT_KEYS = (
    "iterations",
    "stop",
    "delta_e76_mean_corrected",
    "delta_e76_noise_contribution",
    "delta_e2000_mean",
    "ssim",
    "initial_delta_e76_mean_corrected",
    "initial_ssim",
    "eval_spp",
    "initial_eval_spp",
    "seconds",
    "seconds_total",
    "seconds_iterations",
    "seconds_per_iteration",
    "peak_rss_gb",
)


def parse_args():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("case")
    ap.add_argument("name")
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE")
    ap.add_argument("--iterations", type=int, default=OptimizeConfig().iterations)
    ap.add_argument("--snapshots", default="10,20,30,45,60,90,120,180,240,300")
    ap.add_argument("--snap-spp", type=int, default=64, help="samples per texel of the snapshots (0: not rendered)")
    ap.add_argument("--eval-max-spp", type=int, default=1024)
    ap.add_argument("--out-root", default="bench-out/ttq")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--resume", action="store_true")
    ap.add_argument("--coarse-dpi", type=float, help="coarse to fine (``inkopt.coarse.run_coarse_to_fine``)")
    ap.add_argument("--snapshots-only", action="store_true", help="the run is done: its report and snapshots")
    ap.add_argument("--final-spp", type=int, default=256, help="samples per texel of the result's check (0: none)")
    ap.add_argument("--evaluate", action="store_true", help="the run is done: its result's sampled evaluation")
    ap.add_argument("--texel-sample", type=int, default=EVAL_TEXELS)
    ap.add_argument("--sample-windows", type=int, default=EVAL_WINDOWS)
    ap.add_argument("--eval-time-budget", type=float, default=EVAL_SECONDS, help="seconds of --evaluate's renders")
    ap.add_argument("--snap-evaluate", action="store_true", help="snapshots evaluated as --evaluate does instead")
    return ap.parse_args()


def main() -> int:
    if sys.argv[1:2] == ["--plot"]:
        return plot(sys.argv[2])
    a = parse_args()
    out = Path(a.out_root) / a.case / a.name
    if a.evaluate:
        return evaluate(a.case, a.name, out / "run", a.texel_sample, a.sample_windows, a.eval_time_budget, a.threads)
    out.mkdir(parents=True, exist_ok=True)
    overrides = parse_set(a.set)
    cfg = OptimizeConfig(**{"iterations": a.iterations, **overrides})
    cfg.validate()
    spec = spec_of(a.case, out.parent)
    inks = InkTable.parse("vero-cmykw")
    t0 = time.perf_counter()
    scene = build_scene(spec, inks)  # the fine scene (of a coarse-to-fine run too: its snapshots are the fine stage's)
    snaps = {int(s) for s in a.snapshots.split(",") if s}
    times_path = out / "snapshot_times.json"
    times = json.loads(times_path.read_text()) if (a.resume or a.snapshots_only) and times_path.is_file() else {}

    def keep(run: Optimization) -> None:
        if run.iteration in snaps:
            np.save(out / f"x_{run.iteration}.npy", run.x)
            times[str(run.iteration)] = {
                "seconds_job": run.wall_seconds(),
                "seconds_iterations": float(np.sum(run.history.seconds)),
                "training_delta_e76": run.history.delta_e76[-1],
            }
            times_path.write_text(json.dumps(times))

    options = RunOptions(
        resume=a.resume,
        threads=a.threads,
        log=lambda m: print(m, file=sys.stderr, flush=True),
        started=t0,
        on_step=keep,
        eval_max_spp=a.eval_max_spp,
    )
    if a.snapshots_only:
        rep = Report.read(out / "run" / "report.json")
    elif a.coarse_dpi:
        rep = run_coarse_to_fine(spec, inks, out / "run", cfg, a.coarse_dpi, options)
    else:
        rep = run_optimisation(scene, out / "run", cfg, options)
    # with --snap-spp 0 the snapshots' mixtures stay on disk for a later --snapshots-only
    points = measure_snapshots(a, out, scene, cfg, times) if a.snap_spp > 0 or a.snap_evaluate else []
    check = result_check(scene, cfg, out / "run", a.final_spp) if a.final_spp > 0 else None
    r = rep.to_json()
    entry = {
        "case": a.case,
        "name": a.name,
        "settings": overrides,
        "coarse_dpi": a.coarse_dpi,
        "max_iterations": a.iterations,
        "snap_spp": a.snap_spp,
        "snapshots": points,
        "result_check": check,
        "result": {k: r[k] for k in RESULT_KEYS},
        "machine": machine(),
        **provenance(),
    }
    previous = RESULTS / RESULTS_FILE
    results = json.loads(previous.read_text())["results"] if previous.is_file() else {}
    prev = results.get(f"{a.case}/{a.name}", {})
    if a.snapshots_only:  # what this invocation did not measure again stays
        entry["snapshots"] = entry["snapshots"] if a.snap_spp > 0 or a.snap_evaluate else prev.get("snapshots", [])
        entry["result_check"] = check if a.final_spp > 0 else prev.get("result_check")
    ev = prev.get("evaluation")
    if ev is not None and ev["volume_digest"] == file_digest(out / "run" / "volume.npz"):
        entry["evaluation"] = ev
    results[f"{a.case}/{a.name}"] = entry
    write(RESULTS_FILE, {"results": results})
    print(json.dumps(entry["result"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
