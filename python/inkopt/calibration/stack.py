"""The measurement model of a calibration patch: a laterally infinite stack, the patch layer (a mixture of inks)
on a backing layer of one pure ink (or on nothing), nothing below, index of refraction 1.5 throughout (no
interface between the two layers, Fresnel interfaces to air above and below), one Henyey-Greenstein g shared by
all inks, lit by uniform diffuse light of radiance 1 from the upper hemisphere only and seen straight down with
the specular reflection included (as ``inkopt render --face top`` with a map that is 1 above the horizon).

By reciprocity a top texel's radiance under that light is the stack's total reflectance for light arriving along
the normal (specular included), which adding-doubling (``iadpython``) computes for each R, G, B channel:
:func:`reflectance_ad`. :func:`reflectance_mc` renders the same stack with inkopt's Monte Carlo renderer (a
periodic 1 x 1 voxel column), the reference the adding-doubling model is tested against.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from threadpoolctl import threadpool_limits

from ..lighting import Lighting
from ..model import InkTable, Texels, Volume

IOR = 1.5
QUAD_PTS = 16  # adding-doubling quadrature points (16 vs 32 changes a reflectance by ~2e-4)


@dataclass(frozen=True)
class Stack:
    """One patch's geometry: ``mixture`` (N,) float64 shares of the ink table's inks in the patch layer,
    ``thickness_mm`` of that layer, ``backing`` the index of the backing layer's ink (None: nothing under the
    patch) and ``backing_mm`` its thickness (0 with no backing)."""

    mixture: tuple[float, ...]
    thickness_mm: float
    backing: int | None
    backing_mm: float

    def layers(self, inks: InkTable) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """[(sigma_s (3,), sigma_a (3,), thickness mm)] top to bottom, in mm^-1."""
        m = np.asarray(self.mixture, np.float64)
        out = [(m @ inks.sigma_s, m @ inks.sigma_a, float(self.thickness_mm))]
        if self.backing is not None and self.backing_mm > 0:
            out.append((inks.sigma_s[self.backing], inks.sigma_a[self.backing], float(self.backing_mm)))
        return out


def upper_hemisphere(h: int = 256) -> Lighting:
    """Radiance 1 from every direction above the horizon, 0 below (bilinear lookup blurs the step over half a row,
    +-0.35 degrees at h = 256, where a slab sends ~1e-4 of its light)."""
    env = np.zeros((h, 2 * h, 3), np.float32)
    env[: h // 2] = 1.0
    return Lighting(env, 0.0, "upper hemisphere")


# ----------------------------------------------------------------------------------------------- adding-doubling
class _AD:
    """Adding-doubling matrices of one quadrature (g and ior fixed): layers by (albedo, optical thickness), cached,
    and the two air boundaries."""

    def __init__(self, g: float, ior: float = IOR, quad_pts: int = QUAD_PTS):
        import iadpython

        self.sample = iadpython.Sample(a=0.5, b=1.0, g=float(g), d=1.0, n=float(ior), quad_pts=int(quad_pts))
        self.sample.update_quadrature()
        self.top = iadpython.start.boundary_layer(self.sample, top=True)
        self.bottom = iadpython.start.boundary_layer(self.sample, top=False)
        self._layer = lru_cache(maxsize=4096)(self._layer_uncached)

    def _layer_uncached(self, a: float, b: float):
        from iadpython import combine

        self.sample.a, self.sample.b = a, max(b, 1e-9)
        r, t = combine.simple_single_layer_matrices(self.sample)
        return r, r, t, t

    def layer(self, sigma_s: float, sigma_a: float, d_mm: float):
        mu_t = sigma_s + sigma_a
        a = sigma_s / mu_t if mu_t > 0 else 1.0
        return self._layer(float(a), float(mu_t * d_mm))

    def reflectance(self, layers) -> float:
        """Total reflectance for normal incidence (specular included) of [(sigma_s, sigma_a, d_mm)], top first."""
        from iadpython import combine

        s = self.sample
        r01, r10, t01, t10 = self.layer(*layers[0])
        for lay in layers[1:]:
            r01, r10, t01, t10 = combine.add_layers(s, r01, r10, t01, t10, *self.layer(*lay))
        r02, r20, t02, t20 = combine.add_slide_above(s, *self.top, r01, r10, t01, t10)
        r03, _, t03, _ = combine.add_slide_below(s, r02, r20, t02, t20, *self.bottom)
        return float(s.UX1_and_UXU(r03, t03)[0])


def one_blas_thread(fn):
    """Run ``fn`` with the BLAS library on one thread: adding-doubling multiplies matrices of a few dozen rows, where
    BLAS threads cost ~80x the arithmetic (a chart's 5 inks: 4.0 CPU s on the default threads, 0.05 s on one) and
    give the same numbers."""

    @functools.wraps(fn)
    def wrapped(*args, **kwargs):
        with threadpool_limits(limits=1, user_api="blas"):
            return fn(*args, **kwargs)

    return wrapped


@lru_cache(maxsize=8)
def _ad(g: float, ior: float, quad_pts: int) -> _AD:
    return _AD(g, ior, quad_pts)


def channel_reflectance(layers, g: float, ior: float = IOR, quad_pts: int = QUAD_PTS) -> float:
    """One channel: ``layers`` [(sigma_s, sigma_a, thickness_mm)] top first (floats) -> total reflectance."""
    return _ad(float(g), float(ior), int(quad_pts)).reflectance(layers)


@one_blas_thread
def reflectance_ad(stack: Stack, inks: InkTable, quad_pts: int = QUAD_PTS) -> np.ndarray:
    """(3,) float64 linear-RGB reflectance of ``stack`` by adding-doubling."""
    lay = stack.layers(inks)
    return np.array(
        [channel_reflectance([(s[c], a[c], d) for s, a, d in lay], inks.g, IOR, quad_pts) for c in range(3)]
    )


# ----------------------------------------------------------------------------------------------- Monte Carlo
def stack_volume(stack: Stack, inks: InkTable, dz_mm: float | None = None) -> Volume:
    """A periodic 1 x 1 voxel column holding ``stack`` (patch on top, +z up). The z voxel divides both
    thicknesses (``dz_mm``: default their greatest common step of 1 µm, at most 0.05 mm)."""
    lay = stack.layers(inks)
    um = [int(round(d * 1000)) for _, _, d in lay]
    if dz_mm is None:
        step = int(np.gcd.reduce(um))
        dz_mm = step / 1000 / max(1, int(np.ceil(step / 50)))
    counts = [int(round(d / dz_mm)) for _, _, d in lay]
    if any(abs(n * dz_mm - d) > 1e-6 for n, (_, _, d) in zip(counts, lay)) or min(counts) < 1:
        raise ValueError(f"layer thicknesses {[d for _, _, d in lay]} mm are not multiples of {dz_mm} mm")
    s = np.concatenate([np.broadcast_to(s_, (n, 3)) for n, (s_, _, _) in zip(counts, lay)][::-1])
    a = np.concatenate([np.broadcast_to(a_, (n, 3)) for n, (_, a_, _) in zip(counts, lay)][::-1])
    shape = (len(s), 1, 1, 3)
    return Volume.from_coefficients(
        (0.1, 0.1, dz_mm),
        sigma_s=s.reshape(shape).astype(np.float32),
        sigma_a=a.reshape(shape).astype(np.float32),
        g=float(inks.g),
        ior=IOR,
        boundary="periodic-xy",
    )


def reflectance_mc(stack: Stack, inks: InkTable, spp: int, seed: int = 0, threads: int | None = None):
    """The stack rendered by inkopt's renderer under :func:`upper_hemisphere` light, seen from the top:
    (mean (3,), standard error (3,)) float64 linear RGB."""
    from ..render import Renderer

    vol = stack_volume(stack, inks)
    res = Renderer(vol, threads=threads, lighting=upper_hemisphere()).render(
        Texels.for_volume(vol, ["top"]), spp=spp, seed=seed
    )
    return res.mean_rgb, res.mean_rgb_stderr
