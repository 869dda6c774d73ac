"""Does a spectral run's band plan, made from a pilot of its start, still fit after the mixture has moved?

    nice -n 10 .venv/bin/python experiments/spectral_replan.py [--spot-mm 10] [--at 6] [--spp 4] [--threads 2]

A spectral optimisation of Spot (``--spot-mm`` high, the scene's start, ``vero-cmykw@spectral`` under D65, the
default loss, ``--spp`` samples per texel in the forward and the gradient pass) makes its plan from a pilot of its
start as every spectral run does (``Viewing.pilot``). After each iteration count of ``--at`` both pilots (band
paths and hero paths, ``spectral.allocation.pilot``) are made again on the current mixture, and from their measures
(``Pilot.effort``: path events at equal colour noise) the start's plan, with its own groups and weights, is compared
with the plan a new pilot would choose (``allocation.choose``). ``replan_saves``: 1 - new effort / start plan's
effort, the share of path events a re-plan would save at equal noise. Writes
experiments/results/spectral_replan_spot<H>mm.json.
"""

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import SPOT, machine, write_study  # noqa: E402

from inkopt.model import InkTable  # noqa: E402
from inkopt.model.spectral import load_ink_table  # noqa: E402
from inkopt.optim import Optimization, OptimizeConfig  # noqa: E402
from inkopt.scenes import build_scene  # noqa: E402
from inkopt.scenes.spec import MeshSpec  # noqa: E402
from inkopt.spectral.allocation import choose, pilot  # noqa: E402
from inkopt.spectral.lights import named_light  # noqa: E402
from inkopt.spectral.viewing import Viewing  # noqa: E402


def efforts(run: Optimization, threads: int) -> dict:
    """Both pilots on the run's current mixture; the start plan's effort under them and the new plan's."""
    v = run.viewing
    args = (run.volume(), v.table, run.texels, v.colours(), threads)
    bands, hero = pilot(*args), pilot(*args, hero=True)
    new = choose(bands, hero)
    start = v.plan
    kept = (hero if start.hero else bands).effort(start.groups, start.weights)
    fresh = new.measured["effort"]
    return {
        "iteration": run.iteration,
        "delta_e76": run.history.delta_e76[-1] if run.history.delta_e76 else None,
        "start_plan_effort": kept,
        "new_plan_effort": fresh,
        "new_plan_hero": new.hero,
        "new_plan_groups": [list(g) for g in new.groups],
        "new_plan_weights": list(new.weights),
        "replan_saves": 1.0 - fresh / kept,
        "pilot_seconds": new.measured["seconds"],
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--spot-mm", type=float, default=10.0)
    ap.add_argument("--at", default="6", help="iteration counts at which to measure")
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    at = sorted(int(x) for x in a.at.split(","))
    scene = build_scene(MeshSpec(str(SPOT), height_mm=a.spot_mm), InkTable.parse("vero-cmykw"))
    viewing = Viewing(load_ink_table("vero-cmykw@spectral"), (named_light("D65"),))
    cfg = OptimizeConfig(iterations=at[-1], spp=a.spp, forward_spp=a.spp).for_scene(scene.kind)
    run = Optimization(scene, cfg, threads=a.threads, viewing=viewing)
    t0 = time.perf_counter()
    run.renderer()  # the start's pilot and plan
    start = run.viewing.plan
    rows = []
    for n in at:
        while run.iteration < n:
            run.step()
        rows.append(efforts(run, a.threads))
        print(rows[-1], flush=True)
    out = {
        "scene": f"Spot {a.spot_mm:g} mm",
        "texels": len(scene.texels),
        "table": "vero-cmykw@spectral",
        "lights": ["D65"],
        "spp": a.spp,
        "start_plan": start.to_json(),
        "rows": rows,
        "seconds_per_iteration": sorted(run.history.seconds)[len(run.history.seconds) // 2],
        "wall_s": time.perf_counter() - t0,
        **machine(),
    }
    print("wrote", write_study(f"spectral_replan_spot{a.spot_mm:g}mm.json", out))


if __name__ == "__main__":
    main()
