"""Tests of inkopt.printing.compensate: the share pre-compensation of the halftone (its inverse map, its measurement on
flat patches, its use by ``quantize`` and its record)."""

import numpy as np
import pytest

from inkopt.errors import ParameterError
from inkopt.model import InkTable, Quantization
from inkopt.printing import compensate as C
from inkopt.printing import quantize as Q
from inkopt.printing.quantize import MixtureLayers, check_quantization, ink_fractions, quantize

SHARES = np.array([0.0, 0.1, 0.3, 0.6, 1.0])


def scaled(base: int, n: int, factor: float) -> C.ShareCompensation:
    """A compensation whose every ink but ``base`` looks like ``factor`` times its share when dithered (up to 1)."""
    eff = np.tile(SHARES, (n, 1))
    for i in range(n):
        if i != base:
            eff[i] = np.minimum(SHARES * factor, 1.0)
            eff[i, -1] = 1.0
    return C.ShareCompensation(base, SHARES, eff, np.zeros_like(eff))


def test_apply_inverts_the_effective_share_and_gives_the_base_the_rest():
    comp = scaled(base=2, n=3, factor=0.8)
    mix = np.array([[0.08, 0.0, 0.92], [0.04, 0.16, 0.8], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    out = comp.apply(mix)
    np.testing.assert_allclose(out[0], [0.1, 0.0, 0.9])
    np.testing.assert_allclose(out[1], [0.05, 0.2, 0.75])
    np.testing.assert_allclose(out[2], [0.0, 0.0, 1.0])
    np.testing.assert_allclose(out[3], [0.0, 0.0, 0.0])  # outside rows stay empty
    # the effective share of the corrected row is the mixture's own
    for i in (0, 1):
        np.testing.assert_allclose(np.interp(out[1, i], comp.shares, comp.effective[i]), mix[1, i])


def test_apply_scales_non_base_inks_that_would_exceed_the_row():
    comp = scaled(base=0, n=3, factor=0.5)
    out = comp.apply(np.array([[0.1, 0.5, 0.4]]))  # 1.0 + 0.8 > 1
    np.testing.assert_allclose(out.sum(-1), 1.0)
    assert out[0, 0] == 0.0
    inv = [np.interp(v, comp.effective[1], comp.shares) for v in (0.5, 0.4)]
    np.testing.assert_allclose(out[0, 1] / out[0, 2], inv[0] / inv[1])


def test_identity_compensation_leaves_rows_unchanged():
    comp = scaled(base=4, n=5, factor=1.0)
    rng = np.random.default_rng(0)
    mix = rng.dirichlet(np.ones(5) * 0.5, size=200)
    np.testing.assert_allclose(comp.apply(mix), mix, atol=1e-12)


def test_patch_labels_hold_the_share_of_each_ink():
    inks = InkTable.parse("vero-cmykw")
    row = np.array([0.0, 0.0, 0.3, 0.0, 0.7])
    vol = C.patch_labels(row, inks, Quantization(), inks.g, 1.5)
    lab = vol.labels
    assert vol.boundary == "periodic-xy" and lab.shape[1:] == (C.PATCH_LATERAL, C.PATCH_LATERAL)
    # blue noise gives a whole 32 x 32 x 32 tile the share to within one voxel of its 32768
    assert lab.shape[0] >= 32
    assert abs((lab[:32] == 2).mean() - 0.3) <= 1.0 / 32768 + 1e-9
    assert set(np.unique(lab)) == {2, 4}


def test_curve_share_projects_onto_the_polyline():
    curve = np.array([[0.0, 0, 0], [10.0, 0, 0], [10.0, 10, 0]])
    shares = np.array([0.0, 0.5, 1.0])
    assert C._curve_share(np.array([5.0, 1.0, 0.0]), curve, shares) == pytest.approx(0.25)
    assert C._curve_share(np.array([12.0, 5.0, 0.0]), curve, shares) == pytest.approx(0.75)


def test_measured_compensation_of_a_strong_absorber_is_below_its_share(monkeypatch):
    """A yellow-like ink (absorbing blue at 16 /mm) in a white-like scatterer: its dithered patch at share 0.3 looks
    like a smaller continuous share (the package effect), by more than five standard errors of the share."""
    monkeypatch.setattr(C, "DITHERED_SHARES", (0.3,))
    monkeypatch.setattr(C, "CONTINUOUS_SHARES", (0.0, 0.1, 0.2, 0.25, 0.3, 0.35, 0.4, 0.6, 1.0))
    inks = InkTable(
        names=("white", "yellow", "grey"),
        sigma_a=np.array([[0.005, 0.003, 0.024], [0.007, 0.019, 16.15], [0.1, 0.1, 0.1]]),
        sigma_s=np.array([[6.0, 9.0, 24.0], [2.2, 3.7, 2.9], [6.0, 9.0, 24.0]]),
        g=0.4,
    )
    comp = C.measure_compensation(inks, Quantization(), inks.g, 1.5, base=0)
    assert comp.shares.tolist() == [0.0, 0.3, 1.0]
    # the share's standard error from the colour's: ΔE per unit share on the continuous curve about 0.3
    curve = []
    for p in (0.25, 0.35):
        vol = C.Volume.from_mixture(
            voxel_mm=(0.25, 0.25, C.PATCH_MM),
            mixture=np.broadcast_to(np.array([1 - p, p, 0.0], np.float32), (1, 8, 8, 3)).copy(),
            inks=inks, g=inks.g, ior=1.5, boundary="periodic-xy",
        )  # fmt: skip
        curve.append(C.linear_to_lab(C._top_colour(vol, 1024, 99, None)[0]))
    slope = np.linalg.norm(curve[1] - curve[0]) / 0.1
    se_yellow = comp.stderr[1, 1] / slope
    assert comp.effective[1, 1] < 0.3 - 5 * se_yellow, (comp.effective[1], se_yellow)
    assert comp.effective[1, 1] > 0.15  # and not absurdly far
    assert comp.stderr[2, 1] > 0  # every ink but the base is measured


def test_quantize_uses_the_compensation(monkeypatch):
    inks = InkTable.parse("vero-cmykw")
    comp = scaled(base=4, n=5, factor=0.8)
    monkeypatch.setattr(Q, "share_compensation", lambda *a, **k: comp)
    mix = np.zeros((6, 8, 8, 5), np.float32)
    mix[..., 2], mix[..., 4] = 0.24, 0.76
    vo = (25.4 / 300,) * 3
    src = MixtureLayers(mix, vo, None, inks)
    for flag, want in ((False, 0.24), (True, 0.3)):
        labels, vp = quantize(src, Quantization(compensate=flag))
        frac, _ = ink_fractions(labels, 5, mix.shape[:3], vo, vp)
        # blue noise over the whole volume: within 1 % of the share it was given
        assert abs(frac[..., 2].mean() - want) < 0.01, (flag, frac[..., 2].mean())


def test_compensate_is_recorded_and_checked():
    q = Quantization(compensate=True)
    assert Quantization.from_arrays(q.arrays()).compensate is True
    assert Quantization.from_arrays(Quantization().arrays()).compensate is False
    assert q.to_json()["compensate"] is True
    with pytest.raises(ParameterError, match="compensate must be true or false"):
        check_quantization(Quantization(compensate="yes"))


def test_share_compensation_is_cached_on_disk(monkeypatch, tmp_path):
    monkeypatch.setenv("INKOPT_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(C, "_MEMORY", {})
    inks = InkTable.parse("vero-cmykw")
    calls = []

    def fake(inks_, q, g, ior, base, threads=None, log=None):
        calls.append(base)
        return scaled(base, len(inks_), 0.9)

    monkeypatch.setattr(C, "measure_compensation", fake)
    a = C.share_compensation(inks, Quantization(), inks.g, 1.5)
    monkeypatch.setattr(C, "_MEMORY", {})
    b = C.share_compensation(inks, Quantization(), inks.g, 1.5)
    assert calls == [4]  # white, the lightest, is the base; measured once, then read from the disk cache
    np.testing.assert_array_equal(a.effective, b.effective)
    assert list(tmp_path.glob("compensation_*.npz"))
    with pytest.raises(ValueError, match="ink table"):
        C.share_compensation(None, Quantization(), 0.4, 1.5)
