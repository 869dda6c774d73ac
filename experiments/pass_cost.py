"""What a forward render and a gradient pass cost on Spot from a given start: one 4-spp render and one 4-spp
gradient pass (random adjoint) over every texel, with the renderer's counts (paths, events, replayed paths and
events), so that a fine stage's start can be compared with the white one. The replay's cost per replayed event is
the gradient pass's seconds less the forward render's (the gradient pass renders the same paths first), divided by
the replayed events. Writes the entry NAME of experiments/results/pass_cost.json.

    .venv/bin/python experiments/pass_cost.py NAME START [--height-mm 20] [--spp 4] [--threads 2]

START: ``white`` (or any ``--init``) or a mixture file on Spot's grid at ``--height-mm`` (e.g. a coarse-to-fine
job's ``RUN/coarse/fine_start.npz``). Run it alone on the machine: the seconds are wall-clock.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import add_study_entry, machine, provenance  # noqa: E402
from shell_compare import SPOT  # noqa: E402

from inkopt.model import InkTable  # noqa: E402
from inkopt.optim import Optimization, OptimizeConfig  # noqa: E402
from inkopt.scenes import build_scene  # noqa: E402
from inkopt.scenes.spec import MeshSpec  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    ap.add_argument("start")
    ap.add_argument("--height-mm", type=float, default=20.0)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    scene = build_scene(MeshSpec(SPOT, height_mm=a.height_mm), InkTable.parse("vero-cmykw"))
    cfg = OptimizeConfig(init=a.start, iterations=1).for_scene("mesh")
    run = Optimization(scene, cfg, threads=a.threads)
    renderer = run.renderer()
    adjoint = np.random.default_rng(0).standard_normal((len(scene.texels), 3)).astype(np.float32)
    t = time.perf_counter()
    forward = renderer.render(scene.texels, a.spp, 7, cfg.include_specular).stats()
    forward["wall_seconds"] = time.perf_counter() - t
    t = time.perf_counter()
    res = renderer.gradient(
        scene.texels, adjoint, a.spp, 8, cfg.include_specular, cfg.grad_method, grad_index=run.param.free_index
    )[2]
    gradient = {**res.stats(), "wall_seconds": time.perf_counter() - t}
    replay_ns = 1e9 * (gradient["wall_seconds"] - forward["wall_seconds"]) / max(gradient["replayed_events"], 1)
    entry = {
        **provenance(),
        "start": a.start,
        "height_mm": a.height_mm,
        "forward": forward,
        "gradient": gradient,
        "events_per_path": forward["events"] / forward["paths"],
        "forward_ns_per_event": 1e9 * forward["wall_seconds"] / forward["events"],
        "replay_ns_per_replayed_event": replay_ns,
        **machine(),
    }
    print(
        f"forward {forward['wall_seconds']:.1f} s ({entry['events_per_path']:.1f} events per path, "
        f"{entry['forward_ns_per_event']:.0f} ns per event); gradient {gradient['wall_seconds']:.1f} s "
        f"({gradient['replayed_events'] / 1e6:.1f} M of {gradient['events'] / 1e6:.1f} M events replayed, "
        f"~{replay_ns:.0f} ns each)"
    )
    add_study_entry("pass_cost.json", a.name, entry)


if __name__ == "__main__":
    main()
