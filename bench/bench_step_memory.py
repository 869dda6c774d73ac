"""Where a mesh run's step peaks, per free voxel: the resident-memory high-water mark of each phase of
``Optimization.step`` on Spot, and numpy's share of it.

    python bench/bench_step_memory.py 40 [--shell-mm 1] [--iterations 2] [--spp 4] [--code PYTHON_DIR] [--tag T]

The run's renderer is built first (its own peak: ``renderer_build``). Then each phase of a step (the forward
render, the loss, the gradient pass in the core, taking its sums as arrays with dE/dsigma -> dE/dx, the optimiser's
update, the step smoothing, the rest) is bounded by marks: at a mark the process's VmHWM (/proc/self/status) is
read as the peak of the phase just ended and reset (``clear_refs`` 5), so each phase has its own peak; numpy's
share is tracemalloc's peak over the phase (numpy reports its arrays' data to tracemalloc), the rest is the core's
(Rust) or the allocator's. ``--code DIR``: the package measured (another tree's python/; default this tree's), so
two trees are compared in one session.

Writes the entry ``<H>mm[_shell<D>][_<T>]`` of bench/results/step_memory_spot.json: per iteration and phase the peak
(GiB), its excess over the resident memory at the step's start in bytes per free voxel, numpy's peak over the
phase's start and over the step's start (bytes per free voxel), with the command, the commit and the load average.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import tracemalloc
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_CODE = sys.argv[sys.argv.index("--code") + 1] if "--code" in sys.argv[:-1] else str(ROOT / "python")
sys.path.insert(0, _CODE)
sys.path.insert(0, str(ROOT / "bench"))

RESULTS_FILE = "step_memory_spot.json"


def _status(field: str) -> int:
    """A /proc/self/status field in bytes (VmRSS, VmHWM)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    raise KeyError(field)


class Phases:
    """Marks between the phases of a step: ``mark(name)`` ends the running phase (its VmHWM peak and numpy's
    tracemalloc peak are recorded) and starts ``name`` with both peaks reset."""

    def __init__(self):
        self.peaks: list[tuple[str, int, int, int]] = []  # (phase, VmHWM peak, numpy peak, numpy at its start)
        self.cpu: dict[str, float] = {}  # CPU seconds (all threads) per phase, summed over its spans
        self.name = None
        self.numpy_start = 0
        self.cpu_start = 0.0

    def _reset(self) -> None:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        tracemalloc.reset_peak()

    def mark(self, name: str | None) -> None:
        cpu = time.process_time()
        if self.name is not None:
            _, numpy_peak = tracemalloc.get_traced_memory()
            self.peaks.append((self.name, _status("VmHWM"), numpy_peak, self.numpy_start))
            self.cpu[self.name] = self.cpu.get(self.name, 0.0) + cpu - self.cpu_start
        self.name, self.cpu_start = name, cpu
        self.numpy_start = tracemalloc.get_traced_memory()[0]
        self._reset()


def _wrap(obj, attr: str, phases: Phases, name: str, after: str) -> None:
    """Make ``obj.attr`` mark phase ``name`` while it runs and ``after`` when it returns."""
    inner = getattr(obj, attr)

    def wrapped(*a, **k):
        phases.mark(name)
        try:
            return inner(*a, **k)
        finally:
            phases.mark(after)

    setattr(obj, attr, wrapped)


def instrument(run, phases: Phases) -> None:
    """Phase marks in ``run``'s step (an ``Optimization`` whose renderer is built)."""
    renderer = run.renderer()
    _wrap(renderer, "render", phases, "render", "loss")
    _wrap(renderer, "_backward", phases, "gradient pass", "take gradient")
    # the loop's update: in place (``update``) or on copies (``step``, in trees before the in-place update)
    _wrap(run.opt, "update" if hasattr(run.opt, "update") else "step", phases, "optimiser update", "after update")
    if run.smoother is not None:
        _wrap(run.smoother, "apply", phases, "smoothing", "rest")


def main(argv=None) -> dict:
    import json

    from common import RESULTS, SPOT, machine, provenance, write

    from inkopt.model import InkTable
    from inkopt.optim import Optimization, OptimizeConfig
    from inkopt.scenes.mesh import build_mesh_scene
    from inkopt.scenes.spec import MeshSpec

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("height_mm", type=float, nargs="?", default=40.0)
    ap.add_argument("--mesh", default=str(SPOT))
    ap.add_argument("--shell-mm", type=float)
    ap.add_argument("--iterations", type=int, default=2)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--code", default=_CODE, help="python/ directory whose inkopt is measured (default this tree's)")
    ap.add_argument("--tag", help="suffix of the results entry")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)

    load = [os.getloadavg()[0]]
    spec = MeshSpec(args.mesh, height_mm=args.height_mm, shell_mm=args.shell_mm)
    scene = build_mesh_scene(spec, InkTable.parse("vero-cmykw"))
    run = Optimization(scene, OptimizeConfig(iterations=args.iterations, spp=args.spp).for_scene("mesh"), threads=2)
    n_free = run.param.n_free
    tracemalloc.start()
    phases = Phases()
    setup_rss = _status("VmRSS")
    phases.mark("renderer build")  # the run's renderer, built at its first step
    run.renderer()
    phases.mark(None)
    name, build_peak, _, _ = phases.peaks[0]
    build = {"rss_before_gib": round(setup_rss / 2**30, 4), "peak_gib": round(build_peak / 2**30, 4)}
    build["rss_after_gib"] = round(_status("VmRSS") / 2**30, 4)
    print(f"renderer build: {build}")
    instrument(run, phases)
    iterations = []
    for it in range(args.iterations):
        start_rss, numpy_start = _status("VmRSS"), tracemalloc.get_traced_memory()[0]
        phases.peaks.clear()
        phases.cpu.clear()
        t = time.perf_counter()
        phases.mark("renderer and set_mixture")
        run.step()
        phases.mark(None)
        rows = {}
        for name, peak, numpy_peak, numpy_at in phases.peaks:
            rows[name] = {
                "peak_gib": round(peak / 2**30, 4),
                "over_start_b_per_free": round((peak - start_rss) / n_free, 1),
                "numpy_peak_over_phase_start_b_per_free": round((numpy_peak - numpy_at) / n_free, 1),
                "numpy_peak_over_step_start_b_per_free": round((numpy_peak - numpy_start) / n_free, 1),
                "cpu_s": round(phases.cpu[name], 2),
            }
        top = max(phases.peaks, key=lambda p: p[1])
        iterations.append(
            {
                "start_rss_gib": round(start_rss / 2**30, 4),
                "numpy_at_start_b_per_free": round(numpy_start / n_free, 1),
                "peak_gib": round(top[1] / 2**30, 4),
                "peak_phase": top[0],
                "seconds": round(time.perf_counter() - t, 1),
                "phases": rows,
            }
        )
        print(f"iteration {it + 1}: start {start_rss / 2**30:.3f} GiB, peak {top[1] / 2**30:.3f} in {top[0]}")
        for name, row in rows.items():
            print(f"  {name:26s} {row}")
    load.append(os.getloadavg()[0])
    result = {
        **provenance(),
        "height_mm": args.height_mm,
        "shell_mm": args.shell_mm,
        "free_voxels": n_free,
        "texels": len(scene.texels),
        "inside_voxels": scene.vox.inside.count,
        "code": args.code,
        "renderer_build": build,
        "iterations": iterations,
        "load_average_1min_before_after": load,
        # glibc's mmap threshold when set (e.g. 131072: every array above 128 KB mapped and returned when freed, as
        # the arrays of a big object are; unset, arrays below 32 MB come from the heap and its reuse)
        "MALLOC_MMAP_THRESHOLD_": os.environ.get("MALLOC_MMAP_THRESHOLD_"),
        "machine": machine(),
    }
    key = (
        f"{args.height_mm:g}mm"
        + (f"_shell{args.shell_mm:g}" if args.shell_mm else "")
        + (f"_{args.tag}" if args.tag else "")
    )
    if not args.no_write:
        path = RESULTS / RESULTS_FILE
        out = json.loads(path.read_text()) if path.is_file() else {"results": {}}
        out["results"][key] = result
        write(RESULTS_FILE, out)
    return result


if __name__ == "__main__":
    main()
