"""Two texel-sampled evaluations of one run (e.g. ``inkopt evaluate D --seed 0`` and ``--seed 1``, each another
sample and other render seeds): does each figure agree between them within its standard errors?

    .venv/bin/python experiments/texel_sample_seeds.py A.json B.json [--name NAME]

For each result's figures and each paired difference: both values, the two standard errors combined
(sqrt(se_A² + se_B²)) and z = (B - A) / that. Writes experiments/results/texel_sample_NAME.json.
"""

import argparse
import json
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import machine  # noqa: E402
from common import write_study as write

FIGURES = ("delta_e76_mean", "delta_e76_mean_corrected", "delta_e2000_mean", "delta_e76_p95", "ssim", "mottle_l2")


def rows(ev: dict) -> dict:
    return {"continuous": ev["continuous"], "quantized": ev["quantized"], **(ev.get("baselines") or {})}


def compare(va, sa, vb, sb) -> dict:
    se = math.hypot(sa, sb)
    return {"a": va, "b": vb, "combined_stderr": se, "z": (vb - va) / se}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--name", default="seeds")
    args = ap.parse_args()
    a, b = (json.loads(Path(p).read_text()) for p in (args.a, args.b))
    out = {}
    for name, ra in rows(a).items():
        rb = rows(b)[name]
        out[name] = {k: compare(ra[k], ra["stderr"][k], rb[k], rb["stderr"][k]) for k in FIGURES}
    for pair, figs in a["differences"].items():
        other = b["differences"][pair]
        out[pair] = {
            k: compare(v["value"], v["stderr"], other[k]["value"], other[k]["stderr"]) for k, v in figs.items()
        }
    for what, figs in out.items():
        print(what, {k: round(v["z"], 2) for k, v in figs.items()})
    res = {
        "a": str(Path(args.a).resolve()),
        "b": str(Path(args.b).resolve()),
        "texel_sample": [a["texel_sample"], b["texel_sample"]],
        "seconds": [a["seconds"], b["seconds"]],
        "comparison": out,
        **machine(),
    }
    print("wrote", write(f"texel_sample_{args.name}.json", res))


if __name__ == "__main__":
    main()
