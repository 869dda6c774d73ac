"""Predict the appearance of a volume: the Monte Carlo texel-space renderer (Rust core) and its gradients.

The renderer (docs/method.md §4): smooth dielectric boundary (``Volume.ior``, 1.5 by default), lit by the uniform
environment of radiance 1 or by an environment map (``lighting``: a :class:`inkopt.lighting.Lighting`, "uniform" or a
map file), one sensor element per texel looking along the texel's inward normal. A texel's value is the mean linear-RGB
radiance leaving it toward the viewer, including the specular reflection of the environment unless
``include_specular=False``; a path that leaves the object picks up the light's radiance in its direction. Each channel
is its own monochromatic random walk (exact free flights by delta tracking, and regular tracking near the surface of
masked objects; implicit absorption with Russian roulette; Henyey-Greenstein scattering; Fresnel reflection/refraction),
eight paths per core at a time (SIMD lanes).

Gradients (``Renderer.gradient``): given per-texel adjoints de/dc (I, 3), the derivatives de/dsigma_s and
de/dsigma_a (z, y, x, 3) by path replay backpropagation (unbiased, ``method="replay"``) or the paper's biased
one-pass approximation (``method="li1"``: radiance along the adjoint path approximated by 1, whatever the
lighting; only sigma_a receives gradient under it).
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import numpy as np

from .lighting import Lighting, load_lighting
from .model import Texels, Volume, mix

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


class Renderer:
    """A volume prepared for rendering: geometry (grid, inside mask and its safe distances, shading normals,
    boundary) and the thread pool are set up once; the medium can be replaced (:meth:`set_volume`) without
    rebuilding them, as the optimiser does every iteration.

    ``threads``: worker threads (default: all cores). Results do not depend on it.
    ``lighting``: None or "uniform" (radiance 1 from every direction), a map file or a
    :class:`~inkopt.lighting.Lighting` (see :mod:`inkopt.lighting`); :meth:`set_lighting` changes it.
    """

    def __init__(self, volume: Volume, threads: int | None = None, lighting: Lighting | str | None = None):
        from . import _core

        self.volume = volume
        kw = dict(boundary=volume.boundary, ior=float(volume.ior), g=float(volume.g), threads=threads)
        if volume.inside is not None or volume.form == "labels":
            kw["inside"] = np.ascontiguousarray(volume.inside_mask()).view(np.uint8)  # bool bytes are 0/1: no copy
        if volume.normals is not None:
            kw["normal_index"], kw["normal_vectors"] = volume.normals.index, volume.normals.vectors
        voxel_mm = tuple(float(v) for v in volume.voxel_mm)
        self._scene = _core.Scene(volume.shape, voxel_mm, self._medium(volume), **kw)
        self._labels = volume.form == "labels"
        self.lighting = Lighting()
        self.set_lighting(lighting)

    def set_lighting(self, lighting: Lighting | str | None) -> None:
        """Light the volume by ``lighting`` from now on (None / "uniform", a map file, or a Lighting)."""
        light = load_lighting(lighting)
        self._scene.set_light(light.map, float(light.rotate_deg))
        self.lighting = light

    @staticmethod
    def _medium(volume: Volume):
        """The core's medium (``_core.Medium``): labels with the ink table; the inside voxels' coefficients
        (sparse: 4 bytes per grid voxel + 24 per inside voxel) when the volume has an inside mask; else dense
        coefficients."""
        from ._core import Medium

        if volume.form == "labels":
            inks = volume.inks
            return Medium.labels(volume.labels, inks.sigma_s.astype(np.float32), inks.sigma_a.astype(np.float32))
        if volume.inside is not None:
            index = np.flatnonzero(volume.inside)
            return Medium.sparse(index, *volume.coefficients_at(index))
        s, a = volume.coefficients()
        return Medium.dense(np.ascontiguousarray(s, np.float32), np.ascontiguousarray(a, np.float32))

    def set_volume(self, volume: Volume) -> None:
        """Render ``volume`` from now on: same grid, boundary, ior, g, inside mask and normals as the volume this
        renderer was built for (not checked beyond the shape); only the medium is replaced."""
        if volume.shape != self.volume.shape:
            raise ValueError(f"set_volume: shape {volume.shape} differs from the renderer's {self.volume.shape}")
        self._scene.set_medium(self._medium(volume))
        self.volume = volume
        self._labels = volume.form == "labels"

    def set_mixture(self, index: np.ndarray, mixture: np.ndarray) -> None:
        """Give the voxels ``index`` ((K,) flat (z, y, x) indices) the mixtures ``mixture`` ((K, N), the volume's
        inks), in place: the optimiser's per-iteration update of the free voxels, with no grid-sized array. The
        other voxels keep their medium; :attr:`volume` still describes the geometry but no longer the medium. A
        renderer of a label volume (with an inside mask) first turns its medium into the inside voxels'
        coefficients (each its label's ink), so a big object's base can be labels (1 byte per voxel)."""
        inks = self.volume.inks
        if inks is None:
            raise ValueError("set_mixture needs a volume with an ink table")
        if self._labels:  # a label medium takes coefficients from now on: its inside voxels', per ink label
            vol = self.volume
            if vol.inside is None:
                raise ValueError("set_mixture on a label volume needs an inside mask")
            from ._core import Medium

            inside = np.flatnonzero(vol.inside)
            self._scene.set_medium(Medium.sparse(inside, *vol.coefficients_at(inside)))
            self._labels = False
        s, a = mix(mixture, inks)
        self._scene.set_voxels(
            np.ascontiguousarray(index, np.int64),
            np.ascontiguousarray(s, np.float32),
            np.ascontiguousarray(a, np.float32),
        )

    @property
    def threads(self) -> int:
        return self._scene.threads

    def _run(
        self,
        texels: Texels,
        spp: int,
        seed: int,
        include_specular: bool,
        progress: bool,
        desc: str,
        adjoint: np.ndarray | None = None,
        method: str = "replay",
        first_texel: int = 0,
    ) -> RenderResult:
        from ._core import Texels as CoreTexels

        if spp < 1:
            raise ValueError(f"spp must be at least 1, got {spp}")
        n = len(texels)
        rgb = np.zeros((n, 3), np.float32)
        var = np.zeros((n, 3), np.float32)
        totals = dict(paths=0, events=0, replayed_paths=0, replayed_events=0)
        bar = None
        if progress and n > CHUNK and sys.stderr.isatty():
            from tqdm import tqdm

            bar = tqdm(total=n * spp, unit="texel-spp", unit_scale=True, desc=desc, leave=False)
        t0 = time.perf_counter()
        for a in range(0, n, CHUNK):
            b = min(a + CHUNK, n)
            chunk = CoreTexels(texels.voxel[a:b], texels.face[a:b], texels.normal[a:b])
            kw = dict(spp=int(spp), seed=int(seed), first_texel=first_texel + a, include_specular=include_specular)
            if adjoint is None:
                m, v, st = self._scene.render(chunk, **kw)
            else:
                m, v, st = self._scene.backward(
                    chunk, np.ascontiguousarray(adjoint[a:b], np.float32), **kw, method=method
                )
            rgb[a:b], var[a:b] = m, v
            for k in totals:
                totals[k] += st[k]
            if bar is not None:
                bar.update((b - a) * spp)
        if bar is not None:
            bar.close()
        return RenderResult(rgb, var, int(spp), time.perf_counter() - t0, **totals)

    def render(
        self,
        texels: Texels,
        spp: int = 16,
        seed: int = 0,
        include_specular: bool = True,
        progress: bool = False,
        first_texel: int = 0,
    ) -> RenderResult:
        """Forward render of ``texels``; see module docstring. Random numbers are keyed by (seed, texel index,
        sample); ``first_texel`` is the index of ``texels[0]`` (a shard of a longer list renders as in the list)."""
        return self._run(texels, spp, seed, include_specular, progress, "render", first_texel=first_texel)

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
    ):
        """Gradient of e with respect to the coefficients, given ``adjoint`` = de/dc (I, 3) in texel order.

        Returns (grad_sigma_s, grad_sigma_a, result): (z, y, x, 3) float32 each, and the pass's own forward
        estimate. With ``grad_index`` only some voxels' gradients are kept, returned as (F, 3) per slot (memory
        proportional to F, not the grid): either (z, y, x) int32, a slot per voxel (-1 for none), or (F,) int64,
        strictly increasing flat (z, y, x) indices of the voxels of slots 0..F-1 (the optimiser's free voxels; no
        grid-sized array).
        Use a different seed from the forward render whose image produced the adjoint, so that the gradient of a
        nonlinear loss is not correlated with the image noise.
        """
        res = self._backward(texels, adjoint, spp, seed, include_specular, method, progress, grad_index)
        gs, ga = self._scene.take_grad()
        return gs, ga, res

    def gradient_fixed(
        self,
        texels: Texels,
        adjoint: np.ndarray,
        spp: int = 16,
        seed: int = 1,
        include_specular: bool = True,
        method: str = "replay",
        grad_index: np.ndarray | None = None,
        first_texel: int = 0,
        max_abs_adjoint: float | None = None,
    ):
        """:meth:`gradient` of a shard of texels (``texels[0]`` has index ``first_texel``), as raw fixed-point sums:
        (sum_s, sum_a, quantum, result), int64 arrays shaped like :meth:`gradient`'s. The shards of one pass, each
        given the whole pass's ``max_abs_adjoint`` (default: this shard's), add up (int64, wrapping) to the pass's
        sums, and :func:`fixed_to_float` of those is :meth:`gradient`'s result, bit for bit."""
        res = self._backward(
            texels, adjoint, spp, seed, include_specular, method, False, grad_index, first_texel, max_abs_adjoint
        )
        gs, ga, quantum = self._scene.take_grad_fixed()
        return gs, ga, quantum, res

    def _backward(
        self,
        texels,
        adjoint,
        spp,
        seed,
        include_specular,
        method,
        progress,
        grad_index,
        first_texel=0,
        max_abs_adjoint=None,
    ) -> RenderResult:
        adjoint = np.asarray(adjoint, np.float32)
        if adjoint.shape != (len(texels), 3):
            raise ValueError(f"adjoint must have shape ({len(texels)}, 3), got {adjoint.shape}")
        if grad_index is not None:
            grad_index = np.asarray(grad_index)
            grad_index = np.ascontiguousarray(grad_index, np.int64 if grad_index.ndim == 1 else np.int32)
        if max_abs_adjoint is None:
            max_abs_adjoint = float(np.abs(adjoint).max(initial=0.0))
        self._scene.zero_grad(float(max_abs_adjoint), grad_index)
        return self._run(texels, spp, seed, include_specular, progress, "gradient", adjoint, method, first_texel)


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
