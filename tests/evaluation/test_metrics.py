"""Tests of inkopt.evaluation.metrics (the mottle figure) and of the gamut floor's reachable colours
(ColourTable.reachable_lab), on synthetic texel grids and tables with known answers."""

import json

import numpy as np
import pytest

from inkopt.color import linear_to_lab_jacobian
from inkopt.evaluation.metrics import Metrics, flat_texels, mottle, prediction_metrics
from inkopt.loss import TexelLoss

N = 48  # texels per side of a flat face
BAND = 6  # random border: radius + 1 of the sigma-1.5 window, so flat texels have complete windows
SIGMA = 1.5


def grey(lum) -> np.ndarray:
    """Linear RGB of neutral greys with CIELAB L* = lum (a* = b* = 0 for the white of linear sRGB)."""
    y = ((np.asarray(lum, np.float64) + 16) / 116) ** 3
    return np.repeat(y[..., None], 3, -1)


@pytest.fixture(scope="module")
def face():
    """(loss, checkerboard sign, flat mask): a 48 x 48 face whose target is mid grey inside a random band."""
    y, x = np.mgrid[:N, :N]
    pos = np.stack([x.ravel(), y.ravel(), np.zeros(N * N)], 1).astype(np.float64)
    rng = np.random.default_rng(0)
    target = grey(np.full(N * N, 50.0))
    band = ((x < BAND) | (y < BAND) | (x >= N - BAND) | (y >= N - BAND)).ravel()
    target[band] = rng.uniform(0.01, 1, (band.sum(), 3))
    loss = TexelLoss(target, pos, sigma=SIGMA)
    return loss, ((-1.0) ** (x + y)).ravel(), flat_texels(loss)


def test_flat_texels_are_the_interior(face):
    loss, _, flat = face
    assert flat.sum() > 0.5 * (N - 2 * BAND) ** 2
    assert np.all(np.ptp(loss.target_lab[flat], 0) < 1e-9)  # flat texels sit on the constant target


def test_constant_prediction_has_no_mottle(face):
    loss, _, flat = face
    m = mottle(loss, grey(np.full(N * N, 40.0)))
    assert m["mottle_l2"] == pytest.approx(0.0, abs=1e-20) and m["flat_texels"] == flat.sum()
    assert 0 <= m["mottle_l2_target"] < 1e-3  # only window corners reach the random band


def nyquist_gain() -> float:
    """1 - r: what h keeps of a checkerboard, r = the window's response at (π, π) (separable, radius 5)."""
    k = np.arange(-int(3.5 * SIGMA + 0.5), int(3.5 * SIGMA + 0.5) + 1)
    g = np.exp(-k * k / (2 * SIGMA**2))
    return 1.0 - (np.sum(g * (-1.0) ** k) / g.sum()) ** 2


def test_checkerboard_power_is_known(face):
    """L* = 50 ± a on a checkerboard: every flat texel has h = ±a (1 - r), so the mottle is a² (1 - r)²."""
    loss, sign, _ = face
    a = 2.0
    m = mottle(loss, grey(50 + a * sign))
    assert m["mottle_l2"] == pytest.approx((a * nyquist_gain()) ** 2, rel=1e-9)


def highpass_cov(loss, var_l):
    """Exact covariance (I, I) of h = (I - W) L for independent per-texel L* variances var_l."""
    a = np.eye(loss.n) - loss.K.toarray() / loss.wsum[:, None]
    return (a * var_l) @ a.T


@pytest.mark.parametrize("amp", [0.0, 1.0])
def test_noise_correction_removes_pure_noise(face, amp):
    """Gaussian noise in linear RGB on a constant (amp 0) or checkerboard (amp 1) grey: the noise-corrected mottle
    equals the noise-free power within 4 of its standard errors, derived from the Gaussian h: for h = m + e,
    Cov(h_i², h_j²) = 4 m_i m_j C_ij + 2 C_ij² with C = Cov(e) = (I - W) diag(v) (I - W)ᵀ (delta-method v)."""
    loss, sign, flat = face
    clean = grey(50 + amp * sign)
    var = (0.05 * clean) ** 2  # ~0.7 (ΔL*)² per texel
    noisy = clean + np.sqrt(var) * np.random.default_rng(3).standard_normal(clean.shape)
    jl = linear_to_lab_jacobian(clean)[:, 0, :]
    c = highpass_cov(loss, np.einsum("ij,ij->i", jl * jl, var))[np.ix_(flat, flat)]
    m = np.full(flat.sum(), amp * nyquist_gain()) * sign[flat]
    se = np.sqrt(np.sum(4 * np.outer(m, m) * c + 2 * c * c)) / flat.sum()
    truth = (amp * nyquist_gain()) ** 2
    raw = mottle(loss, noisy)["mottle_l2"]
    corrected = mottle(loss, noisy, var)["mottle_l2"]
    assert raw - truth > 8 * se  # the noise is there ...
    assert abs(corrected - truth) < 4 * se  # ... and the correction removes it


def test_prediction_metrics_keys(face):
    loss, sign, _ = face
    rgb = grey(50 + sign)
    m = prediction_metrics(loss, rgb, np.full((loss.n, 3), 1e-6))
    out = m.to_json()
    for k in (
        "mottle_l2",
        "mottle_l2_target",
        "flat_texels",
        "delta_e76_noise_contribution",
        "delta_e76_mean_corrected",
        "delta_e76_mean",
        "delta_e76_rms_denoised",
    ):
        assert k in out
    assert m.delta_e76_mean_corrected == pytest.approx(m.delta_e76_mean - m.delta_e76_noise_contribution)
    assert "delta_e76_noise_contribution" not in prediction_metrics(loss, rgb).to_json()


def test_metrics_json_round_trip(face):
    """to_json -> JSON text -> from_json gives the same metrics, with and without the noise figures."""
    loss, sign, _ = face
    rgb = grey(50 + sign)
    for var in (None, np.full((loss.n, 3), 1e-6)):
        m = prediction_metrics(loss, rgb, var)
        back = Metrics.from_json(json.loads(json.dumps(m.to_json())))
        assert back == m
        assert back.to_json() == m.to_json()


def test_prediction_metrics_without_operators_held_equal_those_with_them(face):
    """The figures found a block of texel rows at a time (nothing held) equal those from the built window and
    Sobel operators bit for bit (noise-corrected and not), and the mottle equals the dense (1 - W) L*."""
    base, sign, flat = face
    loss = TexelLoss(base.target_rgb, base._pos, gamma=(1.0, 2.0, 1.0), sigma=SIGMA)
    rng = np.random.default_rng(4)
    rgb = np.clip(grey(50 + 3 * sign) + 0.02 * rng.standard_normal((loss.n, 3)), 0.001, 1)
    var = rng.uniform(0, 1e-4, rgb.shape)
    assert not loss._ops.held
    found = [prediction_metrics(loss, rgb, v).to_json() for v in (var, None)]
    lum = loss.colours[0].lab(rgb)[:, 0]
    h = lum - (loss.K.toarray() @ lum) / loss.wsum
    loss.S  # noqa: B018 (both operators held now)
    assert loss._ops.held
    assert [prediction_metrics(loss, rgb, v).to_json() for v in (var, None)] == found
    assert found[1]["mottle_l2"] == pytest.approx(np.mean(h[flat] ** 2), rel=1e-12)
