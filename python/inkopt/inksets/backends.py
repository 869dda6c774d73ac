"""Where the candidate runs of an ink-set search execute: in this process, in a local process pool, or as Ray
tasks (a local Ray instance or a cluster). Nothing else: no scheduler of our own.

A task is a plain dict (the target's ``scenes.spec`` spec, ink names, the optimiser settings, the run directory,
the budget) and :func:`run_candidate` builds the scene in the worker, so a task pickles in a few hundred bytes and
any machine with inkopt and the same file paths (a shared filesystem for the target and DIR) can run it. Renders are
bit-identical for any thread count, so every backend returns the same numbers for the same tasks.
"""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict
from multiprocessing import get_context

import numpy as np

# the one Ray import and start, shared with --ray texel shards; RAY_INSTALL_HINT re-exported by inksets
from ..distributed import RAY_INSTALL_HINT, connect_ray  # noqa: F401
from ..errors import ParameterError
from ..optim.checkpoint import read_checkpoint
from ..rundir import RunDir
from ..threads import check_threads


class _Capture:
    """A scene that keeps the final prediction ``run_optimisation`` hands to ``write_pictures`` (no extra
    rendering), and otherwise is the scene it wraps."""

    def __init__(self, scene):
        self._scene, self.prediction = scene, None

    def __getattr__(self, name):
        return getattr(self._scene, name)

    def write_pictures(self, out, pred_rgb, delta_e):
        self.prediction = np.asarray(pred_rgb, np.float32)
        return self._scene.write_pictures(out, pred_rgb, delta_e)


def run_candidate(task: dict) -> dict:
    """One rung of one candidate: build its scene from the task's spec (``task["spec"]``, a ``scenes.spec``
    spec), optimise (continuing from its checkpoint when ``resume``) up to ``cfg["iterations"]``, evaluate at
    ``eval_spp``. Returns the report's figures, the texel count, the run's training-loss history (``hist_loss``,
    every iteration from the start) and the final prediction (I, 3)."""
    from ..model import InkTable
    from ..optim import OptimizeConfig
    from ..run import RunOptions, run_optimisation
    from ..scenes import build_scene

    inks = InkTable.from_names(task["inks"])
    cfg = OptimizeConfig(**{**task["cfg"], "gamma": tuple(task["cfg"]["gamma"])})
    scene = _Capture(build_scene(task["spec"], inks))
    options = RunOptions(
        resume=task["resume"],
        eval_spp=task["eval_spp"],
        threads=task["threads"],
        log=lambda msg: None,
        baseline_guard=False,  # the subsets are ranked against each other, not against a baseline
        figure_texel_sample=0,  # ranked by the result's loss over every texel, the run's own (not a sample's)
    )
    rep = run_optimisation(scene, task["out"], cfg, options)
    m = rep.metrics
    out = {
        "loss": m.loss,
        "delta_e76_mean": m.delta_e76_mean,
        "delta_e2000_mean": m.delta_e2000_mean,
        "ssim": m.ssim,
        "iterations": rep.iterations,
    }
    ck = read_checkpoint(RunDir(task["out"]).checkpoint_path)  # the whole run's training-loss history
    out["hist_loss"] = [float(v) for v in ck["hist_loss"]]
    out["texels"] = len(scene.texels)
    out["prediction"] = scene.prediction
    return out


def config_dict(cfg) -> dict:
    d = asdict(cfg)
    d["gamma"] = list(d["gamma"])
    return d


class Serial:
    """Every run in this process, one after the other, with all cores."""

    name = "serial"

    def __init__(self, threads: int | None = None):
        self.cpus = check_threads(threads) or os.cpu_count() or 1
        self.workers = 1

    def map(self, fn, tasks: list):
        """fn(task) for every task; results in task order, each as soon as it and those before it are done."""
        return (fn(t) for t in tasks)

    def close(self) -> None:
        pass


class Pool(Serial):
    """A local process pool (spawn context: no state shared with the parent)."""

    name = "pool"

    def __init__(self, workers: int):
        self.cpus, self.workers = os.cpu_count() or 1, workers
        self._ex = ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn"))

    def map(self, fn, tasks: list):
        return self._ex.map(fn, tasks)

    def close(self) -> None:
        self._ex.shutdown(wait=True, cancel_futures=True)  # after Ctrl-C or a failure: do not run the queued rest


class Ray(Serial):
    """Ray tasks: ``address`` "auto" starts a local instance (``num_cpus`` of it, default all cores), any other
    address joins that cluster. Each task asks for as many CPUs as it runs threads."""

    name = "ray"

    def __init__(self, address: str = "auto", workers: int | None = None, num_cpus: int | None = None):
        ray, self._started = connect_ray(address, num_cpus)
        self._ray = ray
        self.cpus = int(ray.cluster_resources().get("CPU", 1))
        # a task's threads must fit on one node
        self.node_cpus = max([int(n["Resources"].get("CPU", 1)) for n in ray.nodes() if n.get("Alive")] or [1])
        self.workers = workers or self.cpus

    def map(self, fn, tasks: list):
        ray = self._ray
        remote = ray.remote(max_retries=0)(fn)
        refs = [remote.options(num_cpus=min(t["threads"], self.node_cpus)).remote(t) for t in tasks]
        return (ray.get(r) for r in refs)

    def close(self) -> None:
        if self._started:
            self._ray.shutdown()


def make_backend(workers: int | None = None, ray: str | None = None, threads: int | None = None):
    """Serial (no options), a process pool (``workers``) or Ray (``ray``: "auto" or a cluster address)."""
    if workers is not None and workers < 1:
        raise ParameterError(f"`workers` must be at least 1, got {workers}")
    check_threads(threads)
    if ray:
        return Ray(ray, workers)
    if workers and workers > 1:
        return Pool(workers)
    return Serial(threads)


def threads_per_run(backend, n_tasks: int) -> int:
    """Threads of each run when ``n_tasks`` run at once: the cores shared by the runs that run side by side
    (results do not depend on it: renders are bit-identical for any thread count)."""
    side_by_side = max(1, min(backend.workers, n_tasks))
    return max(1, backend.cpus // side_by_side)
