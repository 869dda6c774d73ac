"""Two builds of the Rust core on the same Spot scene in one process: render and gradient CPU seconds, alternated
pass by pass (so a change of the machine's load falls on both alike), and whether their results are bit-identical.

    python bench/bricks_ab.py [HEIGHT_MM=20] --other-core SO [--shell-mm D] [--spp 4] [--forward-spp 16]
        [--repeats 3] [--threads 2] [--tag T]

This tree's ``inkopt`` builds the scene and both renderers; ``SO`` (another tree's ``python/inkopt/_core.abi3.so``,
e.g. main's) is loaded beside this tree's core and stands in for it while its renderer is built and run (the
Python layer is this tree's for both). Each repeat renders (``--forward-spp``) and takes a gradient (``--spp``,
a random adjoint) with each core, the order alternating. Writes bench/results/bricks_ab_<H>mm[_shell<D>]<T>.json:
per core and pass the CPU seconds (user + system of the process, all threads) of every repeat, their means and
standard errors, the ratio this / other, the load average, the core's distance storage, and bit_identical.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.machinery
import importlib.util
import json
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "bench"))

from bench_mesh import SPOT  # noqa: E402
from common import cpu_seconds as cpu  # noqa: E402


def load_core(path: str):
    """The extension module at ``path`` as a module object named ``inkopt._core`` (not registered in sys.modules)."""
    loader = importlib.machinery.ExtensionFileLoader("inkopt._core", path)
    spec = importlib.util.spec_from_file_location("inkopt._core", path, loader=loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


@contextlib.contextmanager
def core_as(module):
    """``inkopt._core`` is ``module`` within the block (the renderer imports its core at each call)."""
    import inkopt

    before = sys.modules["inkopt._core"]
    sys.modules["inkopt._core"], inkopt._core = module, module
    try:
        yield
    finally:
        sys.modules["inkopt._core"], inkopt._core = before, before


def main(argv=None) -> dict:
    from common import provenance

    import inkopt._core as this_core
    from inkopt.io import atomic_write_bytes
    from inkopt.model import InkTable
    from inkopt.render import Renderer
    from inkopt.scenes.mesh import build_mesh_scene
    from inkopt.scenes.spec import MeshSpec

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("height_mm", type=float, nargs="?", default=20.0)
    ap.add_argument("--other-core", required=True, help="another build's _core.abi3.so (the 'other' core)")
    ap.add_argument("--shell-mm", type=float)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--forward-spp", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--tag", default="")
    args = ap.parse_args(argv)
    cores = {"other": load_core(args.other_core), "this": this_core}
    inks = InkTable.parse("vero-cmykw")
    scene = build_mesh_scene(MeshSpec(str(SPOT), height_mm=args.height_mm, shell_mm=args.shell_mm), inks)
    vol, tex, free = scene.volume, scene.texels, np.flatnonzero(scene.free)
    rows = np.random.default_rng(0).dirichlet(np.ones(len(inks)), size=len(free)).astype(np.float32)
    adj = np.random.default_rng(1).normal(size=(len(tex), 3)).astype(np.float32)
    renderers, build_cpu = {}, {}
    for name, core in cores.items():
        with core_as(core):
            c = cpu()
            r = Renderer(vol, threads=args.threads)
            held = np.setdiff1d(vol.inside.nonzero(), free)
            r.set_mixture(held, scene.fixed_share.at(held))
            r.set_mixture(free, rows)
            build_cpu[name], renderers[name] = cpu() - c, r
    times = {n: {"render_cpu": [], "gradient_cpu": []} for n in cores}
    results, loads = {}, [os.getloadavg()[0]]
    for rep in range(args.repeats):
        for name in list(cores) if rep % 2 == 0 else list(cores)[::-1]:
            r = renderers[name]
            with core_as(cores[name]):
                c = cpu()
                res = r.render(tex, spp=args.forward_spp, seed=rep)
                times[name]["render_cpu"].append(cpu() - c)
                c = cpu()
                g = r.gradient(tex, adj, spp=args.spp, seed=rep)
                times[name]["gradient_cpu"].append(cpu() - c)
            results.setdefault(rep, []).append((res.rgb.tobytes(), g[0].tobytes(), g[1].tobytes()))
        loads.append(os.getloadavg()[0])
        print(json.dumps({"repeat": rep, "times": times, "load": loads[-1]}), flush=True)

    def stats(v: list[float]) -> dict:
        return {"mean": float(np.mean(v)), "stderr": float(np.std(v, ddof=1) / np.sqrt(len(v))) if len(v) > 1 else None}

    summary = {n: {k: stats(v) for k, v in t.items()} for n, t in times.items()}
    total = {n: [a + b for a, b in zip(t["render_cpu"], t["gradient_cpu"])] for n, t in times.items()}
    ratio = {k: summary["this"][k]["mean"] / summary["other"][k]["mean"] for k in ("render_cpu", "gradient_cpu")}
    ratio["passes"] = float(np.mean(total["this"]) / np.mean(total["other"]))
    paired = [t / o for t, o in zip(total["this"], total["other"])]  # each repeat's this / other
    out = {
        "height_mm": args.height_mm,
        "shell_mm": args.shell_mm,
        "spp": args.spp,
        "forward_spp": args.forward_spp,
        "threads": args.threads,
        "repeats": args.repeats,
        "other_core": str(Path(args.other_core).resolve()),
        "grid_voxels": int(np.prod(vol.shape)),
        "texels": len(tex),
        "free_voxels": len(free),
        "distance_storage": renderers["this"].distance_storage,
        "renderer_build_cpu_seconds": build_cpu,
        "cpu_seconds": times,
        "summary": summary,
        "this_over_other_cpu": ratio,
        "this_over_other_paired": stats(paired),
        "load_average_1min": loads,
        "bit_identical": all(len(set(v)) == 1 for v in results.values()),
    }
    shell = "" if args.shell_mm is None else f"_shell{args.shell_mm:g}"
    path = ROOT / "bench" / "results" / f"bricks_ab_{args.height_mm:g}mm{shell}{args.tag}.json"
    atomic_write_bytes(path, (json.dumps({**out, **provenance()}, indent=2) + "\n").encode())
    print(json.dumps({k: out[k] for k in ("this_over_other_cpu", "this_over_other_paired", "bit_identical")}))
    return out


if __name__ == "__main__":
    main()
