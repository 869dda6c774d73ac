"""Texel shards on Ray: one render or gradient pass split over Ray workers (a local Ray instance or a cluster),
bit-identical to the same pass in one process.

:class:`RayShards` connects to Ray and starts the workers (actors): by default one per node, with as many threads
as the node has CPUs. ``RayShards.renderer(volume, threads, lighting)`` builds a :class:`ShardedRenderer`, a
:class:`inkopt.render.TexelRenderer` as :class:`inkopt.render.Renderer` is, so it serves as ``Optimization``'s
``renderer_factory``. Each worker builds its own renderer once from the volume (shipped once through Ray's object
store; a band volume as a :class:`inkopt.shardwire.BandObject`, with no grid-sized array) and renders a
contiguous range of the texels, in proportion to its threads.

Why the result does not depend on the split: random numbers are keyed by (seed, texel index, sample), and a
worker renders its range with the texels' global indices (``first_texel``); forward results are per texel, so
they are concatenated. Gradients are accumulated in fixed point (multiples of a quantum set from the largest
adjoint of the whole pass, which every worker is given); workers return the int64 sums
(``Renderer.gradient_fixed``) of the slots their paths touched (:class:`TouchedSlots`), which are added here in
integer arithmetic and converted once, as the core does.

Per iteration, the driver puts the free voxels' mixtures (F x N float32; their int64 index only once) into the
object store, which every node fetches once, and each worker its slice of the adjoints (12 bytes per texel); each
worker returns rgb and variance of its texels for both passes (2 x 24 bytes per texel) and its touched slots: a
bitmap or gaps for which, and 6 sums each in the narrowest integer dtype that holds them (instead of 48 bytes per
free voxel). A worker's texels are a contiguous range of the list; a mesh's texels are in (z, y, x) order, so a
range is a slab of the object and its paths touch the slots of that slab and its neighbourhood.
``ShardedRenderer.traffic`` counts the bytes.
"""

from __future__ import annotations

import contextlib
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import replace

import numpy as np

from .errors import ParameterError
from .lighting import Lighting, load_lighting
from .model import Texels, Volume
from .render import (
    PassSettings,
    Renderer,
    RendererFactory,
    RenderResult,
    TexelRenderer,
    adjoint_array,
    check_same_grid,
    fixed_to_float,
)
from .shardwire import BandObject, TouchedSlots, payload_bytes
from .threads import check_threads

#: The error of a ``ray`` address given without Ray installed (a ParameterError's template).
RAY_INSTALL_HINT = "`ray` needs Ray: pip install 'inkopt[ray]' (or pip install 'ray[default]')"


#: objects a ShardedRenderer keeps put in the object store while they are passed again: the texels, the gradient
#: index, and the optimiser's slices of the free-voxel index (one per million free voxels: 11 for Spot 60 mm)
REFS_KEPT = 64


def import_ray():
    """The ray module, or a ParameterError (of ``ray``) with the one-line install hint."""
    try:
        import ray
    except ImportError:
        raise ParameterError(RAY_INSTALL_HINT) from None
    return ray


def connect_ray(address: str = "auto", num_cpus: int | None = None):
    """(ray, started): join Ray if it is already initialised in this process, else start a local instance
    (``address`` "auto", ``num_cpus`` of it, default all cores) or join the cluster at ``address``. ``started``:
    whether this call started it (and its caller should shut it down)."""
    ray = import_ray()
    if ray.is_initialized():
        return ray, False
    if address == "auto":
        ray.init(num_cpus=num_cpus, include_dashboard=False, log_to_driver=False)
    else:
        ray.init(address=address, log_to_driver=False)
    return ray, True


class _ShardWorker:
    """A Ray actor: one renderer, rendering the texel ranges it is given."""

    def __init__(self, threads: int):
        self.threads, self.renderer = threads, None

    def load(self, volume, lighting) -> None:
        self.renderer = Renderer(volume, self.threads, lighting)

    def set_volume(self, volume) -> None:
        self.renderer.set_volume(volume)

    def set_mixture(self, index, rows) -> None:
        """Set the mixtures of the voxels ``index`` ((K,) flat indices) to ``rows`` (K, N)."""
        self.renderer.set_mixture(index, rows)

    def set_lighting(self, lighting) -> None:
        self.renderer.set_lighting(lighting)

    def render(self, texels, lo: int, hi: int, settings: PassSettings):
        """The texels ``lo:hi`` of the pass (``settings.first_texel``: the index of ``texels[lo]``): (rgb,
        var_mean, totals)."""
        r = self.renderer.render_pass(texels.subset(slice(lo, hi)), settings)
        return r.rgb, r.var_mean, _totals(r)

    def gradient(self, texels, lo: int, hi: int, adjoint, max_abs: float, settings: PassSettings, grad_index):
        """The texels ``lo:hi`` of the gradient pass (``settings.first_texel``: the index of ``texels[lo]``; their
        adjoints; the whole pass's largest |adjoint| ``max_abs``): (touched, quantum, rgb, var_mean, totals), the
        fixed-point sums as :class:`TouchedSlots`."""
        gs, ga, q, r = self.renderer.gradient_fixed(
            texels.subset(slice(lo, hi)), adjoint, settings, grad_index, max_abs
        )
        touched = TouchedSlots.of(gs, ga)
        del gs, ga
        return touched, q, r.rgb, r.var_mean, _totals(r)

    def peak_rss_gb(self) -> float:
        """This worker process's peak resident memory so far, GiB (Linux's ru_maxrss is in KiB)."""
        import resource

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def _totals(r: RenderResult) -> dict:
    return dict(paths=r.paths, events=r.events, replayed_paths=r.replayed_paths, replayed_events=r.replayed_events)


class RayShards:
    """Ray workers for texel shards. ``address``: "auto" (a local instance of ``num_cpus``) or a cluster address;
    ``workers``: how many (default one per node, each with all of its node's CPUs); ``threads``: threads per worker
    (default: the node's CPUs, or the cluster's CPUs / workers when ``workers`` is given)."""

    def __init__(
        self, address: str = "auto", workers: int | None = None, threads: int | None = None, num_cpus: int | None = None
    ):
        threads = check_threads(threads)  # before Ray starts
        ray, self._started = connect_ray(address, num_cpus)
        self._ray = ray
        nodes = [n for n in ray.nodes() if n.get("Alive") and n["Resources"].get("CPU", 0) >= 1]
        actor = ray.remote(_ShardWorker)
        if workers is None:
            from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

            # at most a node's CPUs: an actor pinned to a node that cannot hold it would never start
            self.threads = [min(threads or 10**9, int(n["Resources"]["CPU"])) for n in nodes]
            self.actors = [
                actor.options(
                    num_cpus=t, scheduling_strategy=NodeAffinitySchedulingStrategy(n["NodeID"], soft=False)
                ).remote(t)
                for n, t in zip(nodes, self.threads)
            ]
        else:
            if workers < 1:
                raise ParameterError(f"`workers` must be at least 1, got {workers}")
            cpus = int(ray.cluster_resources().get("CPU", 1))
            self.threads = [threads or max(1, cpus // workers)] * workers
            self.actors = [actor.options(num_cpus=t, scheduling_strategy="SPREAD").remote(t) for t in self.threads]

    def renderer(
        self, volume: Volume, threads: int | None = None, lighting: Lighting | str | None = None
    ) -> ShardedRenderer:
        """A renderer of ``volume`` on these workers (``threads`` is ignored: each worker has its own)."""
        return ShardedRenderer(self, volume, lighting)

    def peak_rss_gb(self) -> list[float]:
        """Each worker's peak resident memory so far, GiB (pages of the object store it reads count too)."""
        return self._ray.get([a.peak_rss_gb.remote() for a in self.actors])

    def close(self) -> None:
        for a in self.actors:
            self._ray.kill(a)
        self.actors = []
        if self._started:
            self._ray.shutdown()


class ShardedRenderer(TexelRenderer):
    """A :class:`~inkopt.render.TexelRenderer` over the workers of a :class:`RayShards`; results are bit-identical
    to a :class:`~inkopt.render.Renderer`'s for the same volume, texels, seeds and lighting. ``progress`` is
    ignored."""

    def __init__(self, shards: RayShards, volume: Volume, lighting: Lighting | str | None = None):
        self._shards, self._ray = shards, shards._ray
        self.volume, self.lighting = volume, load_lighting(lighting)
        self._refs: dict = {}
        #: bytes moved so far, by what: "out:volume", "out:mixture", "out:index", "out:texels", "out:adjoint",
        #: "out:lighting" (what the driver puts or sends, once per object: a node fetches it once), "back:render"
        #: (rgb and variance) and "back:gradient" (what the workers return), and "dense:gradient" (what the
        #: gradients would be as raw int64 arrays, a slot per free voxel per worker)
        self.traffic: Counter = Counter()
        ref = self._put("volume", _shipped(volume))
        self._pending = [a.load.remote(ref, self.lighting) for a in shards.actors]

    @property
    def threads(self) -> int:
        return sum(self._shards.threads)

    def set_volume(self, volume: Volume) -> None:
        """:meth:`TexelRenderer.set_volume`: the volume (a band volume as a BandObject) goes out to every worker."""
        check_same_grid(volume, self.volume)
        ref = self._put("volume", _shipped(volume))
        self._pending += [a.set_volume.remote(ref) for a in self._shards.actors]
        self.volume = volume

    def set_mixture(self, index: np.ndarray, mixture: np.ndarray) -> None:
        """:meth:`TexelRenderer.set_mixture`: the mixtures (K x N float32) go out through the object store once for
        all workers; the index (the optimiser passes the same array every iteration) only the first time."""
        rows_ref = self._put("mixture", np.ascontiguousarray(mixture, np.float32))
        self._pending += [a.set_mixture.remote(self._ref(index, "index"), rows_ref) for a in self._shards.actors]

    def set_lighting(self, lighting: Lighting | str | None) -> None:
        self.lighting = load_lighting(lighting)
        self.traffic["out:lighting"] += payload_bytes(self.lighting)
        self._pending += [a.set_lighting.remote(self.lighting) for a in self._shards.actors]

    def _put(self, what: str, obj):
        """``obj`` put into the object store, its bytes counted as ``out:<what>``."""
        self.traffic["out:" + what] += payload_bytes(obj)
        return self._ray.put(obj)

    def _ref(self, obj, what: str):
        """An object-store reference to ``obj`` (texels, a gradient index), put (and counted as ``out:<what>``)
        once while the same object, or a view of the same memory (the optimiser passes the same slices of one
        free-voxel index every iteration), is passed again; neither is changed in place between passes."""
        key = _identity(obj)
        hit = self._refs.get(key)
        if hit is None:
            while len(self._refs) >= REFS_KEPT:
                del self._refs[next(iter(self._refs))]  # the oldest
            hit = self._refs[key] = (obj, self._put(what, obj))  # holding obj keeps its memory from reuse
        return hit[1]

    def _bounds(self, n: int) -> list[tuple[int, int]]:
        """Contiguous texel ranges, one per worker, in proportion to its threads."""
        cut = np.round(np.cumsum([0] + self._shards.threads) / sum(self._shards.threads) * n).astype(int)
        return list(zip(cut[:-1].tolist(), cut[1:].tolist()))

    def _gather(self, calls) -> list:
        """Results of ``calls`` (remote calls already made), after the medium updates before them succeeded."""
        pending, self._pending = self._pending, []
        self._ray.get(pending)
        return self._ray.get(calls)

    def render_pass(self, texels: Texels, settings: PassSettings, progress: bool = False) -> RenderResult:
        t0, tex = time.perf_counter(), self._ref(texels, "texels")
        first = settings.first_texel
        outs = self._gather(
            [
                a.render.remote(tex, lo, hi, replace(settings, first_texel=first + lo))
                for a, (lo, hi) in zip(self._shards.actors, self._bounds(len(texels)))
            ]
        )
        return self._result(outs, settings.spp, t0)

    def gradient_pass(
        self,
        texels: Texels,
        adjoint: np.ndarray,
        settings: PassSettings,
        grad_index: np.ndarray | None = None,
        progress: bool = False,
    ) -> tuple[np.ndarray, np.ndarray, RenderResult]:
        """:meth:`TexelRenderer.gradient_pass`: the workers' fixed-point sums are added in int64 and converted
        once."""
        adjoint, t0 = adjoint_array(adjoint, len(texels)), time.perf_counter()
        max_abs = float(np.abs(adjoint).max(initial=0.0))
        gi = None if grad_index is None else self._ref(grad_index, "index")
        tex, first = self._ref(texels, "texels"), settings.first_texel
        self.traffic["out:adjoint"] += adjoint.nbytes
        outs = self._gather(
            [
                a.gradient.remote(tex, lo, hi, adjoint[lo:hi], max_abs, replace(settings, first_texel=first + lo), gi)
                for a, (lo, hi) in zip(self._shards.actors, self._bounds(len(texels)))
            ]
        )
        self.traffic["back:gradient"] += sum(payload_bytes(o[0]) for o in outs)
        self.traffic["dense:gradient"] += sum(2 * 8 * int(np.prod(o[0].shape)) for o in outs)
        quanta = {o[1] for o in outs}
        assert len(quanta) == 1, f"shards used different fixed-point quanta {quanta}"
        gs, ga = np.zeros(outs[0][0].shape, np.int64), np.zeros(outs[0][0].shape, np.int64)
        for o in outs:
            o[0].add_to(gs, ga)  # int64 array sums wrap, as the core's wrapping_add does
        q = quanta.pop()
        return fixed_to_float(gs, q), fixed_to_float(ga, q), self._result([o[2:] for o in outs], settings.spp, t0)

    def _result(self, outs, spp: int, t0: float) -> RenderResult:
        """The pass's result from the workers' (rgb, var_mean, totals), their bytes counted as ``back:render``."""
        self.traffic["back:render"] += sum(payload_bytes(o[:2]) for o in outs)
        totals = {k: sum(o[2][k] for o in outs) for k in outs[0][2]}
        rgb = np.concatenate([o[0] for o in outs]).astype(np.float32)
        var = np.concatenate([o[1] for o in outs]).astype(np.float32)
        return RenderResult(rgb, var, int(spp), time.perf_counter() - t0, **totals)


def _shipped(volume: Volume) -> Volume | BandObject:
    """What a worker is sent of ``volume``: a band volume as a :class:`BandObject` (no grid-sized array), else the
    volume."""
    return BandObject.of(volume) if BandObject.fits(volume) else volume


def _identity(obj) -> tuple:
    """A key of ``obj``: for an array, its memory (owner, address, shape, strides, dtype), so that the same slice
    of one array taken again has the same key; else the object's identity."""
    if isinstance(obj, np.ndarray):
        owner = obj if obj.base is None else obj.base
        return (id(owner), obj.__array_interface__["data"][0], obj.shape, obj.strides, obj.dtype.str)
    return (id(obj),)


@contextlib.contextmanager
def renderer_factory(ray: str | None = None, threads: int | None = None) -> Iterator[RendererFactory]:
    """``Renderer`` (no ``ray``), or ``RayShards(ray, threads=threads).renderer`` for the duration of the block
    (Ray started for it is shut down at the end)."""
    if not ray:
        yield Renderer
        return
    shards = RayShards(ray, threads=threads)
    try:
        yield shards.renderer
    finally:
        shards.close()
