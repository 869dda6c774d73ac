"""The ink-set selection rule on a 35-set search: candidates cyan, cyan2, magenta, magenta2, yellow, yellow2, orange
choose 3, always black and white, on the astronaut photo (6 x 4 x 1 mm slab, 3337 texels), 40 iterations.

Brute force runs every set to the full budget; each run's training-loss history (every iteration) and its loss at
the final figures are recorded. Halving's runs resume and continue exactly, so a halving run of a set is a prefix of
brute force's run of it, and its final runs are brute force's runs: any rung rule's outcome (its winner and its
work) follows exactly from these records, without running it (``inkopt.inksets.search.simulate``). The records go
to experiments/results/select_inks_35.json; tests/inksets/test_rung_rule.py replays the current rule on them.

    .venv/bin/python experiments/select_inks_35.py [--chart astronaut|colour] [--iterations 40] [--workers 2]
        [--out bench-out/select_inks35]
    .venv/bin/python experiments/select_inks_35.py --analyse     # rung plans replayed on the records: a table
    .venv/bin/python experiments/select_inks_35.py --chart colour --validate   # a real halving search against
        its replay on the record (writes experiments/results/select_inks_35_colour_halving.json)
"""

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import machine  # noqa: E402
from common import write_study as write
from select_inks import chart_picture  # noqa: E402

from inkopt.inksets import Selection, make_backend, run_selection  # noqa: E402
from inkopt.inksets.search import set_name  # noqa: E402
from inkopt.optim import OptimizeConfig  # noqa: E402
from inkopt.optim.checkpoint import read_checkpoint  # noqa: E402
from inkopt.scenes.spec import SlabSpec  # noqa: E402

CANDIDATES = "cyan,cyan2,magenta,magenta2,yellow,yellow2,orange"
SIZE_MM = [6.0, 4.0, 1.0]


PLANS = {  # name -> plan for 35 sets at 40 iterations (iterations, sets kept after the rung)
    "previous rule: 1, 2, 5, 10, 40 keeping half": [(1, 18), (2, 9), (5, 5), (10, 3), (40, 1)],
    "current rule: 10, 20, 40 keeping 9, then 5": None,  # plan_rungs(35, 40)
    "10, 40 keeping 4": [(10, 4), (40, 1)],
}


def analyse() -> None:
    """Every plan of ``PLANS`` with both rankings, replayed on every record: the winner's place in brute force's
    order, its loss gap and the work against brute force (a markdown table)."""
    import json

    from inkopt.inksets.search import extrapolate_loss, plan_rungs, rank_loss, rung_work, simulate

    print("| record | plan | ranked by | winner's place | loss gap | work ratio |")
    print("|---|---|---|---|---|---|")
    for path in sorted((Path(__file__).resolve().parent / "results").glob("select_inks_35*.json")):
        if path.stem.endswith("_halving"):  # a --validate result, not a record
            continue
        d = json.loads(path.read_text())
        sets, total, per = d["sets"], d["iterations"], d["spp"] + d["forward_spp"]
        order = sorted(sets, key=lambda n: sets[n]["loss"])
        brute = len(sets) * rung_work(total, per, d["eval_spp"], True)
        for name, plan in PLANS.items():
            for how, rank in (("training loss", rank_loss), ("extrapolation", extrapolate_loss)):
                w, work = simulate(sets, plan or plan_rungs(len(sets), total), total, per, 16, d["eval_spp"], rank)
                gap = 100 * (sets[w]["loss"] / sets[order[0]]["loss"] - 1)
                print(
                    f"| {d['chart']} | {name} | {how} | {order.index(w) + 1} / 35 | {gap:.2f} % | {work / brute:.2f} |"
                )


def validate(args, target, out: Path) -> None:
    """A real halving search of the chart next to ``simulate``'s replay of the current plan on its brute-force
    record: the same winner, loss and work are expected (halving's runs are prefixes of brute force's)."""
    import json

    from inkopt.inksets.search import plan_rungs, simulate

    suffix = "" if args.chart == "astronaut" else "_" + args.chart
    rec = json.loads((Path(__file__).resolve().parent / "results" / f"select_inks_35{suffix}.json").read_text())
    sel = Selection(target, CANDIDATES, 3, ["black", "white"], OptimizeConfig(iterations=args.iterations), "halving")
    backend = make_backend(args.workers)
    t0 = time.perf_counter()
    try:
        res = run_selection(sel, out / "halving", backend, log=lambda m: print(m, flush=True))
    finally:
        backend.close()
    per = rec["spp"] + rec["forward_spp"]
    name, work = simulate(rec["sets"], plan_rungs(35, rec["iterations"]), rec["iterations"], per, 16, rec["eval_spp"])
    data = {
        "machine": machine(),
        "chart": args.chart,
        "seconds": time.perf_counter() - t0,
        "halving_winner": res["winner"],
        "halving_texel_samples": res["texel_samples"],
        "replayed_winner": {"inks": rec["sets"][name]["inks"], "loss": rec["sets"][name]["loss"]},
        "replayed_texel_samples": work * rec["texels"],
        "brute_force_seconds": rec["seconds"],
    }
    data["identical"] = (
        data["halving_winner"] == data["replayed_winner"]
        and data["halving_texel_samples"] == data["replayed_texel_samples"]
    )
    print(data)
    write(f"select_inks_35{suffix}_halving.json", data)


def main():
    if "--analyse" in sys.argv:
        return analyse()
    ap = argparse.ArgumentParser()
    ap.add_argument("--iterations", type=int, default=40)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--chart", default="astronaut")
    ap.add_argument("--out", default="bench-out/select_inks35")
    ap.add_argument("--validate", action="store_true", help="run halving and compare it with its replay")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    pic = chart_picture(args.chart, out)
    target = SlabSpec(str(pic), tuple(SIZE_MM))
    if args.validate:
        return validate(args, target, out)
    sel = Selection(target, CANDIDATES, 3, ["black", "white"], OptimizeConfig(iterations=args.iterations), "brute")
    backend = make_backend(args.workers)
    t0 = time.perf_counter()
    try:
        brute = run_selection(sel, out / "brute", backend, resume=True, log=lambda m: print(m, flush=True))
    finally:
        backend.close()
    sets = {}
    for c in brute["candidates"]:
        name = set_name(c["inks"][:3])
        ck = read_checkpoint(out / "brute" / "runs" / name / "checkpoint.npz")
        sets[name] = {"inks": c["inks"], "loss": c["loss"], "hist_loss": [float(v) for v in ck["hist_loss"]]}
    write(
        f"select_inks_35{'' if args.chart == 'astronaut' else '_' + args.chart}.json",
        {
            "machine": machine(),
            "chart": args.chart,
            "candidates": CANDIDATES,
            "choose": 3,
            "always": ["black", "white"],
            "size_mm": SIZE_MM,
            "iterations": args.iterations,
            "texels": 47 * 71,
            "spp": sel.cfg.spp,
            "forward_spp": sel.cfg.forward_spp,
            "eval_spp": sel.eval_spp,
            "seconds": time.perf_counter() - t0,
            "winner": brute["winner"],
            "sets": sets,
        },
    )


if __name__ == "__main__":
    main()
