"""Tests of inkopt.loss against scikit-image, finite differences and independent computations."""

import numpy as np
import pytest
import scipy.sparse as sp
from helpers import central_differences
from skimage import color as skcolor
from skimage.color.colorconv import _illuminants
from skimage.metrics import structural_similarity

from inkopt import color, loss, neighbourhood
from inkopt.model import Texels

SKI_WHITE = np.array(_illuminants["D65"]["2"])


def _rng():
    return np.random.default_rng(1234)


# ----------------------------------------------------------------------------- flat-face checks
def _flat_face(ny=40, nx=50):
    yy, xx = np.mgrid[0:ny, 0:nx]
    pos = np.stack([xx.ravel() + 0.5, yy.ravel() + 0.5, np.full(xx.size, 7.0)], 1)
    return pos, (ny, nx)


def _smooth_image(shape, rng):
    from scipy.ndimage import gaussian_filter

    img = gaussian_filter(rng.uniform(0, 1, shape + (3,)), (2, 2, 0))
    return np.clip((img - img.min()) / (img.max() - img.min()), 0, 1)


def test_ssim_matches_skimage_on_flat_face_interior():
    rng = _rng()
    pos, shape = _flat_face()
    target = _smooth_image(shape, rng)
    pred = np.clip(target + rng.normal(0, 0.08, target.shape), 0, 1)
    lf = loss.TexelLoss(target.reshape(-1, 3), pos, gamma=(0, 1, 0), sigma=1.5)
    assert lf.radius == 5
    smap = lf.ssim_map(pred.reshape(-1, 3)).reshape(shape + (3,))
    r = lf.radius
    tn = color.normalise_lab(color.linear_to_lab(target))
    cn = color.normalise_lab(color.linear_to_lab(pred))
    for c in range(3):
        _, full = structural_similarity(
            cn[..., c],
            tn[..., c],
            gaussian_weights=True,
            sigma=1.5,
            use_sample_covariance=False,
            data_range=1.0,
            full=True,
        )
        np.testing.assert_allclose(smap[r:-r, r:-r, c], full[r:-r, r:-r], atol=1e-9)
        assert abs(smap[r:-r, r:-r, c].mean() - full[r:-r, r:-r].mean()) < 1e-6
    np.testing.assert_allclose(lf.ssim_mean(pred.reshape(-1, 3)), smap.mean())
    np.testing.assert_allclose(lf(pred.reshape(-1, 3)).e2, 1 - smap.mean(), atol=1e-12)


def test_sobel_of_ramp_is_constant_on_flat_face():
    pos, shape = _flat_face(20, 30)
    s = neighbourhood.sobel_operators(pos)
    n = len(pos)
    ramp = 0.3 * pos[:, 0] - 2.0
    sx, sy, sz = (s @ ramp).reshape(3, *shape)
    # in-plane 3D Sobel on a face = 2 x the 2D Sobel: 2 * 4 * (0.3 * 2) = 4.8 per unit slope
    np.testing.assert_allclose(sx[1:-1, 1:-1], 4.8, atol=1e-12)
    np.testing.assert_allclose(sy[1:-1, 1:-1], 0.0, atol=1e-12)
    np.testing.assert_allclose(sz, 0.0, atol=1e-12)
    np.testing.assert_allclose(s @ np.ones(n), 0.0, atol=1e-12)  # replicate border: constants have no edges
    assert np.all(np.abs(sx[0]) > 0) and np.all(np.abs(sx[:, 0]) > 0)


def test_gaussian_window_rows_and_interior():
    pos, shape = _flat_face(30, 30)
    k, wsum, r = neighbourhood.gaussian_window(pos, 1.5)
    g1 = np.exp(-(np.arange(-5, 6) ** 2) / (2 * 1.5**2))
    centre = 15 * 30 + 15
    np.testing.assert_allclose(wsum[centre], g1.sum() ** 2)
    np.testing.assert_allclose((k.toarray() - k.toarray().T), 0.0)
    row = (k.toarray()[centre] / wsum[centre]).reshape(shape)[10:21, 10:21]
    np.testing.assert_allclose(row, np.outer(g1, g1) / g1.sum() ** 2)
    assert wsum[0] < wsum[centre]  # corner texels see less of the window
    # skimage's window for Gaussian SSIM: win_size = 2 * int(3.5 * sigma + 0.5) + 1
    for sig in (1.0, 1.5, 2.0, 0.5):
        assert neighbourhood.gaussian_window(pos[:10], sig)[2] == int(3.5 * sig + 0.5)
    assert neighbourhood.gaussian_window(pos[:10], 1.0)[2] == 4


def test_gaussian_window_in_chunks_equals_the_dense_definition(monkeypatch):
    """Built a few rows at a time (chunks that end mid-face, a box's edges and corners, a repeated texel
    position), K equals the dense definition: exp(-d^2 / 2 sigma^2) wherever the Chebyshev distance is <= the
    radius, columns sorted in each row."""
    pos = Texels.box_faces((9, 7, 8)).pos_vox
    pos = np.concatenate([pos, pos[:3]])  # texels at the same place are each other's neighbours
    monkeypatch.setattr(neighbourhood, "WINDOW_CHUNK_ROWS", 37)
    k, wsum, r = neighbourhood.gaussian_window(pos, 1.5)
    diff = pos[:, None, :] - pos[None, :, :]
    want = np.where(np.abs(diff).max(-1) <= r + 1e-6, np.exp(-(diff**2).sum(-1) / (2 * 1.5**2)), 0.0)
    np.testing.assert_allclose(k.toarray(), want, rtol=1e-14, atol=0)
    assert k.tocsr().has_sorted_indices and k.nnz == np.count_nonzero(want)
    np.testing.assert_allclose(wsum, want.sum(1), rtol=1e-12)


@pytest.mark.parametrize("step, dtype", [(1.0, np.uint8), (1 / 16, np.uint16)])
def test_gaussian_window_codes_widen_as_the_weights_table_grows(monkeypatch, step, dtype):
    """The codes start as uint8 and widen when a later chunk brings more distinct weights (uint16: positions on a
    1/16-voxel lattice): K equals the dense definition in both cases."""
    rng = np.random.default_rng(5)
    pos = np.round(rng.uniform(0, 12, (400, 3)) / step) * step
    monkeypatch.setattr(neighbourhood, "WINDOW_CHUNK_ROWS", 50)
    k, _, r = neighbourhood.gaussian_window(pos, 1.5)
    assert k.codes.dtype == dtype
    diff = pos[:, None, :] - pos[None, :, :]
    want = np.where(np.abs(diff).max(-1) <= r + 1e-6, np.exp(-(diff**2).sum(-1) / (2 * 1.5**2)), 0.0)
    np.testing.assert_allclose(k.toarray(), want, rtol=1e-14, atol=0)


# ----------------------------------------------------------------------------- the loss
@pytest.mark.parametrize("sigma", [1.5, 1.0])
def test_loss_gradient_finite_differences_box(sigma):
    rng = _rng()
    pos = Texels.box_faces((4, 5, 6)).pos_vox
    n = len(pos)
    target = rng.uniform(0.05, 0.9, (n, 3))
    pred = np.clip(target + rng.normal(0, 0.1, (n, 3)), 0.03, 0.95)
    gamma = rng.uniform(0.5, 3.0, 3)
    lf = loss.TexelLoss(target, pos, gamma=gamma, sigma=sigma)
    assert lf.S.nnz > 0
    res = lf(pred)
    h = 1e-6
    fd = np.zeros_like(pred)
    for i in range(n):
        for c in range(3):
            p = pred.copy()
            p[i, c] += h
            up = lf(p).value
            p[i, c] -= 2 * h
            fd[i, c] = (up - lf(p).value) / (2 * h)
    err = np.linalg.norm(res.grad - fd) / np.linalg.norm(fd)
    assert err < 1e-4, err
    # each term's gradient separately (a wrong term cannot hide behind a large E1)
    for t in range(3):
        gam = np.zeros(3)
        gam[t] = 1.0
        lt = loss.TexelLoss(target, pos, gamma=gam, sigma=sigma)
        g = lt(pred).grad
        k = rng.integers(n, size=6)
        for i in k:
            for c in range(3):
                p = pred.copy()
                p[i, c] += h
                up = lt(p).value
                p[i, c] -= 2 * h
                f = (up - lt(p).value) / (2 * h)
                assert abs(g[i, c] - f) <= 1e-4 * np.abs(g).max() + 1e-9, (t, i, c, g[i, c], f)


def test_loss_values():
    rng = _rng()
    pos = Texels.box_faces((4, 5, 6)).pos_vox
    n = len(pos)
    target = rng.uniform(0, 1, (n, 3))
    pred = rng.uniform(0, 1, (n, 3))
    lf = loss.TexelLoss(target, pos, gamma=(1.0, 4.0, 2.0))
    res = lf(pred)
    lab_p = skcolor.xyz2lab(color.linear_to_xyz(pred) * SKI_WHITE / color.WHITE_XYZ)
    lab_t = skcolor.xyz2lab(color.linear_to_xyz(target) * SKI_WHITE / color.WHITE_XYZ)
    np.testing.assert_allclose(res.e1, np.mean(skcolor.deltaE_cie76(lab_p, lab_t) ** 2), rtol=1e-9)
    np.testing.assert_allclose(res.lab, lab_p, atol=1e-6)
    np.testing.assert_allclose(res.value, (loss.E1_WEIGHT_SCALE * res.e1 + 4 * res.e2 + 2 * res.e3) / 7)
    assert 0 <= res.e2 <= 2 and res.e3 > 0
    # E3 computed independently from the stacked Sobel matrix
    d = lf.S.toarray() @ (color.normalise_lab(lab_p) - color.normalise_lab(lab_t))
    np.testing.assert_allclose(res.e3, 100 / 3 * np.sum(d**2) / (n * 4 * 32), rtol=1e-9)
    same = lf(target)
    assert abs(same.value) < 1e-12 and abs(same.e2) < 1e-12 and same.e1 == 0 and same.e3 < 1e-24
    np.testing.assert_allclose(same.grad, 0.0, atol=1e-12)
    np.testing.assert_allclose(lf.ssim_mean(target), 1.0)


@pytest.mark.parametrize("combine", ["mean", "worst"])
def test_a_call_without_gradient_gives_the_same_value_and_terms(combine):
    """``gradient=False`` (the figures): value, terms and CIELAB bit-identical to the full call, with the noise
    correction and under two colour maps, and no gradient."""
    rng = _rng()
    pos = Texels.box_faces((4, 5, 6)).pos_vox
    target, pred = rng.uniform(0, 1, (2, len(pos), 3))
    var = rng.uniform(0, 1e-3, pred.shape)
    lf = loss.TexelLoss(target, pos, gamma=(1.0, 4.0, 2.0), colours=(color.RGB, color.RGB), combine=combine)
    full, bare = lf(pred, var), lf(pred, var, gradient=False)
    assert bare.grad is None and full.grad is not None
    assert (bare.value, bare.e1, bare.e2, bare.e3) == (full.value, full.e1, full.e2, full.e3)
    assert bare.lab.tobytes() == full.lab.tobytes()


@pytest.mark.parametrize("gamma", [(1.0, 0.0, 0.0), (1.0, 4.0, 0.0), (0.0, 0.0, 2.0)])
def test_training_call_skips_only_unweighted_terms(gamma):
    """all_terms=False (the optimiser's steps) gives the same value and gradient, bit for bit; a term of weight 0
    is NaN, a weighted one equals the full call's."""
    rng = _rng()
    pos = Texels.box_faces((4, 5, 6)).pos_vox
    target, pred = rng.uniform(0, 1, (len(pos), 3)), rng.uniform(0, 1, (len(pos), 3))
    var = rng.uniform(0, 1e-4, pred.shape)
    lf = loss.TexelLoss(target, pos, gamma=gamma)
    full, part = lf(pred, var), lf(pred, var, all_terms=False)
    assert part.value == full.value and part.e1 == full.e1
    np.testing.assert_array_equal(part.grad, full.grad)
    for g, name in zip(gamma[1:], ("e2", "e3")):
        got = getattr(part, name)
        assert (got == getattr(full, name)) if g > 0 else np.isnan(got)
    with pytest.raises(ValueError, match="pred_var"):
        lf(pred, -var, all_terms=False)


def test_released_operators_are_built_again_equal():
    """release_operators frees the window and Sobel operators; the next full call builds them again and gives
    the same value, terms and gradient bit for bit; the kept flat mask and window sums are unchanged."""
    rng = _rng()
    pos = Texels.box_faces((5, 4, 6)).pos_vox
    target, pred = rng.uniform(0, 1, (len(pos), 3)), rng.uniform(0, 1, (len(pos), 3))
    var = rng.uniform(0, 1e-4, pred.shape)
    lf = loss.TexelLoss(target, pos, gamma=(1.0, 2.0, 3.0))
    before, flat, wsum = lf(pred, var), lf.flat.copy(), lf.wsum.copy()
    lf.release_operators()
    assert not lf._ops.held
    after = lf(pred, var)
    assert (after.value, after.e1, after.e2, after.e3) == (before.value, before.e1, before.e2, before.e3)
    np.testing.assert_array_equal(after.grad, before.grad)
    np.testing.assert_array_equal(lf.flat, flat)
    np.testing.assert_array_equal(lf.wsum, wsum)
    assert lf.needs_operators and not loss.TexelLoss(target, pos).needs_operators


def test_box_edges_and_bad_input():
    pos = Texels.box_faces((4, 5, 6)).pos_vox
    n = len(pos)
    s = neighbourhood.sobel_operators(pos)
    # no Sobel link across a box edge (those texels are 0.5 apart per axis)
    rows, cols = (s != 0).nonzero()
    off = pos[cols] - pos[rows % n]
    assert np.all(np.abs(off - np.rint(off)) < 1e-9)
    with pytest.raises(ValueError):
        loss.TexelLoss(np.zeros((n, 3)), pos[:-1])
    with pytest.raises(ValueError):
        loss.TexelLoss(np.zeros((n, 3)), pos, gamma=(0, 0, 0))
    with pytest.raises(ValueError):
        loss.TexelLoss(np.zeros((n, 3)), pos)(np.zeros((n - 1, 3)))


def _face(nx=40, ny=30):
    return Texels.box_faces((2, ny, nx), ["top"]).pos_vox


def test_noise_corrected_ssim_is_unbiased():
    """SSIM of a noisy prediction is biased low (noise inflates its local variance); given the noise variance it
    estimates the noise-free SSIM. Gaussian noise of known variance on a structured face; the mean over 40 noise
    draws must be within 4 standard errors of the clean value, while the uncorrected value is far below it."""
    rng = np.random.default_rng(0)
    pos = _face()
    x = pos[:, 0]
    clean = np.stack([0.2 + 0.15 * np.sin(x / 3), 0.3 + 0.1 * np.cos(x / 5), 0.25 + 0.05 * (x % 4)], 1)
    target = np.clip(clean + rng.normal(0, 0.03, clean.shape), 0.01, 1)
    lf = loss.TexelLoss(target, pos, gamma=(1, 1, 0))
    s_clean = lf.ssim_mean(clean)
    var = np.full_like(clean, 0.02**2)
    corr, unc = [], []
    for _ in range(40):
        noisy = clean + rng.normal(0, 0.02, clean.shape)
        corr.append(lf.ssim_mean(noisy, var))
        unc.append(lf.ssim_mean(noisy))
    se = np.std(corr, ddof=1) / np.sqrt(len(corr))
    assert abs(np.mean(corr) - s_clean) < 4 * se + 2e-3, (np.mean(corr), s_clean, se)
    assert np.mean(unc) < s_clean - 10 * se - 0.01, (np.mean(unc), s_clean)


def test_noise_corrected_loss_gradient():
    rng = np.random.default_rng(1)
    pos = _face(8, 6)
    target = rng.uniform(0.05, 0.9, (len(pos), 3))
    pred = rng.uniform(0.05, 0.9, (len(pos), 3))
    var = rng.uniform(0, 1e-3, pred.shape)
    lf = loss.TexelLoss(target, pos, gamma=(0.5, 2.0, 0.5))
    g = lf(pred, var).grad
    h = 1e-6
    num = np.zeros_like(pred)
    for i in np.ndindex(pred.shape):
        e = np.zeros_like(pred)
        e[i] = h
        # The noise correction is a constant for the gradient: keep it at pred's value.
        noise = lf._noise(pred, var)
        f = lambda p, noise=noise: lf._value_with_noise(p, noise)
        num[i] = (f(pred + e) - f(pred - e)) / (2 * h)
    np.testing.assert_allclose(g, num, rtol=1e-4, atol=1e-9)


@pytest.mark.parametrize("jitter", [0.0, 1e-3])
def test_window_operator_products_equal_its_csr_bit_for_bit(monkeypatch, jitter):
    """K's products (vectors, several columns, K squared) and row sums, taken a few rows at a time from the coded
    weights, equal those of the CSR matrix with the same entries bit for bit; positions off the lattice (jitter)
    give one weight per entry (more than 2^16 distinct weights)."""
    rng = _rng()
    pos = Texels.box_faces((9, 7, 8)).pos_vox if jitter == 0 else _flat_face(40, 40)[0]
    pos = pos + jitter * rng.standard_normal(pos.shape)
    monkeypatch.setattr(neighbourhood, "WINDOW_CHUNK_ROWS", 37 if jitter == 0 else 512)
    k, wsum, _ = neighbourhood.gaussian_window(pos, 1.5)
    assert (k.codes is None) == (jitter > 0) and (jitter > 0 or k.codes.dtype == np.uint8)
    c = k.tocsr()
    np.testing.assert_array_equal(wsum, np.asarray(c.sum(axis=1)).ravel())
    x = rng.standard_normal((len(pos), 9))
    np.testing.assert_array_equal(k @ x, c @ x)
    np.testing.assert_array_equal(k @ x[:, 0], c @ x[:, 0])
    c2 = sp.csr_matrix((c.data * c.data, c.indices, c.indptr), shape=c.shape)
    np.testing.assert_array_equal(k.squared @ x, c2 @ x)


def _sobel_all_pairs(pos, tol=1e-6):
    """The Sobel operators from every pair at once (the construction before the blocks): a reference."""
    n = len(pos)
    pairs = neighbourhood.cKDTree(pos).query_pairs(1.0 + tol, p=np.inf, output_type="ndarray")
    off = pos[pairs[:, 1]] - pos[pairs[:, 0]]
    r = np.rint(off)
    keep = np.all(np.abs(off - r) <= tol, axis=1) & np.any(r != 0, axis=1)
    i, j, r = pairs[keep, 0], pairs[keep, 1], r[keep].astype(int)
    d, s = np.array([-1.0, 0.0, 1.0]), np.array([1.0, 2.0, 1.0])
    axes = []
    for a in range(3):
        b, c = [x for x in range(3) if x != a]
        w = d[r[:, a] + 1] * s[r[:, b] + 1] * s[r[:, c] + 1]
        centre = -(np.bincount(i, w, n) - np.bincount(j, w, n))
        rows, cols = np.concatenate([i, j, np.arange(n)]), np.concatenate([j, i, np.arange(n)])
        m = sp.coo_matrix((np.concatenate([w, -w, centre]), (rows, cols)), shape=(n, n)).tocsr()
        m.sum_duplicates()
        m.eliminate_zeros()
        axes.append(m)
    return sp.vstack(axes, format="csr")


def _box_texels():
    """A box's texels (edges, corners) and three repeated positions."""
    pos = Texels.box_faces((9, 7, 8)).pos_vox
    return np.concatenate([pos, pos[:3]])


def test_sobel_operators_in_blocks_equal_the_all_pairs_construction_bit_for_bit(monkeypatch):
    pos = _box_texels()
    monkeypatch.setattr(neighbourhood, "NEIGHBOUR_BLOCK_ROWS", 41)
    got, want = neighbourhood.sobel_operators(pos), _sobel_all_pairs(pos)
    assert got.has_sorted_indices and got.shape == want.shape
    np.testing.assert_array_equal(got.indptr, want.indptr)
    np.testing.assert_array_equal(got.indices, want.indices)
    assert got.data.tobytes() == want.data.tobytes()


@pytest.mark.parametrize("sigma", [1.5, 0.2])
def test_found_products_equal_the_held_operators_bit_for_bit(monkeypatch, sigma):
    """``TexelNeighbours`` finds the rows a few at a time (blocks ending mid-face, a box's edges, repeated
    positions; sigma 0.2: a window narrower than the Sobel operators' reach): K, K^2 and S products and the row
    sums equal the built operators' bit for bit, and so do they with only some operators held."""
    pos = _box_texels()
    monkeypatch.setattr(neighbourhood, "NEIGHBOUR_BLOCK_ROWS", 41)
    rng = _rng()
    x, y, c = rng.standard_normal((len(pos), 5)), rng.standard_normal((len(pos), 2)), rng.standard_normal((len(pos), 3))
    k, wsum, _ = neighbourhood.gaussian_window(pos, sigma)
    s = neighbourhood.sobel_operators(pos)
    want = (k @ x, k.squared @ y, s @ c, wsum)
    ops = neighbourhood.TexelNeighbours(pos, sigma)
    for hold in ((), ("window",), ("sobel",), ("window", "sobel")):
        ops.release()
        for h in hold:
            getattr(ops, h)()
        got = ops.products(x, y, c, wsum=True)
        for g, w in zip(got, want):
            assert g.tobytes() == w.tobytes(), hold
    assert ops.held
    ops.release()
    assert not ops.held
    assert all(g is None for g in ops.products())


@pytest.mark.parametrize("gamma", [(1.0, 0.0, 0.0), (1.0, 4.0, 2.0)])
def test_figures_equal_the_loss_and_ssim_bit_for_bit_held_or_not(gamma):
    """``TexelLoss.figures`` (one pass, nothing held) gives the value, terms and CIELAB of a call without the
    gradient, the first light's ``ssim_mean`` and K @ / K^2 @ the asked columns, bit for bit, under two colour maps;
    the same with the operators held by a training call's gradient."""
    rng = _rng()
    pos = Texels.box_faces((4, 5, 6)).pos_vox
    target, pred = rng.uniform(0, 1, (2, len(pos), 3))
    var = rng.uniform(0, 1e-3, pred.shape)
    cols, cols_sq = rng.standard_normal((len(pos), 2)), rng.standard_normal((len(pos), 1))
    lf = loss.TexelLoss(target, pos, gamma=gamma, colours=(color.RGB, color.RGB))
    k, wsum, _ = neighbourhood.gaussian_window(pos, 1.5)
    for step in range(2):
        assert lf._ops.held == (step == 1 and gamma[1] > 0)
        fig = lf.figures(pred, var, cols, cols_sq)
        bare = lf(pred, var, gradient=False)
        assert (fig.loss.value, fig.loss.e1, fig.loss.e2, fig.loss.e3) == (bare.value, bare.e1, bare.e2, bare.e3)
        assert fig.loss.lab.tobytes() == bare.lab.tobytes() and fig.ssim == lf.ssim_mean(pred, var)
        assert fig.window.tobytes() == (k @ cols).tobytes()
        assert fig.window_sq.tobytes() == (k.squared @ cols_sq).tobytes()
        assert lf.wsum.tobytes() == wsum.tobytes()
        lf(pred, var, all_terms=False)  # a training step: holds what its gradient reads


# ----------------------------------------------------------------------------- the linear colour term
def test_linear_colour_term_value_and_gradient():
    """colour_term "linear": the value is E1_WEIGHT_SCALE (mean sqrt(dE76² + eps²))² (with the other terms as
    before), e1 stays the mean dE76², and the gradient is the value's (central differences), alone and with the SSIM
    and edge terms; the squared term's value is the mean dE76² as before."""
    rng = _rng()
    pos = Texels.box_faces((4, 5, 6)).pos_vox
    n = len(pos)
    target = rng.uniform(0.05, 0.9, (n, 3))
    pred = np.clip(target + rng.normal(0, 0.1, (n, 3)), 0.03, 0.95)
    pred[:3] = target[:3]  # texels on their target: the term's smooth part
    d = color.linear_to_lab(pred) - color.linear_to_lab(target)
    lin = loss.TexelLoss(target, pos, colour_term="linear")
    r = lin(pred)
    mean = np.mean(np.sqrt(np.sum(d * d, axis=1) + loss.LINEAR_EPS**2))
    assert r.value == pytest.approx(loss.E1_WEIGHT_SCALE * mean**2, rel=1e-12)
    assert r.e1 == pytest.approx(np.mean(np.sum(d * d, axis=1)), rel=1e-12)
    sq = loss.TexelLoss(target, pos)(pred)
    assert sq.value == pytest.approx(loss.E1_WEIGHT_SCALE * r.e1, rel=1e-12) and sq.e1 == r.e1
    assert not np.allclose(sq.grad, r.grad)  # the two terms push texels differently
    h = 1e-6
    for gamma in ((1.0, 0.0, 0.0), (1.0, 2.0, 0.5)):
        lf = loss.TexelLoss(target, pos, gamma=gamma, colour_term="linear")
        g = lf(pred).grad
        fd = central_differences(lambda p, lf=lf: lf(p).value, pred, h)
        err = np.linalg.norm(g - fd) / np.linalg.norm(fd)
        assert err < 1e-4, (gamma, err)


def test_colour_term_is_checked():
    pos = _face(4, 3)
    with pytest.raises(ValueError, match="colour_term"):
        loss.TexelLoss(np.full((len(pos), 3), 0.5), pos, colour_term="cubic")
    from inkopt.errors import ParameterError
    from inkopt.optim import OptimizeConfig

    with pytest.raises(ParameterError, match="colour_term"):
        OptimizeConfig(colour_term="cubic").validate()
