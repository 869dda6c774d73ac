"""Predict the appearance of a volume: the Monte Carlo texel-space renderer (Rust core) and its gradients.

The renderer (docs/method.md §4): smooth dielectric boundary (``Volume.ior``, 1.5 by default), lit by the uniform
environment of radiance 1 or by an environment map (``lighting``: a :class:`inkopt.lighting.Lighting`, "uniform" or a
map file), one sensor element per texel looking along the texel's inward normal. A texel's value is the mean linear-RGB
radiance leaving it toward the viewer, including the specular reflection of the environment unless
``include_specular=False``; a path that leaves the object picks up the light's radiance in its direction. Each channel
is its own monochromatic random walk (exact free flights by delta tracking, and regular tracking near the surface of
masked objects; implicit absorption with Russian roulette; Henyey-Greenstein scattering; Fresnel reflection/refraction),
eight paths per core at a time (SIMD lanes).

Gradients (``Renderer.gradient``): given per-texel adjoints de/dc (I, 3), de/dsigma_s and de/dsigma_a (z, y, x, 3)
by path replay backpropagation (unbiased, ``method="replay"``) or the paper's biased one-pass approximation
(``method="li1"``: radiance along the adjoint path taken as 1, whatever the lighting; only sigma_a gets gradient).

:class:`TexelRenderer` is what every renderer offers (render, gradient, set_volume, set_mixture, set_lighting);
:class:`Renderer` implements it in this process, :class:`inkopt.distributed.ShardedRenderer` over texel shards on
Ray workers, bit-identically.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from .errors import ParameterError
from .lighting import Lighting, load_lighting
from .model import Texels, Volume, mix
from .threads import check_threads

if TYPE_CHECKING:
    from . import _core

# Texels per call into the core; a call re-enters Python only to update the progress bar.
CHUNK = 4096


@dataclass
class RenderResult:
    """rgb, var_mean: (I, 3) float32 linear RGB per texel and the variance of each mean (squared standard error)."""

    rgb: np.ndarray
    var_mean: np.ndarray
    spp: int
    seconds: float
    paths: int
    events: int
    replayed_paths: int = 0
    replayed_events: int = 0

    @property
    def mean_rgb(self) -> np.ndarray:
        """Mean over texels (3,) float64."""
        return self.rgb.astype(np.float64).mean(axis=0)

    @property
    def mean_rgb_stderr(self) -> np.ndarray:
        """Standard error of :attr:`mean_rgb` (texels are independent)."""
        return np.sqrt(self.var_mean.astype(np.float64).sum(axis=0)) / max(len(self.rgb), 1)

    def stats(self) -> dict:
        return {
            "texels": int(len(self.rgb)),
            "spp": self.spp,
            "paths": self.paths,
            "events": self.events,
            "seconds": self.seconds,
            "replayed_paths": self.replayed_paths,
            "replayed_events": self.replayed_events,
        }


@dataclass(frozen=True)
class PassSettings:
    """The settings of one render or gradient pass: ``spp`` samples per texel and channel (at least 1), random
    numbers keyed by (``seed``, texel index, sample), with or without the specular reflection of the light
    (``include_specular``), a gradient pass's ``method`` ("replay" or "li1"), and the index of the pass's first
    texel in the whole list (``first_texel``: a shard of a longer list renders as in the list). ``hero``: ``spp``
    paths per texel, each serving the three channels (hero-channel sampling, "replay" gradients only; the
    spectral band groups) instead of ``spp`` per channel."""

    spp: int
    seed: int
    include_specular: bool = True
    method: str = "replay"
    first_texel: int = 0
    hero: bool = False

    def __post_init__(self):
        if self.spp < 1:
            raise ParameterError(f"`spp` must be at least 1, got {self.spp}")

    def core_kwargs(self, offset: int) -> dict:
        """The core's keyword arguments for the texels from ``offset`` in this pass's list on (``hero`` only when
        asked)."""
        kw = dict(
            spp=int(self.spp),
            seed=int(self.seed),
            first_texel=int(self.first_texel) + offset,
            include_specular=self.include_specular,
        )
        return kw | {"hero": True} if self.hero else kw


def adjoint_array(adjoint: np.ndarray, texels: int) -> np.ndarray:
    """``adjoint`` as a C-contiguous (texels, 3) float32 array; a ParameterError for another shape."""
    adjoint = np.ascontiguousarray(adjoint, np.float32)
    if adjoint.shape != (texels, 3):
        raise ParameterError(f"`adjoint` must have shape ({texels}, 3), got {adjoint.shape}")
    return adjoint


def check_same_grid(volume: Volume, current: Volume) -> None:
    """A ParameterError unless ``volume`` has the grid shape of ``current`` (the volume a renderer was built for)."""
    if volume.shape != current.shape:
        raise ParameterError(f"`volume` has shape {volume.shape}, the renderer's has {current.shape}")


class TexelRenderer(Protocol):
    """What renders the texels of one volume and their gradients: :class:`Renderer` in this process,
    :class:`inkopt.distributed.ShardedRenderer` over texel shards on Ray workers, with bit-identical results.
    ``volume``: the volume it renders (its geometry; after :meth:`set_mixture` no longer its medium);
    ``lighting``: how it is lit. An implementation supplies the passes on a :class:`PassSettings`
    (:meth:`render_pass`, :meth:`gradient_pass`); :meth:`render` and :meth:`gradient`, the callers' signatures,
    are declared here once."""

    volume: Volume
    lighting: Lighting

    @property
    def threads(self) -> int:
        """Worker threads rendering (over all workers). Results do not depend on it."""
        ...

    def set_lighting(self, lighting: Lighting | str | None) -> None:
        """Light the volume by ``lighting`` from now on (None / "uniform", a map file, or a Lighting)."""
        ...

    def set_volume(self, volume: Volume) -> None:
        """Render ``volume`` from now on: same grid, boundary, ior, g, inside mask and normals as the volume this
        renderer was built for (not checked beyond the shape); only the medium is replaced."""
        ...

    def set_mixture(self, index: np.ndarray, mixture: np.ndarray) -> None:
        """Give the voxels ``index`` ((K,) flat (z, y, x) indices) the mixtures ``mixture`` ((K, N), the volume's
        inks), in place: the optimiser's per-iteration update of the free voxels, with no grid-sized array. The
        other voxels keep their medium; :attr:`volume` still describes the geometry but no longer the medium. A
        renderer of a label volume (with an inside mask) first turns its medium into the inside voxels'
        coefficients (each its label's ink), so a big object's base can be labels (1 byte per voxel)."""
        ...

    def render_pass(self, texels: Texels, settings: PassSettings, progress: bool = False) -> RenderResult:
        """:meth:`render` of ``texels``, the first of them with index ``settings.first_texel``."""
        ...

    def gradient_pass(
        self,
        texels: Texels,
        adjoint: np.ndarray,
        settings: PassSettings,
        grad_index: np.ndarray | None = None,
        progress: bool = False,
    ) -> tuple[np.ndarray, np.ndarray, RenderResult]:
        """:meth:`gradient` of ``texels``, the first of them with index ``settings.first_texel``."""
        ...

    def render(
        self, texels: Texels, spp: int = 16, seed: int = 0, include_specular: bool = True, progress: bool = False
    ) -> RenderResult:
        """Forward render of ``texels`` (see the module docstring) with ``spp`` samples per texel; random numbers
        are keyed by (seed, texel index, sample). ``progress``: a progress bar on a terminal, if the renderer has
        one."""
        return self.render_pass(texels, PassSettings(spp, seed, include_specular), progress)

    def gradient(
        self,
        texels: Texels,
        adjoint: np.ndarray,
        spp: int = 16,
        seed: int = 1,
        include_specular: bool = True,
        method: str = "replay",
        progress: bool = False,
        grad_index: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, RenderResult]:
        """Gradient of e with respect to the coefficients, given ``adjoint`` = de/dc (I, 3) in texel order.

        Returns (grad_sigma_s, grad_sigma_a, result): (z, y, x, 3) float32 each, and the pass's own forward
        estimate. With ``grad_index`` only some voxels' gradients are kept, returned as (F, 3) per slot (memory
        proportional to F, not the grid): either (z, y, x) int32, a slot per voxel (-1 for none), or (F,) int64,
        strictly increasing flat (z, y, x) indices of the voxels of slots 0..F-1 (the optimiser's free voxels; no
        grid-sized array).
        Use a different seed from the forward render whose image produced the adjoint, so that the gradient of a
        nonlinear loss is not correlated with the image noise.
        """
        settings = PassSettings(spp, seed, include_specular, method)
        return self.gradient_pass(texels, adjoint, settings, grad_index, progress)


#: What builds a renderer: ``factory(volume, threads, lighting)``, as :class:`Renderer` and
#: :meth:`inkopt.distributed.RayShards.renderer` do.
RendererFactory = Callable[[Volume, int | None, Lighting | str | None], TexelRenderer]


class Renderer(TexelRenderer):
    """A volume prepared for rendering in this process: geometry (grid, inside mask and its safe distances,
    shading normals, boundary) and the thread pool are set up once; the medium can be replaced
    (:meth:`set_volume`, :meth:`set_mixture`) without rebuilding them, as the optimiser does every iteration.

    ``threads``: worker threads (default: all cores). Results do not depend on it.
    ``lighting``: None or "uniform" (radiance 1 from every direction), a map file or a
    :class:`~inkopt.lighting.Lighting` (see :mod:`inkopt.lighting`); :meth:`set_lighting` changes it.
    """

    def __init__(self, volume: Volume, threads: int | None = None, lighting: Lighting | str | None = None):
        from . import _core

        threads = check_threads(threads)  # before the core starts a pool of that many threads
        self.volume = volume
        kw = dict(boundary=volume.boundary, ior=float(volume.ior), g=float(volume.g), threads=threads)
        inside = _core_inside(volume)
        if inside is not None:
            kw["inside"] = inside
        if volume.normals is not None:
            kw["normal_index"], kw["normal_vectors"] = volume.normals.index, volume.normals.vectors
        voxel_mm = tuple(float(v) for v in volume.voxel_mm)
        self._scene = _core.Scene(volume.shape, voxel_mm, self._medium(volume, inside), **kw)
        del inside
        self._labels = volume.form == "labels" and volume.band is None
        self.lighting = Lighting()
        self.set_lighting(lighting)

    def set_lighting(self, lighting: Lighting | str | None) -> None:
        light = load_lighting(lighting)
        self._scene.set_light(light.map, float(light.rotate_deg))
        self.lighting = light

    @staticmethod
    def _medium(volume: Volume, inside: np.ndarray | None = None) -> _core.Medium:
        """The core's medium (``_core.Medium``): with a band (``Volume.band``), the band's coefficients and the
        core's (24 bytes per band voxel, nothing per core voxel; ``inside``: the mask as ``_core_inside`` gives
        it, if already made); labels (by bricks) with the ink table; the inside voxels' coefficients (sparse: 24
        bytes per voxel of each grid row's span) when the volume has an inside mask; else dense coefficients."""
        from ._core import Medium

        if volume.band is not None:
            # Mixed as a row of a batch: a one-row product takes another BLAS path whose float32 sums may round
            # differently, and the core must read exactly what the sparse form's batched rows hold.
            core_s, core_a = mix(np.stack([volume.band.core] * 2), volume.inks)
            inside = _core_inside(volume) if inside is None else inside
            band = volume.band.index
            return Medium.band(inside, band, *volume.coefficients_at(band), core_s[0], core_a[0])
        if volume.form == "labels":  # by bricks
            s, a = (np.asarray(c, np.float32) for c in (volume.inks.sigma_s, volume.inks.sigma_a))
            return Medium.labels(label_bricks(volume.labels, volume.shape), s, a)
        if volume.inside is not None:
            index = volume.inside.nonzero()
            return Medium.sparse(index, *volume.coefficients_at(index))
        s, a = volume.coefficients()
        return Medium.dense(np.ascontiguousarray(s, np.float32), np.ascontiguousarray(a, np.float32))

    def set_volume(self, volume: Volume) -> None:
        check_same_grid(volume, self.volume)
        self._scene.set_medium(self._medium(volume))
        self.volume = volume
        self._labels = volume.form == "labels" and volume.band is None

    def set_mixture(self, index: np.ndarray, mixture: np.ndarray) -> None:
        inks = self.volume.inks
        if inks is None:
            raise ValueError("set_mixture needs a volume with an ink table")
        if self._labels:  # a label medium takes coefficients from now on: its inside voxels', per ink label
            from ._core import Medium

            vol = self.volume
            if vol.inside is None:
                raise ValueError("set_mixture on a label volume needs an inside mask")
            inside = vol.inside.nonzero()
            self._scene.set_medium(Medium.sparse(inside, *vol.coefficients_at(inside)))
            self._labels = False
        if self.volume.band is not None:
            index, mixture = self._band_rows(index, mixture)
        # one row mixed as a row of a batch, as every other (a one-row product rounds by another BLAS path)
        s, a = (c[: len(mixture)] for c in mix(mixture if len(mixture) != 1 else np.repeat(mixture, 2, 0), inks))
        self._scene.set_voxels(
            np.ascontiguousarray(index, np.int64),
            np.ascontiguousarray(s, np.float32),
            np.ascontiguousarray(a, np.float32),
        )

    def _band_rows(self, index: np.ndarray, mixture: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The entries of ``index`` (K,) and ``mixture`` (K, N) in the band; a ValueError for a core voxel given a
        mixture other than the core's (the band medium holds one core mixture), the core's are dropped."""
        index = np.ascontiguousarray(index, np.int64)
        ours = self._scene.in_band(index)
        if ours.all():
            return index, mixture
        core = self.volume.band.core
        rest = np.asarray(mixture)[~ours]
        if not np.array_equal(rest, np.broadcast_to(core, rest.shape)):
            j = int(index[~ours][np.flatnonzero(np.any(rest != core, axis=1))[0]])
            raise ValueError(f"voxel {j} is in the core (one mixture {core.tolist()}) or outside the object")
        return index[ours], np.asarray(mixture)[ours]

    @property
    def distance_storage(self) -> dict | None:
        """The core's signed distances of the inside mask, stored by 8^3 bricks: {"bricks": the grid's, "stored_bricks":
        those held as bytes (512 B each; the others, of one value, 4 B), "bytes": held}; None without a mask."""
        s = self._scene.distance_storage
        return None if s is None else dict(zip(("bricks", "stored_bricks", "bytes"), s))

    @property
    def threads(self) -> int:
        return self._scene.threads

    def _run(
        self, texels: Texels, settings: PassSettings, adjoint: np.ndarray | None = None, progress: bool = False
    ) -> RenderResult:
        """A render pass over ``texels`` (a gradient pass with ``adjoint``, (I, 3) float32), ``CHUNK`` texels per
        call into the core."""
        from ._core import Texels as CoreTexels

        n = len(texels)
        rgb = np.zeros((n, 3), np.float32)
        var = np.zeros((n, 3), np.float32)
        totals = dict(paths=0, events=0, replayed_paths=0, replayed_events=0)
        bar = None
        if progress and n > CHUNK and sys.stderr.isatty():
            from tqdm import tqdm

            desc = "render" if adjoint is None else "gradient"
            bar = tqdm(total=n * settings.spp, unit="texel-spp", unit_scale=True, desc=desc, leave=False)
        t0 = time.perf_counter()
        for a in range(0, n, CHUNK):
            b = min(a + CHUNK, n)
            chunk = CoreTexels(texels.voxel[a:b], texels.face[a:b], texels.normal[a:b])
            kw = settings.core_kwargs(a)
            if adjoint is None:
                m, v, st = self._scene.render(chunk, **kw)
            else:
                m, v, st = self._scene.backward(chunk, adjoint[a:b], **kw, method=settings.method)
            rgb[a:b], var[a:b] = m, v
            for k in totals:
                totals[k] += st[k]
            if bar is not None:
                bar.update((b - a) * settings.spp)
        if bar is not None:
            bar.close()
        return RenderResult(rgb, var, int(settings.spp), time.perf_counter() - t0, **totals)

    def render_pass(self, texels: Texels, settings: PassSettings, progress: bool = False) -> RenderResult:
        return self._run(texels, settings, None, progress)

    def gradient_pass(
        self,
        texels: Texels,
        adjoint: np.ndarray,
        settings: PassSettings,
        grad_index: np.ndarray | None = None,
        progress: bool = False,
    ) -> tuple[np.ndarray, np.ndarray, RenderResult]:
        res = self._backward(texels, adjoint, settings, grad_index, progress)
        gs, ga = self._scene.take_grad()
        return gs, ga, res

    def gradient_fixed(
        self,
        texels: Texels,
        adjoint: np.ndarray,
        settings: PassSettings,
        grad_index: np.ndarray | None = None,
        max_abs_adjoint: float | None = None,
    ) -> tuple[np.ndarray, np.ndarray, float, RenderResult]:
        """:meth:`gradient` of a shard of texels (``texels[0]`` has index ``settings.first_texel``), as raw
        fixed-point sums: (sum_s, sum_a, quantum, result), int64 arrays shaped like :meth:`gradient`'s. The shards of
        one pass, each given the whole pass's ``max_abs_adjoint`` (default: this shard's), add up (int64, wrapping)
        to the pass's sums, and :func:`fixed_to_float` of those is :meth:`gradient`'s result, bit for bit."""
        res = self._backward(texels, adjoint, settings, grad_index, False, max_abs_adjoint)
        gs, ga, quantum = self._scene.take_grad_fixed()
        return gs, ga, quantum, res

    def _backward(
        self,
        texels: Texels,
        adjoint: np.ndarray,
        settings: PassSettings,
        grad_index: np.ndarray | None,
        progress: bool,
        max_abs_adjoint: float | None = None,
    ) -> RenderResult:
        """The gradient pass into the core's buffers (fixed-point quantum from ``max_abs_adjoint``, default the
        largest |adjoint|), left there for ``take_grad`` or ``take_grad_fixed``."""
        adjoint = adjoint_array(adjoint, len(texels))
        if grad_index is not None:
            grad_index = np.asarray(grad_index)
            grad_index = np.ascontiguousarray(grad_index, np.int64 if grad_index.ndim == 1 else np.int32)
        if max_abs_adjoint is None:
            max_abs_adjoint = float(np.abs(adjoint).max(initial=0.0))
        self._scene.zero_grad(float(max_abs_adjoint), grad_index)
        return self._run(texels, settings, adjoint, progress)


def label_bricks(labels, shape) -> _core.LabelBricks:
    """A label grid as the core stores it (``_core.LabelBricks``: 8^3 bricks, one table entry for a brick of one
    label), pushed 8 z-planes at a time from ``labels`` (uint8 (Z, Y, X), read by slices of planes)."""
    from ._core import LabelBricks

    bricks = LabelBricks(tuple(int(s) for s in shape))
    for z in range(0, shape[0], 8):
        bricks.push(np.ascontiguousarray(labels[z : z + 8], np.uint8))
    return bricks


def _core_inside(volume: Volume):
    """The inside mask as the core reads it (``_core.Scene``'s and ``_core.Medium.band``'s ``inside``): a volume's
    mask as its bits (``PackedMask.bits``, no copy; the core unpacks a slab at a time), "labels" for a labels volume
    without one (the core's own label bricks), else None; ``shardwire.BandObject`` (a Ray worker's) makes its own."""
    make = getattr(volume, "inside_bytes", None)
    if make is not None:
        return make()
    if volume.inside is not None:
        return volume.inside.bits
    if volume.form == "labels":  # a band medium reads a mask of its own
        return "labels" if volume.band is None else np.ascontiguousarray(volume.inside_mask()).view(np.uint8)
    return None


def fixed_to_float(fixed_sum: np.ndarray, quantum: float) -> np.ndarray:
    """A gradient from its fixed-point sum, converted exactly as the core converts it: float32(float64(sum) x
    quantum)."""
    return (np.asarray(fixed_sum, np.int64).astype(np.float64) * np.float64(quantum)).astype(np.float32)


def render(
    volume: Volume,
    texels: Texels,
    spp: int = 16,
    seed: int = 0,
    include_specular: bool = True,
    threads: int | None = None,
    progress: bool = False,
    lighting: Lighting | str | None = None,
) -> RenderResult:
    """One-shot forward render (builds a :class:`Renderer`)."""
    return Renderer(volume, threads, lighting).render(texels, spp, seed, include_specular, progress)
