"""How far the figures of one result read apart between texel samples, against the standard errors each sampled
evaluation reports: the check of the suite's standard errors (docs/quality.md, "Mesh suite").

    nice -n 5 .venv/bin/python experiments/sample_spread.py NAME RUN [--seeds 0,1,2,3,4] [--texels 1500]
        [--evaluations DIR] [--also E.json ...]

RUN is evaluated once per seed as ``inkopt evaluate RUN --texel-sample T --seed S --out DIR/NAME_sS.json`` does (an
evaluation file already there is read, not made again): each seed draws its own simple random sample of texels and
its own render seeds; the result and its print are the same in all. ``--also``: further evaluation files of the same
run (e.g. the suite cell's own, whose sample size a pilot chose). For each paired difference of ours against a
baseline (printed − extrusion, printed − surface) and each figure (ΔE76 noise-corrected, ΔE2000, SSIM) the entry
NAME of experiments/results/sample_spread.json holds every sample's value and standard error, their mean, the
standard deviation between samples, the root mean square of the reported standard errors and their ratio, and the
chi-square statistic (k − 1) s² / RMS(se)² with its upper tail probability under k − 1 degrees of freedom (small:
the samples spread more than their standard errors allow).
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import add_study_entry, machine, provenance  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from colour_term_cells import FIGURES, evaluation, paired  # noqa: E402

PAIRS = {"printed - extrusion": "extrusion", "printed - surface": "surface"}


def differences(ev: dict) -> dict:
    """pair -> figure -> (value, stderr) of an evaluation file's paired differences (``PAIRS``, ``FIGURES``)."""
    return {
        pair: {f: (v["value"], v["stderr"]) for f, v in paired(ev, baseline).items()}
        for pair, baseline in PAIRS.items()
    }


def spread(values: list[tuple[float, float]]) -> dict:
    """The spread between samples of (value, stderr) pairs against their reported standard errors."""
    v, se = np.array(values, float).T
    k = len(v)
    sd, rms = float(np.std(v, ddof=1)), float(np.sqrt(np.mean(se**2)))
    chi2 = (k - 1) * sd**2 / rms**2
    return {
        "values": v.tolist(),
        "stderrs": se.tolist(),
        "mean": float(v.mean()),
        "sd_between_samples": sd,
        "rms_stderr": rms,
        "ratio": sd / rms,
        "chi2": chi2,
        "p_upper": float(stats.chi2.sf(chi2, k - 1)),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    ap.add_argument("run", type=Path)
    ap.add_argument("--seeds", default="0,1,2,3,4")
    ap.add_argument("--texels", type=int, default=1500)
    ap.add_argument("--evaluations", type=Path, default=Path("."), help="folder of the evaluation files")
    ap.add_argument("--also", type=Path, nargs="*", default=[], help="further evaluation files of RUN")
    a = ap.parse_args()
    files = [a.evaluations / f"{a.name}_s{s}.json" for s in (int(x) for x in a.seeds.split(","))]
    evs = [evaluation(a.run, f, a.texels, int(f.stem.rsplit("_s", 1)[1])) for f in files]
    evs += [json.loads(f.read_text()) for f in a.also]
    digests = {ev.get("quantized_digest") for ev in evs}
    if len(digests) != 1:
        raise SystemExit("the evaluation files are of different prints")
    per = [differences(ev) for ev in evs]
    samples = [{"seed": ev["seed"], "texels": ev["texel_sample"]["texels"]} for ev in evs]
    entry = {**provenance(), "run": str(a.run), "samples": samples, "evaluations": [str(f) for f in files + a.also]}
    for pair in PAIRS:
        entry[pair] = {f: spread([p[pair][f] for p in per]) for f in FIGURES}
        for f, s in entry[pair].items():
            print(
                f"{a.name} {pair} {f}: mean {s['mean']:+.3f}, sd between samples {s['sd_between_samples']:.3f}, "
                f"rms stderr {s['rms_stderr']:.3f} (x{s['ratio']:.2f}, p {s['p_upper']:.3f})"
            )
    entry.update(machine())
    add_study_entry("sample_spread.json", a.name, entry)


if __name__ == "__main__":
    main()
