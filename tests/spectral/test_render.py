"""Band renders (inkopt.spectral.render): a 3-band table whose bands are an RGB table's channels renders (and its
gradient replays) bit-identically to the RGB renderer; a table flat within each RGB band agrees with the RGB
render within the standard error; each band of a slab matches adding-doubling within the standard error."""

import numpy as np
import pytest
from spectral_helpers import INKS, VOX, random_volume, rgb_as_bands, smooth_table

from inkopt.errors import ParameterError
from inkopt.lighting import Lighting
from inkopt.model import InkTable, Texels, Volume
from inkopt.model.spectral import SpectralInkTable
from inkopt.render import Renderer
from inkopt.spectral.allocation import BandPlan
from inkopt.spectral.render import SpectralRenderer, group_seed, group_spp


def test_group_seeds():
    assert group_seed(123, 0) == 123
    seeds = {group_seed(s, k) for s in range(5) for k in range(1, 12)}
    assert len(seeds) == 55 and all(0 <= x < 2**63 for x in seeds)


def test_three_bands_are_the_rgb_renderer_bit_for_bit():
    vol = random_volume()
    tex = Texels.for_volume(vol)
    table = SpectralInkTable(INKS.names, [450.0, 550.0, 650.0], INKS.sigma_s, INKS.sigma_a, INKS.g)
    spec = SpectralRenderer(vol, table, threads=2)
    rgb = Renderer(vol, threads=1)
    a, b = spec.render(tex, spp=4, seed=9), rgb.render(tex, spp=4, seed=9)
    np.testing.assert_array_equal(a.rgb, b.rgb)
    np.testing.assert_array_equal(a.var_mean, b.var_mean)
    adj = np.random.default_rng(1).normal(size=(len(tex), 3)).astype(np.float32)
    ga, gb = spec.gradient(tex, adj, spp=2, seed=3), rgb.gradient(tex, adj, spp=2, seed=3)
    np.testing.assert_array_equal(ga[0], gb[0])
    np.testing.assert_array_equal(ga[1], gb[1])


def test_flat_bands_agree_with_rgb_within_the_standard_error():
    """Nine bands, three per RGB channel with its coefficients: every band estimates its channel's value. The texel
    mean of each band against the RGB render's (independent noise): |difference| < 4.5 standard errors."""
    vol = random_volume(seed=2)
    tex = Texels.for_volume(vol, ["top"])
    spec = SpectralRenderer(vol, rgb_as_bands(INKS, 3), threads=2).render(tex, spp=64, seed=5)
    rgb = Renderer(vol, threads=2).render(tex, spp=64, seed=1005)
    channel = np.repeat([2, 1, 0], 3)
    band_mean = spec.rgb.astype(np.float64).mean(axis=0)
    band_se = np.sqrt(spec.var_mean.astype(np.float64).sum(axis=0)) / len(tex)
    diff = band_mean - rgb.mean_rgb[channel]
    se = np.sqrt(band_se**2 + rgb.mean_rgb_stderr[channel] ** 2)
    assert np.all(np.abs(diff) < 4.5 * se), (diff, se)
    # the groups' noise is independent: bands of one channel in different groups do not agree bit for bit
    assert not np.array_equal(spec.rgb[:, 0], spec.rgb[:, 3])


def test_bands_match_adding_doubling_on_a_slab():
    """A 1 mm layer of one mixture over nothing, under light from the upper hemisphere: each band's mean within
    four standard errors plus the adding-doubling quadrature's own error (|R16 - R32|)."""
    pytest.importorskip("iadpython")
    from inkopt.calibration.stack import channel_reflectance, upper_hemisphere

    table = smooth_table()
    share = np.array([0.3, 0.1, 0.2, 0.05, 0.35])
    m = np.broadcast_to(share.astype(np.float32), (20, 1, 1, 5)).copy()
    vol = Volume.from_mixture((0.1, 0.1, 0.05), m, INKS, g=float(INKS.g), ior=1.5, boundary="periodic-xy")
    res = SpectralRenderer(vol, table, threads=2, lighting=upper_hemisphere()).render(
        Texels.for_volume(vol, ["top"]), spp=100_000, seed=7
    )
    mc, se = res.mean_rgb, res.mean_rgb_stderr
    s, a = share @ table.sigma_s, share @ table.sigma_a
    ad16 = np.array([channel_reflectance([(s[b], a[b], 1.0)], table.g, 1.5, 16) for b in range(6)])
    ad32 = np.array([channel_reflectance([(s[b], a[b], 1.0)], table.g, 1.5, 32) for b in range(6)])
    assert np.all(np.abs(mc - ad32) < 4 * se + np.abs(ad16 - ad32)), (mc, ad32, se)


def test_refusals():
    vol = random_volume((2, 2, 2))
    table = smooth_table()
    env = np.ones((4, 8, 3), np.float32)
    env[..., 0] = 2.0
    with pytest.raises(ParameterError, match="grey"):
        SpectralRenderer(vol, table, lighting=Lighting(env, 0.0, "red"))
    other = SpectralInkTable(("a", "b", "c", "d", "e"), table.wavelengths_nm, table.sigma_s, table.sigma_a)
    with pytest.raises(ParameterError, match="inks"):
        SpectralRenderer(vol, other)
    dense = Volume.from_coefficients((VOX,) * 3, np.ones((2, 2, 2, 3), np.float32), np.ones((2, 2, 2, 3), np.float32))
    with pytest.raises(ParameterError, match="volume's inks None"):
        SpectralRenderer(dense, table)


def test_group_samples():
    assert group_spp(7, None, 6) == [7] * 6
    assert group_spp(7, np.ones(1), 1) == [7]
    got = group_spp(8, np.array([1.0, 3.0, 0.001]), 3)
    assert got == [6, 18, 1]


def test_weighted_groups_stay_unbiased():
    """Weighted samples per group (9 bands flat within RGB channels): each band's texel mean within 4.5 standard
    errors of the RGB render's, and each band's variance that of its own sample count."""
    vol = random_volume(seed=3)
    tex = Texels.for_volume(vol, ["top"])
    bands = rgb_as_bands(INKS, 3)
    spec = SpectralRenderer(vol, bands, threads=2, plan=BandPlan.in_order(bands, (1.0, 2.0, 0.5)))
    res = spec.render(tex, spp=32, seed=5)
    rgb = Renderer(vol, threads=2).render(tex, spp=64, seed=1005)
    channel = np.repeat([2, 1, 0], 3)
    diff = res.rgb.astype(np.float64).mean(axis=0) - rgb.mean_rgb[channel]
    se = np.sqrt(res.var_mean.astype(np.float64).sum(axis=0) / len(tex) ** 2 + rgb.mean_rgb_stderr[channel] ** 2)
    assert np.all(np.abs(diff) < 4.5 * se), (diff, se)
    # each group's variance is that of its own samples: against an equal-samples render, var ~ 32 / spp_g
    equal = SpectralRenderer(vol, rgb_as_bands(INKS, 3), threads=2).render(tex, spp=32, seed=5)
    spp = np.repeat(group_spp(32, spec.weights, 3), 3)
    ratio = res.var_mean.astype(np.float64).mean(axis=0) / equal.var_mean.astype(np.float64).mean(axis=0)
    np.testing.assert_allclose(ratio, 32.0 / spp, rtol=0.25)


def test_label_volumes_render_as_the_rgb_renderer():
    """A labels volume (a mesh scene's base) with a 3-band table whose bands are the RGB channels: bit for bit."""
    labels = np.random.default_rng(6).integers(0, len(INKS), (5, 6, 7)).astype(np.uint8)
    vol = Volume.from_labels((VOX,) * 3, labels, INKS)
    tex = Texels.for_volume(vol)
    table = rgb_as_bands(INKS)  # bands B, G, R: group 0 traces them as channels 0, 1, 2
    got = SpectralRenderer(vol, table, threads=2).render(tex, spp=4, seed=2)
    order = InkTable(INKS.names, INKS.sigma_s[:, [2, 1, 0]].copy(), INKS.sigma_a[:, [2, 1, 0]].copy(), INKS.g)
    want = Renderer(Volume.from_labels((VOX,) * 3, labels, order), threads=1).render(tex, spp=4, seed=2)
    np.testing.assert_array_equal(got.rgb, want.rgb)


def test_printed_renderer_renders_bands_as_the_rgb_one():
    """The printer texels of a labels grid (``evaluation.printed.PrintedRenderer``) rendered through band renders of
    a 3-band table whose bands are the RGB channels: the same scene-texel averages bit for bit, for the first labels
    volume and for one swapped in; the swapped-in volume is released by every group's renderer."""
    from inkopt.evaluation.printed import PrintedRenderer

    rng = np.random.default_rng(8)
    a, b = (rng.integers(0, len(INKS), (6, 8, 10)).astype(np.uint8) for _ in range(2))
    scene = Texels.for_volume(Volume.from_labels((2 * VOX,) * 3, a[::2, ::2, ::2].copy(), INKS), [5])
    table = rgb_as_bands(INKS)
    order = InkTable(INKS.names, INKS.sigma_s[:, [2, 1, 0]].copy(), INKS.sigma_a[:, [2, 1, 0]].copy(), INKS.g)
    spec_factory = lambda v, threads, lighting: SpectralRenderer(v, table, threads, lighting)  # noqa: E731
    spec = PrintedRenderer(
        Volume.from_labels((VOX,) * 3, a, INKS), scene, (2 * VOX,) * 3, "slab", 2, None, None, factory=spec_factory
    )
    rgb = PrintedRenderer(Volume.from_labels((VOX,) * 3, a, order), scene, (2 * VOX,) * 3, "slab", 1)
    for labels in (a, b):
        spec.use(Volume.from_labels((VOX,) * 3, labels, INKS))
        rgb.use(Volume.from_labels((VOX,) * 3, labels, order))
        got, want = spec(4, 3), rgb(4, 3)
        assert got[0].shape == (len(scene), 3) and got[2] == want[2]
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
    assert all(r.volume.labels is a for r in spec.renderer._renderers)  # b is not held
    with pytest.raises(TypeError, match="unexpected"):
        PrintedRenderer(Volume.from_labels((VOX,) * 3, a, INKS), scene, (2 * VOX,) * 3, "slab", other=1)


@pytest.mark.parametrize("labels", [False, True])
def test_shared_renderer_is_the_per_group_one(labels):
    """``shared``: one renderer whose medium each group swaps in renders, and replays, bit for bit as one renderer
    per group, also after ``set_volume``; it refuses in-place medium updates."""
    table = smooth_table()  # 6 bands: two groups
    rng = np.random.default_rng(3)
    if labels:
        vols = [Volume.from_labels((VOX,) * 3, rng.integers(0, len(INKS), (5, 6, 7)).astype(np.uint8), INKS)]
        vols.append(Volume.from_labels((VOX,) * 3, rng.integers(0, len(INKS), (5, 6, 7)).astype(np.uint8), INKS))
    else:
        vols = [random_volume((5, 6, 7), seed=3), random_volume((5, 6, 7), seed=4)]
    tex = Texels.for_volume(vols[0])
    w = np.linspace(1.0, 2.0, len(table.band_groups()))
    each, one = (
        SpectralRenderer(vols[0], table, 2, plan=BandPlan.in_order(table, w)),
        SpectralRenderer(vols[0], table, 2, plan=BandPlan.in_order(table, w), shared=True),
    )
    assert len(one._renderers) == 1 and len(each._renderers) == len(table.band_groups())
    for vol in vols:
        each.set_volume(vol)
        one.set_volume(vol)
        one.volume = vols[0]  # as evaluation.printed does: the description only, not what is rendered
        for _ in range(2):  # twice: the shared renderer starts the second pass on the last group's medium
            a, b = each.render(tex, spp=3, seed=5), one.render(tex, spp=3, seed=5)
            np.testing.assert_array_equal(a.rgb, b.rgb)
            np.testing.assert_array_equal(a.var_mean, b.var_mean)
    if not labels:  # gradients are taken of mixtures
        adj = rng.normal(size=(len(tex), table.bands)).astype(np.float32)
        ga, gb = each.gradient(tex, adj, spp=2, seed=1), one.gradient(tex, adj, spp=2, seed=1)
        for x, y in zip(ga[:2], gb[:2]):
            np.testing.assert_array_equal(x, y)
    with pytest.raises(ParameterError, match="shared"):
        one.set_mixture(np.array([0]), np.full((1, len(INKS)), 0.25, np.float32))


def test_printed_renderer_shared_bands_swap_every_volume():
    """``PrintedRenderer`` with shared band renders of a 6-band table (two groups) renders each labels volume it is
    given, bit for bit as with one renderer per group: a second volume is not rendered with the first's medium."""
    from inkopt.evaluation.printed import PrintedRenderer

    rng = np.random.default_rng(9)
    a, b = (rng.integers(0, len(INKS), (6, 8, 10)).astype(np.uint8) for _ in range(2))
    scene = Texels.for_volume(Volume.from_labels((2 * VOX,) * 3, a[::2, ::2, ::2].copy(), INKS), [5])
    table = smooth_table()

    def printer(shared):
        make = lambda v, threads, lighting: SpectralRenderer(v, table, threads, lighting, shared=shared)  # noqa: E731
        return PrintedRenderer(Volume.from_labels((VOX,) * 3, a, INKS), scene, (2 * VOX,) * 3, "slab", 2, factory=make)

    one, each = printer(True), printer(False)
    got = []
    for labels in (a, b):
        one.use(Volume.from_labels((VOX,) * 3, labels, INKS))
        each.use(Volume.from_labels((VOX,) * 3, labels, INKS))
        x, y = one(4, 3), each(4, 3)
        np.testing.assert_array_equal(x[0], y[0])
        got.append(x[0])
    assert np.abs(got[0] - got[1]).max() > 0.01  # the two volumes differ
