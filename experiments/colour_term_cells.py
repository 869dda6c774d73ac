"""Two whole mesh-suite cells of one mesh, size and budget, one optimised with each colour term, compared on one texel
sample: the decision of the meshes' default colour term (``optim.config.SCENE_DEFAULTS``).

    nice -n 5 .venv/bin/python experiments/colour_term_cells.py NAME --squared RUN --linear RUN [--texels 1500]
        [--seed 0] [--evaluations DIR]

Each run folder is a whole coarse-to-fine job (``bench/mesh_suite.py run ... --variant linear --optimize-args
'--colour-term linear'`` and the default cell of the same budget). Each is evaluated as ``inkopt evaluate RUN
--texel-sample T --seed S --out DIR/NAME_ARM.json`` does (an evaluation file already there is read, not made again):
the same texels and seeds in both, so both arms' print-shop baselines are the same renders and each arm's
printed − extrusion difference is paired on those texels. The entry NAME of experiments/results/colour_term_cells.json
holds both arms' figures and paired differences, and linear − squared for the print: the difference of the arms'
printed − extrusion differences (the same baseline render cancels), whose standard error is at most the sum of
the two paired standard errors (the per-texel values of a sampled evaluation are not written, so the arms cannot
be paired texel by texel across two evaluations; the sum bounds the standard deviation of a difference whatever
its correlation).
"""

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import add_study_entry, machine, provenance  # noqa: E402

from inkopt.evaluation.evaluate import evaluate_run  # noqa: E402
from inkopt.evaluation.options import EvaluateOptions  # noqa: E402

ARMS = ("squared", "linear")
FIGURES = ("delta_e76_corrected", "delta_e2000", "ssim")
#: each figure's key in an evaluation file's differences
FIGURE_KEYS = {"delta_e76_corrected": "delta_e76_mean_corrected", "delta_e2000": "delta_e2000_mean", "ssim": "ssim"}
PAIR = "printed - extrusion"


def evaluation(run: Path, out: Path, texels: int, seed: int) -> dict:
    """The evaluation file ``out`` of ``run`` on ``texels`` sampled texels with ``seed``, made when missing."""
    if not out.is_file():
        evaluate_run(run, EvaluateOptions(seed=seed, texel_sample=texels, out=out))
    ev = json.loads(out.read_text())
    sample = ev.get("texel_sample") or {}
    if sample.get("texels") != texels or ev.get("seed", seed) != seed:
        raise SystemExit(f"{out}: not an evaluation of {texels} sampled texels with seed {seed}")
    return ev


def paired(ev: dict, baseline: str = "extrusion") -> dict:
    """printed − ``baseline`` of an evaluation file: figure -> {"value", "stderr"} (the keys of ``FIGURES``)."""
    diffs = ev.get("differences") or {}
    d = diffs.get(f"quantized - {baseline} baseline") or diffs.get(f"quantized - {baseline}")
    if d is None:
        raise SystemExit(f"no printed - {baseline} difference among {sorted(diffs)}: not a sampled evaluation")
    return {k: d[v] for k, v in FIGURE_KEYS.items()}


def baseline_figures(ev: dict) -> dict:
    """The print-shop baselines' figures of an evaluation file (name -> the figures of ``FIGURES`` with their standard
    errors): the same in two evaluations of one object on one texel sample with one seed."""
    keys = ("delta_e76_mean_corrected", "delta_e2000_mean", "ssim")
    return {name: {k: (m[k], m["stderr"].get(k)) for k in keys} for name, m in (ev.get("baselines") or {}).items()}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    ap.add_argument("--squared", type=Path, required=True, help="the cell optimised with the mean dE76^2")
    ap.add_argument("--linear", type=Path, required=True, help="the cell optimised with the mean dE76")
    ap.add_argument("--texels", type=int, default=1500)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--evaluations", type=Path, default=Path("."), help="folder of the arms' evaluation files")
    a = ap.parse_args()
    entry = {**provenance(), "texels": a.texels, "seed": a.seed}
    diffs = {}
    for arm in ARMS:
        run = getattr(a, arm)
        out = a.evaluations / f"{a.name}_{arm}.json"
        ev = evaluation(run, out, a.texels, a.seed)
        report = json.loads((run / "report.json").read_text())
        diffs[arm] = paired(ev)
        entry[arm] = {
            "run": str(run),
            "evaluation": str(out),
            "colour_term": report.get("colour_term") or "squared",
            "printed_minus_extrusion": diffs[arm],
            "figures": {
                k: {f: ev[k][f] for f in ("delta_e76_mean_corrected", "delta_e2000_mean", "ssim", "stderr")}
                for k in ("continuous", "quantized")
            },
            "baselines": baseline_figures(ev),
        }
    if entry["squared"]["baselines"] != entry["linear"]["baselines"]:
        raise SystemExit("the arms' baselines differ: not the same texel sample and seeds")
    entry["linear_minus_squared"] = {
        f: {
            "value": diffs["linear"][f]["value"] - diffs["squared"][f]["value"],
            "stderr_bound": diffs["linear"][f]["stderr"] + diffs["squared"][f]["stderr"],
        }
        for f in FIGURES
    }
    for f, v in entry["linear_minus_squared"].items():
        print(f"{a.name}: linear - squared, printed {f}: {v['value']:+.3f} (stderr <= {v['stderr_bound']:.3f})")
    entry.update(machine())
    add_study_entry("colour_term_cells.json", a.name, entry)


if __name__ == "__main__":
    main()
