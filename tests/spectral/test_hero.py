"""Hero paths in band renders (``BandPlan(hero=True)``: each group's paths carry its three bands): every
band agrees with the per-band render and with adding-doubling within the standard error, on the lanes (mask-free
grids) and the scalar walk (masked grids); the option changes nothing else."""

import numpy as np
import pytest
from spectral_helpers import INKS, smooth_table

from inkopt.model import Texels, Volume
from inkopt.render import PassSettings
from inkopt.spectral.allocation import BandPlan
from inkopt.spectral.render import SpectralRenderer

VOX = 0.0847


def volume(inside: bool, seed=0) -> Volume:
    """A random mixture in a 6 x 7 x 8 box; ``inside``: with a notch cut out (a masked box: the scalar walk)."""
    rng = np.random.default_rng(seed)
    m = rng.dirichlet(np.ones(len(INKS)), size=(6, 7, 8)).astype(np.float32)
    mask = None
    if inside:
        mask = np.ones((6, 7, 8), bool)
        mask[:2, :3, :3] = False
    return Volume.from_mixture(voxel_mm=(VOX,) * 3, mixture=m, inks=INKS, inside=mask)


@pytest.mark.parametrize("inside", [False, True])
def test_hero_bands_agree_with_band_paths(inside):
    """Each band's texel mean by hero paths against the per-band render's (independent noise): |difference| < 4.5
    combined standard errors (a false alarm 7e-6 per band)."""
    vol = volume(inside)
    table = smooth_table()
    tex = Texels.for_volume(vol, ["top", "front"])
    hero = SpectralRenderer(vol, table, threads=2, plan=BandPlan.in_order(table, hero=True)).render(tex, spp=60, seed=5)
    plain = SpectralRenderer(vol, table, threads=2).render(tex, spp=60, seed=1005)
    assert hero.paths * 3 == plain.paths  # one path per sample and group instead of three
    diff = hero.mean_rgb - plain.mean_rgb
    se = np.sqrt(hero.mean_rgb_stderr**2 + plain.mean_rgb_stderr**2)
    assert np.all(np.abs(diff) < 4.5 * se), (diff, se)


def test_hero_bands_match_adding_doubling_on_a_slab():
    """As test_render's adding-doubling check, with hero paths: each band within four standard errors plus the
    quadrature's own error (|R16 - R32|)."""
    pytest.importorskip("iadpython")
    from inkopt.calibration.stack import channel_reflectance, upper_hemisphere

    table = smooth_table()
    share = np.array([0.3, 0.1, 0.2, 0.05, 0.35])
    m = np.broadcast_to(share.astype(np.float32), (20, 1, 1, 5)).copy()
    vol = Volume.from_mixture((0.1, 0.1, 0.05), m, INKS, g=float(INKS.g), ior=1.5, boundary="periodic-xy")
    res = SpectralRenderer(
        vol, table, threads=2, lighting=upper_hemisphere(), plan=BandPlan.in_order(table, hero=True)
    ).render(Texels.for_volume(vol, ["top"]), spp=100_000, seed=7)
    mc, se = res.mean_rgb, res.mean_rgb_stderr
    s, a = share @ table.sigma_s, share @ table.sigma_a
    ad16 = np.array([channel_reflectance([(s[b], a[b], 1.0)], table.g, 1.5, 16) for b in range(6)])
    ad32 = np.array([channel_reflectance([(s[b], a[b], 1.0)], table.g, 1.5, 32) for b in range(6)])
    assert np.all(np.abs(mc - ad32) < 4 * se + np.abs(ad16 - ad32)), (mc, ad32, se)


def test_hero_is_off_unless_asked():
    """The core is asked for hero paths only when a pass says so: the RGB path's keyword arguments are as before."""
    assert "hero" not in PassSettings(4, 1).core_kwargs(0)
    assert PassSettings(4, 1, hero=True).core_kwargs(10) == dict(
        spp=4, seed=1, first_texel=10, include_specular=True, hero=True
    )
