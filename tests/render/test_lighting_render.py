"""Rendering under an environment map (``inkopt.lighting``, core ``EnvMap``): a constant map is the uniform light,
a map lit from above only gives a slab's top and bottom faces adding-doubling's reflectance and transmittance,
and path-replay gradients under a map match finite differences.

Tolerances come from the estimators' standard errors: a difference of two independent Monte Carlo means over
thousands of paths is normal to a very good approximation, and 4 standard errors give a false-alarm rate of
6e-5 per comparison (about a dozen comparisons here: ~1e-3 for the file). Adding-doubling also gets the
difference between its 16- and 32-point quadratures as its own discretisation error.
"""

import numpy as np
import pytest
from helpers import replay_matches_fd

from inkopt.lighting import Lighting, load_lighting
from inkopt.model import Texels, Volume
from inkopt.render import Renderer, render


def homogeneous(a, b, d=1.0, nz=10, nxy=6):
    """An infinite (periodic) slab of thickness d mm, albedo a, optical thickness b, g 0.4, IOR 1.5."""
    mu_t = b / d
    s = np.full((nz, nxy, nxy, 3), mu_t * a, np.float32)
    return Volume.from_coefficients(
        (d / nz,) * 3, sigma_s=s, sigma_a=np.full_like(s, mu_t * (1 - a)), g=0.4, ior=1.5, boundary="periodic-xy"
    )


def constant_map(rgb, h=8) -> Lighting:
    return Lighting(np.broadcast_to(np.asarray(rgb, np.float32), (h, 2 * h, 3)).copy(), 0.0, "constant")


def upper_hemisphere_map(h=256) -> Lighting:
    """Radiance 1 from every direction above the horizon, 0 below. Bilinear lookup blurs the step over half a
    row on either side of the horizon (+-0.35 degrees at h = 256), where a slab sends a fraction ~1e-4 of its
    light: far below the tests' standard errors."""
    env = np.zeros((h, 2 * h, 3), np.float32)
    env[: h // 2] = 1.0
    return Lighting(env, 0.0, "upper hemisphere")


def test_a_constant_map_is_the_uniform_light():
    """Radiance 1 everywhere is the uniform light to the bit (same seed); radiance k per channel equals k times
    the uniform render in expectation (independent seeds, within 4 standard errors of the difference)."""
    vol = homogeneous(0.9, 2.0)
    tex = Texels.for_volume(vol, ["top", "bottom"])
    uni = render(vol, tex, spp=256, seed=5)
    np.testing.assert_array_equal(render(vol, tex, spp=256, seed=5, lighting=constant_map([1, 1, 1])).rgb, uni.rgb)
    k = np.array([0.5, 1.0, 2.5])
    a = render(vol, tex, spp=512, seed=6, lighting=constant_map(k))
    b = render(vol, tex, spp=512, seed=7)
    se = np.sqrt(a.mean_rgb_stderr**2 + (k * b.mean_rgb_stderr) ** 2)
    assert np.all(np.abs(a.mean_rgb - k * b.mean_rgb) < 4 * se), (a.mean_rgb, k * b.mean_rgb, se)


@pytest.mark.parametrize("a,b", [(0.99, 4.0), (0.9, 2.0)])
def test_light_from_above_gives_reflectance_on_top_and_transmittance_below(a, b):
    """Radiance 1 from the upper hemisphere, 0 from below, on an infinite slab. A top-face texel looks straight
    down; by reciprocity its radiance is the fraction of light entering along its camera ray (normal incidence)
    that leaves through the top face (into the lit hemisphere), specular reflection included: adding-doubling's
    total reflectance for normal incidence, R. A bottom-face texel looks straight up; its paths leave into the lit
    hemisphere only through the top face, and its specular reflection goes down into the dark: the total
    transmittance for normal incidence, T. So top - bottom = R - T (uniform light gives R + T on both)."""
    iad = pytest.importorskip("iadpython")
    vol = homogeneous(a, b)
    top, bottom = (Texels.for_volume(vol, [f]) for f in ("top", "bottom"))
    rnd = Renderer(vol, lighting=upper_hemisphere_map())
    rt, rb = rnd.render(top, spp=1500, seed=3), rnd.render(bottom, spp=1500, seed=4)
    r16, t16, _, _ = iad.Sample(a=a, b=b, g=0.4, d=1.0, n=1.5, quad_pts=16).rt()
    r32, t32, _, _ = iad.Sample(a=a, b=b, g=0.4, d=1.0, n=1.5, quad_pts=32).rt()
    assert np.all(np.abs(rt.mean_rgb - r32) < 4 * rt.mean_rgb_stderr + abs(r16 - r32)), (rt.mean_rgb, r32)
    assert np.all(np.abs(rb.mean_rgb - t32) < 4 * rb.mean_rgb_stderr + abs(t16 - t32)), (rb.mean_rgb, t32)
    diff, se = rt.mean_rgb - rb.mean_rgb, np.hypot(rt.mean_rgb_stderr, rb.mean_rgb_stderr)
    assert np.all(np.abs(diff - (r32 - t32)) < 4 * se + abs(r16 - t16 - r32 + t32)), (diff, r32 - t32)
    assert np.all(diff > 0) == (r32 > t32)


def _small_slab():
    rng = np.random.default_rng(3)
    s = rng.uniform(2, 12, (4, 3, 3, 3)).astype(np.float32)
    return Volume.from_coefficients(
        (0.1,) * 3, sigma_s=s, sigma_a=rng.uniform(0.2, 3, s.shape).astype(np.float32), boundary="periodic-xy"
    )


PROBES = [(3, 1, 1, 0, "sigma_s"), (3, 1, 1, 2, "sigma_a"), (2, 0, 1, 1, "sigma_s"), (1, 1, 2, 0, "sigma_a")]


def test_gradient_under_a_constant_map_matches_finite_differences():
    """The same check as under uniform light (tests/render/test_render.py), with radiance (0.5, 1, 2.5)."""
    replay_matches_fd(_small_slab(), PROBES, spp=600, lighting=constant_map([0.5, 1.0, 2.5]))


def test_gradient_under_a_directional_map_matches_finite_differences():
    """A warm light low on one side and a dim cool sky, turned by 30 degrees: the values of the escaping paths
    now depend on their direction, and replay must weigh every path by its own value."""
    h = 32
    theta = (np.arange(h) + 0.5) * np.pi / h
    phi = (np.arange(2 * h) + 0.5) * np.pi / h
    d = np.stack(
        np.broadcast_arrays(
            np.sin(theta)[:, None] * np.cos(phi), np.sin(theta)[:, None] * np.sin(phi), np.cos(theta)[:, None] + 0 * phi
        ),
        -1,
    )
    key = np.clip(d @ np.array([0.8, 0.0, 0.6]), 0, None) ** 4
    env = 0.1 * np.array([0.6, 0.8, 1.2]) * (d[..., 2:] > 0) + key[..., None] * np.array([3.0, 2.0, 1.0])
    replay_matches_fd(_small_slab(), PROBES, spp=600, lighting=Lighting(env.astype(np.float32), 30.0, "key"))


def test_renderer_set_lighting_and_one_line_errors(tmp_path):
    vol = _small_slab()
    tex = Texels.for_volume(vol, ["top"])
    rnd = Renderer(vol, lighting=constant_map([2, 2, 2]))
    lit = rnd.render(tex, spp=8, seed=1)
    rnd.set_lighting("uniform")
    np.testing.assert_array_equal(rnd.render(tex, spp=8, seed=1).rgb * 2, lit.rgb)
    assert rnd.lighting.uniform and load_lighting(None).uniform
    bad = np.ones((4, 8, 3), np.float32)
    bad[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        Renderer(vol, lighting=Lighting(bad))
