"""Where a mesh suite deadline job's time goes after its coarse stage, and the fit of ``coarse.fine_stage_seconds``.

    python bench/mesh_suite_phases.py --fit fixed-80 --check default,cuts-fixed-80
    python bench/mesh_suite_phases.py --fit '' --check default --out mesh_suite_phases_finish.json   # a check only

Reads the optimize part of each 20 mm short-budget cell's ``suite.log`` (each line after the seconds since the
command began, ``bench/mesh_suite.py``) in the run folders of the variants named (``default``: the defaults' cells,
``MESH_20mm_short``): the coarse run's set-up ``setup_s`` (its seconds outside its iterations: the job's own
``fine stage predicted`` line where the job logged one, else the first coarse iteration's end less its time), the
coarse stage's end (that line's time, else the transfer's line less the transfer's seconds), the job's end (the
line ``... after N iterations``), and the fine stage's fixed seconds ``fine_stage_s``: from the coarse stage's end
to the job's end, the fine iterations after the first taken out (at their logged seconds per iteration). The cells of
``--fit`` give the least upper bound a + b * setup_s (least total excess, a linear programme; ``fit``), the others
are checked against ``coarse.FINE_FIXED_SECONDS`` and ``FINE_SETUP_FACTOR`` (``excess_s``: predicted - measured).
Writes bench/results/mesh_suite_phases.json (``--out``: another name in bench/results/; ``--fit ''``: no fit).
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write  # noqa: E402
from mesh_suite import CACHE, MESHES  # noqa: E402

TIME = re.compile(r"^\[\s*([\d.]+) s\] (.*)$")


def phases(log: Path) -> dict | None:
    """The phases (seconds) of the optimize command in ``log``; None when it has no coarse stage or did not end."""
    lines = [
        (float(m.group(1)), m.group(2))
        for m in map(TIME.match, log.read_text().split("$ inkopt quantize")[0].splitlines())
        if m
    ]
    coarse_it = [(t, s) for t, s in lines if re.match(r"  iteration 1/\d+:", s)]
    fine_it = [(t, s) for t, s in lines if re.match(r"iteration \d+/\d+:", s)]
    ends = [(t, s) for t, s in lines if re.search(r"after \d+ iterations", s) and "->" in s]
    if not coarse_it or not fine_it or not ends:
        return None
    said = [(t, s) for t, s in lines if s.startswith("fine stage predicted")]
    if said:
        t_coarse, setup = said[0][0], float(re.search(r"set-up (\d+) s", said[0][1]).group(1))
    else:
        moved = next((t, s) for t, s in lines if s.startswith("coarse result moved"))
        t_coarse = moved[0] - float(re.search(r" in (\d+) s:", moved[1]).group(1))
        setup = coarse_it[0][0] - float(re.search(r"([\d.]+) s/iteration", coarse_it[0][1]).group(1))
    t_end, n = ends[-1][0], int(re.search(r"after (\d+) iterations", ends[-1][1]).group(1))
    per = float(re.search(r"([\d.]+) s/iteration", fine_it[-1][1]).group(1))
    return {
        "setup_s": round(setup, 1),
        "coarse_end_s": round(t_coarse, 1),
        "job_s": t_end,
        "fine_iterations": n,
        "fine_seconds_per_iteration": per,
        "fine_stage_s": round(t_end - t_coarse - (n - 1) * per, 1),
    }


def fit(cells: dict) -> dict:
    """The least upper bound a + b * setup_s of the cells' ``fine_stage_s`` (least total excess; a, b >= 0)."""
    from scipy.optimize import linprog

    s = np.array([c["setup_s"] for c in cells.values()])
    f = np.array([c["fine_stage_s"] for c in cells.values()])
    a = np.c_[np.ones_like(s), s]
    res = linprog(c=a.sum(0), A_ub=-a, b_ub=-f, bounds=[(0, None)] * 2)
    return {"cells": list(cells), "fixed_s": round(float(res.x[0]), 2), "per_setup_s": round(float(res.x[1]), 3)}


def main(argv: list[str] | None = None) -> int:
    from inkopt.coarse import FINE_FIXED_SECONDS, FINE_SETUP_FACTOR, fine_stage_seconds

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fit", default="fixed-80", help="variants whose cells are fitted")
    ap.add_argument("--check", default="default,cuts-fixed-80", help="variants whose cells are checked")
    ap.add_argument("--cache", type=Path, default=CACHE)
    ap.add_argument("--out", default="mesh_suite_phases.json", help="the results file's name in bench/results/")
    a = ap.parse_args(argv)
    out = {"constants": {"FINE_FIXED_SECONDS": FINE_FIXED_SECONDS, "FINE_SETUP_FACTOR": FINE_SETUP_FACTOR}}
    for group in ("fit", "check"):
        cells = {}
        for variant in [v for v in getattr(a, group).split(",") if v]:
            for mesh in MESHES:
                name = f"{mesh}_20mm_short" + ("" if variant == "default" else f"_{variant}")
                log = a.cache / "runs" / name / "suite.log"
                got = phases(log) if log.is_file() else None
                if got is not None:
                    predicted = fine_stage_seconds(got["setup_s"])
                    cells[name] = {**got, "predicted_s": round(predicted, 1)}
                    cells[name]["excess_s"] = round(predicted - got["fine_stage_s"], 1)
                    print(f"{name:42s} " + ", ".join(f"{k} {v}" for k, v in cells[name].items()))
        out[group] = {"variants": getattr(a, group).split(","), "cells": cells}
    if out["fit"]["cells"]:
        out["fit"]["bound"] = fit(out["fit"]["cells"])
        print("fit:", out["fit"]["bound"])
    write(a.out, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
