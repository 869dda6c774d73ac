"""Band plans (inkopt.spectral.allocation): bands grouped by the samples they need and the groups weighted by a
pilot render. Regrouped bands render and replay their gradients exactly as a table with its bands in that order;
every band of a planned render agrees with band paths in wavelength order and with adding-doubling within the
standard error; the pilot, the plan and planned renders and gradients are bit-identical for any thread count."""

from dataclasses import replace

import numpy as np
import pytest
from spectral_helpers import INKS, random_volume, smooth_table

from inkopt.errors import ParameterError
from inkopt.model import Texels, Volume
from inkopt.model.spectral import SpectralInkTable
from inkopt.render import Renderer
from inkopt.spectral.allocation import BandPlan, Pilot, choose, pilot, pilot_texels, plan
from inkopt.spectral.lights import named_light
from inkopt.spectral.render import SpectralRenderer, group_spp
from inkopt.spectral.viewing import Viewing


def test_plan_groups_bands_by_their_ideal_density_and_weights_groups_by_neyman():
    """Seven bands: the ideal density sqrt(A / c) orders them; consecutive triples; weight sqrt(A_g / C_g) with a
    short group's repeated slots in its cost; the largest weight 1."""
    noise = np.array([1.0, 16.0, 4.0, 0.0, 9.0, 1.0, 25.0])
    cost = np.array([1.0, 1.0, 4.0, 1.0, 1.0, 4.0, 1.0])
    p = plan(Pilot(noise, cost, 10, 70))
    # densities: 1, 4, 1, 0, 3, 0.5, 5 -> order 6, 1, 4, then 0 and 2 (equal: stable), 5, 3
    assert p.groups == ((6, 1, 4), (0, 2, 5), (3,))
    w = np.array([np.sqrt(50.0 / 3.0), np.sqrt(6.0 / 9.0), 1e-6 * np.sqrt(50.0 / 3.0)])
    np.testing.assert_allclose(p.weights, w / w[0], rtol=1e-12)
    assert group_spp(4, np.array(p.weights), 3) == [10, 2, 1]


def test_the_pilots_choose_hero_paths_only_where_they_cost_less_at_equal_noise():
    """Effort (sum_g sqrt(A_g C_g))^2: band paths' C_g is the three slots' cost, hero paths' one path's; the plan
    chosen is the one of less effort, both efforts recorded."""
    noise, cost = np.array([4.0, 1.0, 1.0, 9.0]), np.array([1.0, 1.0, 2.0, 1.0])
    bands = Pilot(noise, cost, 10, 100, 500, 1.0)
    assert bands.effort(((3, 0, 1), (2,))) == pytest.approx((np.sqrt(14.0 * 3.0) + np.sqrt(1.0 * 6.0)) ** 2)
    cheap = Pilot(noise * 1.5, np.array([2.0, 2.0, 2.0, 1.5]), 10, 30, 60, 0.5, hero=True)
    assert cheap.effort(((0, 1, 2), (3,))) == pytest.approx((np.sqrt(9.0 * 2.0) + np.sqrt(13.5 * 1.5)) ** 2)
    p = choose(bands, cheap)
    assert p.hero and p.groups == ((0, 1, 2), (3,)) and p.measured["effort_hero"] < p.measured["effort_bands"]
    assert p.measured["paths"] == 130 and p.measured["seconds"] == 1.5
    dear = Pilot(noise * 16.0, cheap.cost, 10, 30, 60, 0.5, hero=True)  # a hero path's noise 4x: 16x variance
    q = choose(bands, dear)
    assert not q.hero and q == plan(bands) and q.measured["effort_hero"] > q.measured["effort_bands"]


@pytest.mark.parametrize("groups", [((0, 1), (1, 2)), ((0, 1, 2, 3),), ((0,), (2,)), ((0, 1), (2, 5))])
def test_bad_groups_are_refused(groups):
    with pytest.raises(ParameterError, match="groups must"):
        BandPlan(groups, (1.0,) * len(groups))
    vol = random_volume((2, 2, 2))
    table = SpectralInkTable(INKS.names, [450.0, 550.0, 650.0, 700.0], *[np.ones((5, 4))] * 2, INKS.g)
    with pytest.raises(ParameterError, match="plan must"):
        SpectralRenderer(vol, table, plan=BandPlan(((0, 1, 2),)))
    with pytest.raises(ParameterError, match="weights must"):
        BandPlan(((0, 1, 2), (3,)), (1.0, 0.0))


def test_regrouped_bands_render_as_the_reordered_table_bit_for_bit():
    """Groups ((3, 1, 5), (0, 4, 2)) render, with the same weights, exactly as a table whose bands are in the
    order 3, 1, 5, 0, 4, 2 in its default groups: the same seeds, channels and samples per group, so each band's
    value, variance and gradient are the same bits."""
    vol = random_volume(seed=4)
    tex = Texels.for_volume(vol, ["top", "left"])
    table = smooth_table()
    order = [3, 1, 5, 0, 4, 2]
    moved = SpectralInkTable(INKS.names, np.arange(6.0) + 400, table.sigma_s[:, order], table.sigma_a[:, order])
    w = np.array([2.0, 1.0])
    a = SpectralRenderer(vol, table, threads=2, plan=BandPlan(((3, 1, 5), (0, 4, 2)), w))
    b = SpectralRenderer(vol, moved, threads=1, plan=BandPlan.in_order(moved, w))
    ra, rb = a.render(tex, spp=3, seed=11), b.render(tex, spp=3, seed=11)
    np.testing.assert_array_equal(ra.rgb[:, order], rb.rgb)
    np.testing.assert_array_equal(ra.var_mean[:, order], rb.var_mean)
    adj = np.random.default_rng(2).normal(size=(len(tex), 6)).astype(np.float32)
    ga, gb = a.gradient(tex, adj, spp=2, seed=5), b.gradient(tex, adj[:, order], spp=2, seed=5)
    np.testing.assert_array_equal(ga[0][..., order], gb[0])
    np.testing.assert_array_equal(ga[1][..., order], gb[1])


def test_pilot_measures_each_band_and_is_the_same_for_any_thread_count():
    vol = random_volume(seed=5)
    tex = Texels.for_volume(vol)
    table = smooth_table()
    cmaps = [named_light(n).colour_map(table.wavelengths_nm) for n in ("D65", "A")]
    one, two = pilot(vol, table, tex, cmaps, threads=1), pilot(vol, table, tex, cmaps, threads=2)
    np.testing.assert_array_equal(one.noise, two.noise)
    np.testing.assert_array_equal(one.cost, two.cost)
    spp = max(2, -(-8192 // len(tex)))
    assert one.texels == len(tex) and one.paths == 6 * 3 * spp * len(tex)
    assert np.all(one.noise > 0) and np.all(one.cost >= 1)
    assert len(pilot_texels(tex, 50)) == 50 and pilot_texels(tex, 50).voxel[-1].tolist() == tex.voxel[-1].tolist()


def test_planned_bands_agree_with_band_paths_and_the_plan_keeps_thread_bit_identity():
    """Each band's texel mean by a planned viewing's renderer against wavelength-ordered band paths (independent
    noise): |difference| < 4.5 combined standard errors; renders and gradients the same bits for 1 and 2
    threads; the plan is in the viewing's key."""
    vol = random_volume(seed=6)
    tex = Texels.for_volume(vol, ["top", "front"])
    table = smooth_table()
    viewing = Viewing(table, (named_light("D65"), named_light("A"))).planned(vol, tex, threads=2)
    assert viewing.plan is not None and viewing.key() != Viewing(table, viewing.lights).key()
    assert viewing.plan == Viewing(table, viewing.lights).planned(vol, tex, threads=1).plan
    make = viewing.renderer_factory(Renderer)
    planned = make(vol, 2, None).render(tex, spp=40, seed=5)
    plain = SpectralRenderer(vol, table, threads=2).render(tex, spp=40, seed=1005)
    diff = planned.mean_rgb - plain.mean_rgb
    se = np.sqrt(planned.mean_rgb_stderr**2 + plain.mean_rgb_stderr**2)
    assert np.all(np.abs(diff) < 4.5 * se), (diff, se)
    again = make(vol, 1, None).render(tex, spp=40, seed=5)
    np.testing.assert_array_equal(planned.rgb, again.rgb)
    adj = np.random.default_rng(3).normal(size=(len(tex), 6)).astype(np.float32)
    g2, g1 = make(vol, 2, None).gradient(tex, adj, spp=2, seed=9), make(vol, 1, None).gradient(tex, adj, 2, 9)
    np.testing.assert_array_equal(g2[0], g1[0])
    np.testing.assert_array_equal(g2[1], g1[1])


def test_planned_bands_match_adding_doubling_on_a_slab():
    """As test_render's adding-doubling check, with the bands grouped and weighted by a pilot: each band within
    four standard errors plus the quadrature's own error (|R16 - R32|)."""
    pytest.importorskip("iadpython")
    from inkopt.calibration.stack import channel_reflectance, upper_hemisphere

    table = smooth_table()
    share = np.array([0.3, 0.1, 0.2, 0.05, 0.35])
    m = np.broadcast_to(share.astype(np.float32), (20, 1, 1, 5)).copy()
    vol = Volume.from_mixture((0.1, 0.1, 0.05), m, INKS, g=float(INKS.g), ior=1.5, boundary="periodic-xy")
    tex, light = Texels.for_volume(vol, ["top"]), upper_hemisphere()
    viewing = Viewing(table, (named_light("A"),))  # band paths' plan (a pilot here would choose hero paths)
    viewing = replace(viewing, plan=plan(pilot(vol, table, tex, viewing.colours(), 2, light)))
    assert viewing.plan.groups != ((0, 1, 2), (3, 4, 5))  # regrouped: the test covers the groups' wiring
    res = viewing.renderer_factory(Renderer)(vol, 2, light).render(tex, spp=50_000, seed=7)
    mc, se = res.mean_rgb, res.mean_rgb_stderr
    s, a = share @ table.sigma_s, share @ table.sigma_a
    ad16 = np.array([channel_reflectance([(s[b], a[b], 1.0)], table.g, 1.5, 16) for b in range(6)])
    ad32 = np.array([channel_reflectance([(s[b], a[b], 1.0)], table.g, 1.5, 32) for b in range(6)])
    assert np.all(np.abs(mc - ad32) < 4 * se + np.abs(ad16 - ad32)), (mc, ad32, se)


def test_viewing_plan_refusals():
    table = smooth_table()
    with pytest.raises(ParameterError, match="plan"):
        Viewing(None, (), plan=BandPlan(((0, 1, 2),), (1.0,)))
    with pytest.raises(ParameterError, match="plan"):
        Viewing(table, (), plan=BandPlan(((0, 1, 2),), (1.0,)))
    with pytest.raises(ParameterError, match="plan"):
        Viewing().planned(random_volume((2, 2, 2)), Texels.for_volume(random_volume((2, 2, 2))))
