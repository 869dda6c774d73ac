"""The step's spatial preconditioner (optim/smooth.py): checked against scipy.ndimage's convolution, its
conservation and spectral properties, its guide; in the loop: test_optimize.py (what it is applied to, resume,
checkpoint keys)."""

import numpy as np
import pytest
from scipy import ndimage

from inkopt.optim import OptimizeConfig
from inkopt.optim.smooth import ALPHA, GradientSmoother, diffusion_steps, nearest_texels, texel_guide


def _free_grid(mask):
    """(grid shape, the free voxels' increasing linear indices), as GradientSmoother takes them."""
    return mask.shape, np.flatnonzero(mask)


def test_matches_a_dense_convolution_on_a_full_box():
    """Every voxel free: k steps equal k convolutions with the 7-point stencil (centre 1 - 6a, faces a), with
    scipy's 'nearest' border (a missing neighbour contributes g_i - g_i = 0: no flux through the border)."""
    rng = np.random.default_rng(0)
    shape = (5, 7, 6)
    g = rng.normal(size=shape + (3,)).astype(np.float32)
    sm = GradientSmoother(*_free_grid(np.ones(shape, bool)), sigma=1.0)
    assert sm.steps == diffusion_steps(1.0) == 4
    out = sm(g.reshape(-1, 3)).reshape(g.shape)
    k = np.zeros((3, 3, 3))
    k[1, 1, 1] = 1 - 6 * ALPHA
    for a in range(3):
        for s in (0, 2):
            idx = [1, 1, 1]
            idx[a] = s
            k[tuple(idx)] = ALPHA
    ref = g.astype(np.float64)
    for _ in range(sm.steps):
        ref = np.stack([ndimage.convolve(ref[..., c], k, mode="nearest") for c in range(3)], -1)
    np.testing.assert_allclose(out, ref, atol=1e-5)


def test_conserves_each_channel_sum_and_keeps_constants_on_an_irregular_set():
    """No flux leaves the free set (Neumann boundary): the sum over free voxels is kept (float32 rounding only),
    a constant field is a fixed point, and the input is not modified."""
    rng = np.random.default_rng(1)
    mask = rng.random((8, 9, 10)) < 0.6
    gi = _free_grid(mask)
    g = rng.normal(size=(mask.sum(), 4)).astype(np.float32)
    g0 = g.copy()
    out = GradientSmoother(*gi, sigma=1.5)(g)
    np.testing.assert_array_equal(g, g0)
    np.testing.assert_allclose(out.sum(0), g.sum(0), atol=1e-3)
    const = np.full_like(g, 0.25)
    np.testing.assert_allclose(GradientSmoother(*gi, sigma=1.5)(const), const, rtol=1e-6)
    # never amplifies: an even number of steps has eigenvalues in [0, 1]
    assert np.linalg.norm(out) <= np.linalg.norm(g)


def test_kernel_width_and_voxel_scale_damping():
    """A unit impulse in the middle of a large box spreads with variance 2 a k per axis (the explicit scheme's
    exact moment), >= sigma²; the checkerboard (the highest frequency: pure voxel-to-voxel noise) is damped by
    exactly (1 - 12 a)^k (positive: k is even); the smooth lowest mode barely changes."""
    n = 25
    gi = _free_grid(np.ones((n, n, n), bool))
    sm = GradientSmoother(*gi, sigma=1.0)
    d = np.zeros((n, n, n, 1), np.float32)
    d[n // 2, n // 2, n // 2] = 1
    out = sm(d.reshape(-1, 1)).reshape(n, n, n)
    c = np.arange(n) - n // 2
    var_x = float((out.sum((0, 1)) * c**2).sum())
    assert var_x == pytest.approx(2 * ALPHA * sm.steps, rel=1e-5)
    assert var_x >= 1.0
    z, y, x = np.indices((n, n, n))
    cb = ((-1.0) ** (z + y + x)).astype(np.float32).reshape(-1, 1)
    inner = (slice(sm.steps, n - sm.steps),) * 3  # away from the border, where the stencil is complete
    ratio = sm(cb).reshape(n, n, n)[inner] / cb.reshape(n, n, n)[inner]
    np.testing.assert_allclose(ratio, (1 - 12 * ALPHA) ** sm.steps, atol=1e-5)
    low = np.cos(np.pi * (x + 0.5) / n).astype(np.float32).reshape(-1, 1)  # the lowest Neumann mode along x
    lam = (1 - 2 * ALPHA * (1 - np.cos(np.pi / n))) ** sm.steps
    np.testing.assert_allclose(sm(low), lam * low, atol=1e-5)
    assert lam > 0.97


def test_settings_are_checked():
    with pytest.raises(ValueError, match="smoothing"):
        OptimizeConfig(smooth=-1).validate()
    with pytest.raises(ValueError, match="smooth_edge"):
        OptimizeConfig(smooth_edge=-1).validate()
    with pytest.raises(ValueError, match="smoothing"):
        GradientSmoother((2, 2, 2), np.arange(8), 0.0)
    assert diffusion_steps(0) == 0 and diffusion_steps(0.5) == 2 and diffusion_steps(0.7) == 2
    assert diffusion_steps(1.5) == 10


def test_guide_stops_the_flux_at_target_edges():
    """Two halves of a box with target colours 100 ΔE76 apart: with edge 10 (weight e^-100) nothing crosses
    between them (each half keeps its sum), with a uniform guide the result is the unguided one."""
    rng = np.random.default_rng(2)
    shape = (4, 6, 8)
    gi = _free_grid(np.ones(shape, bool))
    g = rng.normal(size=(np.prod(shape), 2)).astype(np.float32)
    left = (np.indices(shape)[2] < 4).reshape(-1)
    guide = np.where(left[:, None], [[0, 0, 0]], [[100, 0, 0]]).astype(np.float32)
    out = GradientSmoother(*gi, 1.0, guide, edge=10.0)(g)
    for half in (left, ~left):
        np.testing.assert_allclose(out[half].sum(0), g[half].sum(0), atol=1e-4)
    assert not np.allclose(out[left], g[left])
    same = GradientSmoother(*gi, 1.0, np.zeros_like(guide), edge=10.0)(g)
    np.testing.assert_allclose(same, GradientSmoother(*gi, 1.0)(g), atol=1e-6)
    # each voxel's guide is its nearest texel's target: texels on the top face (z = 4) of a 2-layer free set
    mask = np.zeros(shape, bool)
    mask[2:] = True
    y, x = np.mgrid[:6, :8]
    pos = np.stack([x.ravel() + 0.5, y.ravel() + 0.5, np.full(48, 4.0)], 1)
    lab = rng.normal(size=(48, 3)).astype(np.float32)
    nearest, dist = nearest_texels(shape, np.flatnonzero(mask), pos, chunk=7)
    got = texel_guide(lab, nearest, dist, depth_de=30.0).dense().reshape(2, 48, 4)
    np.testing.assert_array_equal(got[..., :3], np.stack([lab, lab]))
    np.testing.assert_allclose(got[..., 3], [[45.0] * 48, [15.0] * 48])  # 1.5 and 0.5 voxels below the face
    near, d = nearest_texels(shape, np.flatnonzero(mask), pos, max_dist=1.0)  # only the top layer is that close
    np.testing.assert_array_equal(near.reshape(2, 48), np.stack([np.full(48, -1), nearest.reshape(2, 48)[1]]))
    assert np.all(np.isinf(d.reshape(2, 48)[0])) and np.array_equal(d.reshape(2, 48)[1], dist.reshape(2, 48)[1])
    with pytest.raises(ValueError, match="edge"):
        GradientSmoother(*gi, 1.0, guide, edge=0.0)
    with pytest.raises(ValueError, match="guide has"):
        GradientSmoother(*gi, 1.0, guide[:5], edge=1.0)


def test_a_subset_of_rows_is_smoothed_alone():
    """With ``rows``, only those free voxels are smoothed, as if they were the whole free set (no flux to the
    others), and the other rows are kept exactly; ``apply`` does the same in place."""
    rng = np.random.default_rng(5)
    shape = (3, 6, 8)
    index = np.arange(np.prod(shape))
    sub = (np.indices(shape)[2] < 5).reshape(-1)  # the rows to smooth: x < 5
    rows = np.flatnonzero(sub)
    g = rng.normal(size=(len(index), 3)).astype(np.float32)
    guide = rng.normal(size=(len(rows), 4)).astype(np.float32)
    out = GradientSmoother(shape, index, 1.0, guide, 4.0, rows=rows)(g)
    np.testing.assert_array_equal(out[~sub], g[~sub])
    alone = GradientSmoother(shape, index[rows], 1.0, guide, 4.0)(g[rows])
    np.testing.assert_array_equal(out[rows], alone)
    assert not np.allclose(out[rows], g[rows])
    inplace = g.copy()
    assert GradientSmoother(shape, index, 1.0, guide, 4.0, rows=rows).apply(inplace) is inplace
    np.testing.assert_array_equal(inplace, out)
    with pytest.raises(ValueError, match="increasing"):
        GradientSmoother(shape, index[::-1].copy(), 1.0)(g)


def test_depth_guide_lets_neighbours_under_a_sloped_surface_exchange():
    """Mesh texels sit at surface-voxel centres, so on a sloped surface grid neighbours side by side differ by a
    fraction of a voxel in their distance to the nearest texel. The default depth weight (DEPTH_DE) must leave
    them coupled: under a 26.6° slope (z rises 0.5 voxel per x) at least 90 % of the x-neighbour pairs keep a
    guide weight above 0.1 at the default edge of 4 ΔE76, as all do under an axis-aligned face. A weight of
    30 ΔE76 per voxel keeps 10 % (the smoothing hardly acts on Spot's curved surfaces)."""
    from inkopt.optim.smooth import MAX_DEPTH

    edge = OptimizeConfig().smooth_edge

    def coupled_share(slope: float, **kw) -> float:
        z, y, x = np.mgrid[:40, :8, :40]
        inside = (z + 0.5) < slope * (x + 0.5) + 5
        above = np.concatenate([inside[1:], np.zeros((1, 8, 40), bool)])
        sz, sy, sx = np.nonzero(inside & ~above)  # the top surface's voxels: the texels
        idx = np.flatnonzero(inside.ravel())
        near, dist = nearest_texels(inside.shape, idx, np.stack([sx, sy, sz], 1) + 0.5, MAX_DEPTH)
        ok = near >= 0
        depth = np.full(inside.size, np.nan)
        depth[idx[ok]] = texel_guide(np.zeros((len(sx), 3), np.float32), near[ok], dist[ok], **kw).extra
        d = np.diff(depth.reshape(inside.shape), axis=2).ravel()
        d = d[np.isfinite(d)]
        return float(np.mean(np.exp(-((d / edge) ** 2)) > 0.1))

    assert coupled_share(0.0) == 1.0
    assert coupled_share(0.5) >= 0.9
    assert coupled_share(0.5, depth_de=30.0) < 0.5
