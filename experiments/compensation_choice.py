"""What ``inkopt quantize --compensate-auto`` chooses on optimised results, and what the choice costs (docs/quality.md,
"The compensation decided by the run").

    nice -n 5 .venv/bin/python experiments/compensation_choice.py NAME LABEL=RUN [LABEL=RUN ...] [--texels N --spp S]

RUN is an optimisation run folder (volume.npz, scene.npz); it is not written to: the two candidates are quantized
into a scratch folder (``--scratch``, default the system's temporary folder) exactly as the command does
(``evaluation.halftone_choice``), and their paired figures are those the command decides on. Per run, the entry NAME
of experiments/results/compensation_choice.json holds the decision, the paired differences compensated − plain
(noise-corrected ΔE76, ΔE2000; ± their standard errors), the sample, and the seconds of each quantization and of the
two renders.
"""

import argparse
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import add_study_entry, machine, provenance  # noqa: E402


def choose(run: Path, texels: int, spp: int, scratch: str | None) -> dict:
    from inkopt.evaluation import halftone_choice as hc
    from inkopt.model import Quantization
    from inkopt.printing.stream import quantize_run
    from inkopt.rundir import RunDir

    d, q, out = RunDir(run), Quantization(), {"run": str(run)}
    with tempfile.TemporaryDirectory(prefix="inkopt-choice-", dir=scratch) as tmp:
        stage = {}
        for name in ("plain", "compensated"):
            (Path(tmp) / name).mkdir()
            stage[name] = RunDir(Path(tmp) / name)
            t0 = time.perf_counter()
            quantize_run(d, replace(q, compensate=name == "compensated"), into=stage[name])
            out[f"quantize_seconds_{name}"] = round(time.perf_counter() - t0, 2)
        t0 = time.perf_counter()
        d76, d2000, n, population = hc.paired_figures(d, stage["plain"], stage["compensated"], q.seed, texels, spp)
        out["render_seconds"] = round(time.perf_counter() - t0, 2)
    out.update(
        compensate=hc.compensate_wins(d76, d2000),
        delta_e76=d76[0],
        delta_e76_stderr=d76[1],
        delta_e2000=d2000[0],
        delta_e2000_stderr=d2000[1],
        texels=n,
        population=population,
        spp=spp,
    )
    return out


def main():
    from inkopt.evaluation.halftone_choice import CHOICE_SPP, CHOICE_TEXELS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    ap.add_argument("runs", nargs="+", help="LABEL=RUN")
    ap.add_argument("--texels", type=int, default=CHOICE_TEXELS)
    ap.add_argument("--spp", type=int, default=CHOICE_SPP)
    ap.add_argument("--scratch", help="folder for the candidates' labels (default: the system's temporary folder)")
    a = ap.parse_args()
    entry = {**provenance(), "runs": {}}
    for item in a.runs:
        label, _, run = item.partition("=")
        r = entry["runs"][label] = choose(Path(run), a.texels, a.spp, a.scratch)
        print(
            f"{label}: {'compensated' if r['compensate'] else 'plain'}; compensated - plain "
            f"{r['delta_e76']:+.3f} ± {r['delta_e76_stderr']:.3f} ΔE76, {r['delta_e2000']:+.3f} ± "
            f"{r['delta_e2000_stderr']:.3f} ΔE2000; quantize {r['quantize_seconds_plain']} + "
            f"{r['quantize_seconds_compensated']} s, renders {r['render_seconds']} s",
            flush=True,
        )
        entry.update(machine())
        add_study_entry("compensation_choice.json", a.name, entry)


if __name__ == "__main__":
    main()
