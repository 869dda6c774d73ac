"""The renderer against references nobody here wrote (adding-doubling), exact limits, and finite differences.

Monte Carlo tolerances are multiples of the estimator's own standard error (and, for adding-doubling, plus the
difference between its 16- and 32-point quadratures as an estimate of its discretisation error).
"""

import numpy as np
import pytest
from helpers import replay_matches_fd

from inkopt.model import InkTable, Texels, Volume, mix
from inkopt.render import Renderer, render

VOX = 25.4 / 300


def homogeneous(a, b, d=1.0, nz=10, nxy=6, g=0.4, ior=1.5, boundary="periodic-xy"):
    mu_t = b / d
    s = np.full((nz, nxy, nxy, 3), mu_t * a, np.float32)
    return Volume.from_coefficients(
        (d / nz,) * 3, sigma_s=s, sigma_a=np.full_like(s, mu_t * (1 - a)), g=g, ior=ior, boundary=boundary
    )


@pytest.mark.parametrize("a,b", [(0.0, 1.0), (0.5, 0.5), (0.9, 2.0), (0.99, 4.0), (0.999, 8.0)])
def test_infinite_slab_matches_adding_doubling(a, b):
    """R + T at normal incidence (iadpython) equals a texel's radiance under uniform light, by reciprocity."""
    iad = pytest.importorskip("iadpython")
    vol = homogeneous(a, b)
    tex = Texels.for_volume(vol, ["top"])
    res = render(vol, tex, spp=1500, seed=3)
    r16, t16, _, _ = iad.Sample(a=a, b=b, g=0.4, d=1.0, n=1.5, quad_pts=16).rt()
    r32, t32, _, _ = iad.Sample(a=a, b=b, g=0.4, d=1.0, n=1.5, quad_pts=32).rt()
    expect = r32 + t32
    tol = 3 * res.mean_rgb_stderr + abs((r16 + t16) - expect)
    assert np.all(np.abs(res.mean_rgb - expect) < tol), (res.mean_rgb, expect, tol)


def test_white_furnace_and_energy_bound():
    """No absorption, index-matched boundary: every texel is exactly 1. With absorption nothing exceeds 1."""
    rng = np.random.default_rng(0)
    s = rng.uniform(1, 30, (5, 6, 7, 3)).astype(np.float32)
    vol = Volume.from_coefficients(voxel_mm=(0.05, 0.08, 0.03), sigma_s=s, sigma_a=np.zeros_like(s), ior=1.0)
    tex = Texels.for_volume(vol)
    assert len(tex) == 2 * (6 * 7 + 5 * 7 + 5 * 6)
    res = render(vol, tex, spp=64, seed=1)
    assert np.all(res.rgb == 1.0)
    vol2 = Volume.from_coefficients((0.05, 0.08, 0.03), s, sigma_a=rng.uniform(0, 2, s.shape).astype(np.float32))
    res2 = render(vol2, tex, spp=64, seed=1)
    assert np.all(res2.rgb <= 1.0) and np.all(res2.rgb >= 0.0)


def test_bit_identical_for_any_thread_count():
    rng = np.random.default_rng(1)
    inks = InkTable.parse("vero-cmykw")
    m = rng.dirichlet(np.ones(5), size=(6, 9, 11)).astype(np.float32)
    vol = Volume.from_mixture(voxel_mm=(VOX,) * 3, mixture=m, inks=inks)
    tex = Texels.for_volume(vol)
    a = Renderer(vol, threads=1).render(tex, spp=8, seed=7)
    b = Renderer(vol, threads=2).render(tex, spp=8, seed=7)
    assert np.array_equal(a.rgb, b.rgb) and a.events == b.events
    adj = rng.normal(size=(len(tex), 3)).astype(np.float32)
    ga1 = Renderer(vol, threads=1).gradient(tex, adj, spp=4, seed=9)
    ga2 = Renderer(vol, threads=2).gradient(tex, adj, spp=4, seed=9)
    assert np.array_equal(ga1[0], ga2[0]) and np.array_equal(ga1[1], ga2[1])


def test_labels_mixture_and_dense_forms_agree():
    """One ink per voxel given as labels, as a one-hot mixture and as dense coefficients renders identically."""
    rng = np.random.default_rng(2)
    inks = InkTable.parse("vero-cmykw")
    labels = rng.integers(0, 5, (4, 7, 9)).astype(np.uint8)
    onehot = np.eye(5, dtype=np.float32)[labels]
    s, a = mix(onehot, inks)
    vols = [
        Volume.from_labels(voxel_mm=(0.04, 0.08, 0.03), labels=labels, inks=inks),
        Volume.from_mixture(voxel_mm=(0.04, 0.08, 0.03), mixture=onehot, inks=inks),
        Volume.from_coefficients(voxel_mm=(0.04, 0.08, 0.03), sigma_s=s, sigma_a=a),
    ]
    tex = Texels.for_volume(vols[1])
    out = [render(v, tex, spp=4, seed=5).rgb for v in vols]
    # The label form goes through regular tracking (it has an inside mask), the others through delta tracking:
    # different samplers of the same medium, so compare within standard errors.
    r = render(vols[1], tex, spp=4, seed=5)
    np.testing.assert_array_equal(out[1], out[2])
    mean_diff = np.abs(out[0].mean(0) - out[1].mean(0))
    assert np.all(mean_diff < 4 * np.sqrt(2) * r.mean_rgb_stderr)


def test_mask_regular_tracking_matches_delta_tracking():
    """An inside mask that is all True takes the regular-tracking path; it must agree with delta tracking."""
    vol = homogeneous(0.95, 3.0, boundary="box", nxy=8)
    vol_m = Volume.from_coefficients(
        voxel_mm=vol.voxel_mm, sigma_s=vol.sigma_s, sigma_a=vol.sigma_a, inside=np.ones(vol.shape, bool)
    )
    tex = Texels.for_volume(vol, ["top"])
    a, b = render(vol, tex, spp=400, seed=1), render(vol_m, tex, spp=400, seed=2)
    se = np.hypot(a.mean_rgb_stderr, b.mean_rgb_stderr)
    assert np.all(np.abs(a.mean_rgb - b.mean_rgb) < 4 * se)


@pytest.mark.parametrize("masked", [False, True])
def test_gradient_matches_finite_differences(masked):
    """Both sigma_s and sigma_a, voxels at several depths, in a periodic slab with delta tracking in packets (no
    mask) and with the scalar regular-tracking walk (a mask)."""
    rng = np.random.default_rng(3)
    shape = (4, 3, 3)
    s = rng.uniform(2, 12, shape + (3,)).astype(np.float32)
    a = rng.uniform(0.2, 3, shape + (3,)).astype(np.float32)
    inside = np.ones(shape, bool) if masked else None
    vol = Volume.from_coefficients(voxel_mm=(0.1,) * 3, sigma_s=s, sigma_a=a, boundary="periodic-xy", inside=inside)
    replay_matches_fd(
        vol, [(3, 1, 1, 0, "sigma_s"), (3, 1, 1, 2, "sigma_a"), (2, 0, 1, 1, "sigma_s"), (1, 1, 2, 0, "sigma_a")]
    )


def test_gradient_matches_finite_differences_masked_object():
    """A masked object (a box with a notch, vacuum outside) as meshes are rendered: packets with delta tracking
    inside safe balls in the interior (safe distance 3 at the centre) and the general walk near the surface."""
    rng = np.random.default_rng(5)
    shape = (6, 6, 6)
    inside = np.ones(shape, bool)
    inside[3:, 2:4, :2] = False  # a notch in the top (light can leave and re-enter)
    s = np.where(inside[..., None], rng.uniform(4, 12, shape + (3,)), 0).astype(np.float32)
    a = np.where(inside[..., None], rng.uniform(0.2, 2, shape + (3,)), 0).astype(np.float32)
    vol = Volume.from_coefficients(voxel_mm=(0.1,) * 3, sigma_s=s, sigma_a=a, boundary="box", inside=inside)
    replay_matches_fd(
        vol,
        [(5, 3, 3, 0, "sigma_s"), (5, 1, 1, 1, "sigma_a"), (2, 2, 2, 2, "sigma_s"), (3, 3, 3, 0, "sigma_a")],
        spp=400,
    )


def test_li1_gradient_is_correlated_with_replay():
    """The biased one-pass L_i = 1 gradient only reaches sigma_a; it points the same way as the unbiased one
    (cosine similarity of the sigma_a gradients on a random mixture slab: measured ~0.9, asserted > 0.5)."""
    rng = np.random.default_rng(4)
    inks = InkTable.parse("vero-cmykw")
    m = rng.dirichlet(np.ones(5), size=(8, 10, 10)).astype(np.float32)
    vol = Volume.from_mixture(voxel_mm=(VOX,) * 3, mixture=m, inks=inks)
    tex = Texels.for_volume(vol, ["top"])
    adj = rng.uniform(0.5, 1.0, (len(tex), 3)).astype(np.float32)
    r = Renderer(vol)
    gs, ga, _ = r.gradient(tex, adj, spp=256, seed=1, method="replay")
    ls, la, _ = r.gradient(tex, adj, spp=256, seed=1, method="li1")
    assert np.all(ls == 0)
    cos = float(np.sum(ga * la) / np.sqrt(np.sum(ga * ga) * np.sum(la * la)))
    assert cos > 0.5, cos


def test_set_mixture_of_some_voxels_renders_like_a_fresh_renderer():
    """Renderer.set_mixture(index, rows) (the optimiser's per-iteration update of the free voxels) gives bit for
    bit the render and gradient of a renderer built for the volume with those voxels changed; the majorant follows
    values that go down; bad input is refused before anything changes."""
    rng = np.random.default_rng(9)
    inks = InkTable.parse("vero-cmykw")
    shape = (6, 7, 8)
    inside = np.ones(shape, bool)
    inside[4:, 2:5, :3] = False
    mix0 = rng.dirichlet(np.ones(5), size=shape).astype(np.float32)
    mix0[..., inks.index("white")] += 3.0  # a high majorant that the update removes
    mix0 /= mix0.sum(-1, keepdims=True)
    a = Volume.from_mixture(voxel_mm=(VOX,) * 3, mixture=mix0, inks=inks, inside=inside)
    index = np.sort(rng.choice(np.flatnonzero(inside), 150, replace=False))  # the optimiser's are inside
    rows = rng.dirichlet(np.ones(5), size=len(index)).astype(np.float32)
    mix1 = mix0.copy().reshape(-1, 5)
    mix1[index] = rows
    mix1 = mix1.reshape(mix0.shape)
    tex = Texels.for_volume(a)
    adj = rng.normal(size=(len(tex), 3)).astype(np.float32)
    reused = Renderer(a)
    reused.set_mixture(index, rows)
    fresh = Renderer(a.with_mixture(mix1))
    np.testing.assert_array_equal(reused.render(tex, spp=4, seed=3).rgb, fresh.render(tex, spp=4, seed=3).rgb)
    g1, g2 = reused.gradient(tex, adj, spp=3, seed=4), fresh.gradient(tex, adj, spp=3, seed=4)
    np.testing.assert_array_equal(g1[0], g2[0])
    np.testing.assert_array_equal(g1[1], g2[1])
    with pytest.raises(ValueError, match="index"):
        reused.set_mixture(np.array([mix0.size // 5], np.int64), rows[:1])
    with pytest.raises(ValueError, match="does not store"):  # the sparse medium keeps only the inside
        reused.set_mixture(np.flatnonzero(~inside)[:1], rows[:1])
    bad = rows[:2].copy()
    bad[1, 0] = np.nan
    with pytest.raises(ValueError):
        reused.set_mixture(index[:2], bad)
    np.testing.assert_array_equal(reused.render(tex, spp=4, seed=3).rgb, fresh.render(tex, spp=4, seed=3).rgb)


def test_masked_volumes_store_only_their_inside_and_render_as_the_dense_form():
    """A volume with an inside mask goes to the core as the inside voxels' coefficients only (4 bytes per grid
    voxel + 24 per inside voxel instead of 24 per grid voxel): renders and gradients are bit-identical to the dense
    form with vacuum outside, whatever the mixture outside the mask (the walks never read it)."""
    from inkopt import _core

    rng = np.random.default_rng(5)
    inks = InkTable.parse("vero-cmykw")
    shape = (7, 6, 9)
    inside = np.ones(shape, bool)
    inside[2:5, 1:4, 3:7] = False  # a cavity
    inside[:, 0, :2] = False  # a notch through the object
    mixture = rng.dirichlet(np.ones(5), size=shape).astype(np.float32)
    vol = Volume.from_mixture(voxel_mm=(VOX,) * 3, mixture=mixture, inks=inks, inside=inside)
    n, k = inside.size, int(inside.sum())
    assert vol.render_bytes() == 4 * n + 24 * k + 2 * n
    s, a = vol.coefficients()
    s, a = (np.where(inside[..., None], x, 0).astype(np.float32) for x in (s, a))
    dense = _core.Scene(shape, (VOX,) * 3, _core.Medium.dense(s, a), inside=inside.astype(np.uint8))
    tex = Texels.for_volume(vol)
    adj = rng.normal(size=(len(tex), 3)).astype(np.float32)
    core_tex = _core.Texels(tex.voxel, tex.face, tex.normal)
    want = dense.render(core_tex, spp=4, seed=3, first_texel=0, include_specular=True)
    for outside_mix in (mixture, np.zeros_like(mixture)):  # what lies outside the mask does not matter
        r = Renderer(vol.with_mixture(np.where(inside[..., None], mixture, outside_mix)))
        got = r.render(tex, spp=4, seed=3)
        np.testing.assert_array_equal(got.rgb, want[0])
        np.testing.assert_array_equal(got.var_mean, want[1])
    dense.zero_grad(float(np.abs(adj).max()), None)
    dense.backward(core_tex, adj, spp=3, seed=4, first_texel=0, include_specular=True, method="replay")
    gs, ga, _ = r.gradient(tex, adj, spp=3, seed=4)
    for g, w in zip((gs, ga), dense.take_grad()):
        np.testing.assert_array_equal(g, w)
    assert np.abs(ga).sum() > 0


@pytest.mark.parametrize("form", ["dense", "mixture", "labels"])
def test_coefficients_at_matches_the_dense_coefficients(form):
    rng = np.random.default_rng(6)
    inks = InkTable.parse("vero-cmykw")
    shape = (3, 4, 5)
    mixture = rng.dirichlet(np.ones(5), size=shape).astype(np.float32)
    vol = Volume.from_mixture(voxel_mm=(VOX,) * 3, mixture=mixture, inks=inks)
    if form == "dense":
        vol = Volume.from_coefficients((VOX,) * 3, sigma_s=vol.coefficients()[0], sigma_a=vol.coefficients()[1])
    elif form == "labels":
        labels = rng.integers(0, 5, size=shape).astype(np.uint8)
        labels[0, 0, :3] = 255
        vol = Volume.from_labels(voxel_mm=(VOX,) * 3, labels=labels, inks=inks)
    index = np.sort(rng.choice(60, 25, replace=False))
    s, a = vol.coefficients_at(index, chunk=7)
    ds, da = vol.coefficients()
    np.testing.assert_array_equal(s, ds.reshape(-1, 3)[index])
    np.testing.assert_array_equal(a, da.reshape(-1, 3)[index])


@pytest.mark.parametrize("masked", [False, True])
def test_set_volume_renders_like_a_fresh_renderer(masked):
    """One renderer for a whole optimisation: replacing the medium gives bit-identically the render and gradient
    of a renderer built for the new volume (geometry, safe distances and thread pool are kept)."""
    from inkopt import _core

    rng = np.random.default_rng(8)
    inks = InkTable.parse("vero-cmykw")
    shape = (6, 7, 8)
    inside = None
    if masked:
        inside = np.ones(shape, bool)
        inside[4:, 2:5, :3] = False
    a = Volume.from_mixture(
        (VOX,) * 3, mixture=rng.dirichlet(np.ones(5), size=shape).astype(np.float32), inks=inks, inside=inside
    )
    b = a.with_mixture(rng.dirichlet(np.ones(5), size=shape).astype(np.float32))
    tex = Texels.for_volume(a)
    adj = rng.normal(size=(len(tex), 3)).astype(np.float32)
    reused = Renderer(a)
    reused.render(tex, spp=2, seed=0)
    reused.set_volume(b)
    fresh = Renderer(b)
    r1, r2 = reused.render(tex, spp=4, seed=3), fresh.render(tex, spp=4, seed=3)
    np.testing.assert_array_equal(r1.rgb, r2.rgb)
    g1, g2 = reused.gradient(tex, adj, spp=3, seed=4), fresh.gradient(tex, adj, spp=3, seed=4)
    np.testing.assert_array_equal(g1[0], g2[0])
    np.testing.assert_array_equal(g1[1], g2[1])
    with pytest.raises(ValueError, match="shape"):
        reused.set_volume(Volume.from_mixture((VOX,) * 3, mixture=np.ones((2, 2, 2, 5), np.float32) / 5, inks=inks))
    # A dense medium is overwritten in place; bad coefficients are refused before anything is written.
    s, a_ = b.coefficients()
    bad = np.ascontiguousarray(s, np.float32).copy()
    bad[1, 2, 3, 1] = -1.0
    with pytest.raises(ValueError, match="voxel .* channel 1 are negative"):
        reused._scene.set_medium(_core.Medium.dense(bad, np.ascontiguousarray(a_, np.float32)))
    np.testing.assert_array_equal(reused.render(tex, spp=4, seed=3).rgb, r2.rgb)


def test_gradient_slots_from_a_voxel_list_match_the_slot_map():
    """grad_index as the free voxels' flat indices (what the optimiser passes: no grid-sized array) gives the same
    per-slot gradients as the equivalent (z, y, x) slot map, bit for bit, in a fresh and in a reused buffer;
    a list that is not strictly increasing or leaves the grid is refused in one line."""
    rng = np.random.default_rng(12)
    inks = InkTable.parse("vero-cmykw")
    shape = (5, 6, 7)
    inside = np.ones(shape, bool)
    inside[3:, :2, :2] = False
    vol = Volume.from_mixture(
        (VOX,) * 3, mixture=rng.dirichlet(np.ones(5), size=shape).astype(np.float32), inks=inks, inside=inside
    )
    tex = Texels.for_volume(vol)
    adj = rng.normal(size=(len(tex), 3)).astype(np.float32)
    voxels = np.sort(rng.choice(np.flatnonzero(inside), 90, replace=False))
    slot_map = np.full(shape, -1, np.int32)
    slot_map.reshape(-1)[voxels] = np.arange(len(voxels))
    r = Renderer(vol)
    want = r.gradient(tex, adj, spp=3, seed=4, grad_index=slot_map)
    for _ in range(2):  # a fresh buffer, then the same one zeroed in place
        got = r.gradient(tex, adj, spp=3, seed=4, grad_index=voxels)
        assert got[0].shape == (len(voxels), 3)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
    assert np.abs(want[1]).sum() > 0
    other = voxels[1:]  # other slots: a new buffer, not the old one reused
    np.testing.assert_array_equal(
        r.gradient(tex, adj, spp=3, seed=4, grad_index=other)[1],
        r.gradient(tex, adj, spp=3, seed=4, grad_index=np.where(slot_map > 0, slot_map - 1, -1).astype(np.int32))[1],
    )
    for bad, msg in ((voxels[::-1], "strictly increasing"), (np.array([vol.inside.size]), "outside the grid")):
        with pytest.raises(ValueError, match=msg):
            r.gradient(tex, adj, spp=1, seed=4, grad_index=bad)


def test_set_mixture_on_a_label_volume_switches_to_coefficients():
    """A renderer of a masked label volume (a big object's 1-byte base) given mixtures for some voxels renders
    as a fresh renderer of the mixture volume with the labels' inks elsewhere, bit for bit."""
    rng = np.random.default_rng(13)
    inks = InkTable.parse("vero-cmykw")
    shape = (5, 6, 7)
    inside = np.ones(shape, bool)
    inside[3:, :3, :2] = False
    labels = np.where(inside, rng.integers(0, 5, size=shape), 255).astype(np.uint8)
    base = Volume.from_labels(voxel_mm=(VOX,) * 3, labels=labels, inks=inks, inside=inside)
    index = np.sort(rng.choice(np.flatnonzero(inside), 60, replace=False))
    rows = rng.dirichlet(np.ones(5), size=len(index)).astype(np.float32)
    full = np.eye(5, dtype=np.float32)[np.where(inside, labels, 0)] * inside[..., None]
    full.reshape(-1, 5)[index] = rows
    tex = Texels.for_volume(base)
    r = Renderer(base)
    r.set_mixture(index, rows)
    np.testing.assert_array_equal(
        r.render(tex, spp=4, seed=2).rgb, Renderer(base.with_mixture(full)).render(tex, spp=4, seed=2).rgb
    )
