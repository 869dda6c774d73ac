"""Tests of inkopt.printing.compensate: the share pre-compensation of the halftone (its inverse map, its measurement on
flat patches, its use by ``quantize`` and its record)."""

from dataclasses import replace

import numpy as np
import pytest

from inkopt.errors import ParameterError
from inkopt.model import InkTable, Quantization
from inkopt.printing import compensate as C
from inkopt.printing import quantize as Q
from inkopt.printing.quantize import MixtureLayers, check_quantization, ink_fractions, quantize

SHARES = np.array([0.1, 0.3, 0.6])


def scaled(base: int, n: int, k: float) -> C.ShareCompensation:
    """A compensation with the package factor ``k`` for every ink but ``base``."""
    ks = np.full(n, float(k))
    ks[base] = 0.0
    measured = np.array([C.ShareCompensation(base, ks, ks, SHARES, None, None).effective(SHARES, i) for i in range(n)])
    return C.ShareCompensation(base, ks, np.zeros(n), SHARES, measured, np.zeros_like(measured))


def test_apply_inverts_the_effective_share_and_gives_the_base_the_rest():
    comp = scaled(base=2, n=3, k=0.25)
    mix = np.array([[0.08, 0.0, 0.92], [0.04, 0.16, 0.8], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    out = comp.apply(mix)
    np.testing.assert_allclose(out.sum(-1), [1, 1, 1, 0])
    np.testing.assert_allclose(out[2], [0.0, 0.0, 1.0])
    np.testing.assert_allclose(out[3], [0.0, 0.0, 0.0])  # outside rows stay empty
    # the effective share of each corrected share is the mixture's own, and the correction raises it
    for r in (0, 1):
        for i in (0, 1):
            np.testing.assert_allclose(comp.effective(out[r, i], i), mix[r, i], atol=1e-12)
            assert out[r, i] >= mix[r, i]
    assert out[0, 0] > 0.08 * 1.2  # at small shares the dither needs 1 + k times the share


def test_apply_scales_non_base_inks_that_would_exceed_the_row():
    comp = scaled(base=0, n=3, k=1.0)
    out = comp.apply(np.array([[0.1, 0.5, 0.4]]))  # 2 * 0.5 / 1.5 + 2 * 0.4 / 1.4 > 1
    np.testing.assert_allclose(out.sum(-1), 1.0)
    assert out[0, 0] == 0.0
    np.testing.assert_allclose(out[0, 1] / out[0, 2], (2 * 0.5 / 1.5) / (2 * 0.4 / 1.4))


def test_identity_compensation_leaves_rows_unchanged():
    comp = scaled(base=4, n=5, k=0.0)
    rng = np.random.default_rng(0)
    mix = rng.dirichlet(np.ones(5) * 0.5, size=200)
    np.testing.assert_allclose(comp.apply(mix), mix, atol=1e-12)


def test_fit_k_recovers_the_factor_within_its_standard_error():
    rng = np.random.default_rng(1)
    p = np.array(C.DITHERED_SHARES)
    s = np.full(len(p), 0.01)
    ks = []
    for _ in range(200):
        e = p / (1 + 0.3 * (1 - p)) + rng.normal(0, 0.01, len(p))
        ks.append(C.fit_k(p, e, s))
    k, se = np.array(ks).T
    # the fitted factors scatter about 0.3 as their standard error says (200 fits: the mean within 5 of its errors)
    assert abs(k.mean() - 0.3) < 5 * se.mean() / np.sqrt(len(k))
    assert 0.7 < k.std() / se.mean() < 1.3


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
    share, slope, j = C._curve_share(np.array([5.0, 1.0, 0.0]), curve, shares)
    assert (share, slope, j) == (pytest.approx(0.25), pytest.approx(20.0), 0)
    assert C._curve_share(np.array([12.0, 5.0, 0.0]), curve, shares)[0] == pytest.approx(0.75)


def test_measured_compensation_of_a_strong_absorber_is_below_its_share(monkeypatch):
    """A yellow-like ink (absorbing blue at 16 /mm) in a white-like scatterer: its dithered patch at share 0.3 looks
    like a smaller continuous share (the package effect), by more than five standard errors of the share."""
    monkeypatch.setattr(C, "DITHERED_SHARES", (0.3,))
    monkeypatch.setattr(C, "CONTINUOUS_SHARES", (0.0, 0.1, 0.2, 0.25, 0.3, 0.35, 0.4, 0.6, 1.0))
    monkeypatch.setattr(C, "PAIR_SHARES", ((0.1, 0.1),))
    inks = InkTable(
        names=("white", "yellow", "grey"),
        sigma_a=np.array([[0.005, 0.003, 0.024], [0.007, 0.019, 16.15], [0.1, 0.1, 0.1]]),
        sigma_s=np.array([[6.0, 9.0, 24.0], [2.2, 3.7, 2.9], [6.0, 9.0, 24.0]]),
        g=0.4,
    )
    comp = C.measure_compensation(inks, Quantization(), inks.g, 1.5, base=0)
    assert comp.shares.tolist() == [0.3]
    # the matched share's own standard error (the colours' over the curve's slope)
    se = comp.share_stderr[1, 0]
    assert 0 < se < 0.02
    assert comp.measured[1, 0] < 0.3 - 5 * se, (comp.measured[1], se)
    assert comp.measured[1, 0] > 0.15  # and not absurdly far
    assert comp.k[1] > 5 * comp.k_stderr[1] and comp.k[0] == 0.0
    assert comp.share_stderr[2, 0] > 0  # every ink but the base is measured
    # the pair's patch: both inks' effective shares measured with errors, and their factors fitted
    assert comp.mixed_rows.tolist() == [[0.8, 0.1, 0.1]] and np.all(comp.mixed_stderr[0, 1:] > 0)
    assert np.isfinite(comp.kappa_stderr[1, 2]) and np.isfinite(comp.kappa_stderr[2, 1])
    assert 0.05 < comp.mixed_effective[0, 1] < 0.1 - 3 * comp.mixed_stderr[0, 1]  # yellow's package effect there too


def test_quantize_uses_the_compensation(monkeypatch):
    inks = InkTable.parse("vero-cmykw")
    comp = scaled(base=4, n=5, k=0.25)
    monkeypatch.setattr(Q, "share_compensation", lambda *a, **k: comp)
    mix = np.zeros((6, 8, 8, 5), np.float32)
    mix[..., 2], mix[..., 4] = 0.24, 0.76
    vo = (25.4 / 300,) * 3
    src = MixtureLayers(mix, vo, None, inks)
    for method in ("blue-noise", "count-diffusion"):
        for flag, want in ((False, 0.24), (True, 0.24 * 1.25 / (1 + 0.25 * 0.24))):
            labels, vp = quantize(src, Quantization(method, compensate=flag))
            frac, _ = ink_fractions(labels, 5, mix.shape[:3], vo, vp)
            # over the whole volume: within 1 % of the share it was given
            assert abs(frac[..., 2].mean() - want) < 0.01, (method, flag, frac[..., 2].mean())


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
    monkeypatch.setattr(C, "PACKAGED", tmp_path / "packaged")  # none shipped
    inks = InkTable.parse("vero-cmykw")
    calls = []

    def fake(inks_, q, g, ior, base, threads=None, log=None):
        calls.append(base)
        return scaled(base, len(inks_), 0.1)

    monkeypatch.setattr(C, "measure_compensation", fake)
    a = C.share_compensation(inks, Quantization(), inks.g, 1.5)
    monkeypatch.setattr(C, "_MEMORY", {})
    b = C.share_compensation(inks, Quantization(), inks.g, 1.5)
    assert calls == [4]  # white, the lightest, is the base; measured once, then read from the disk cache
    np.testing.assert_array_equal(a.k, b.k)
    np.testing.assert_array_equal(a.measured, b.measured)
    assert list(tmp_path.glob("compensation_*.npz"))
    with pytest.raises(ValueError, match="ink table"):
        C.share_compensation(None, Quantization(), 0.4, 1.5)


def test_compensated_run_streams_like_memory_and_records_it(tmp_path, monkeypatch):
    """``inkopt quantize --compensate``: the run's labels file equals the in-memory compensated quantization, says
    ``compensate`` in its record and in the summary, and differs from the uncompensated labels."""
    from inkopt.cli import main
    from inkopt.printing.quantize import quantize_volume
    from inkopt.rundir import RunDir

    monkeypatch.setenv("INKOPT_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(C, "_MEMORY", {})
    monkeypatch.setattr(C, "PACKAGED", tmp_path / "packaged")
    monkeypatch.setattr(C, "measure_compensation", lambda inks, q, g, ior, base, *a, **k: scaled(base, len(inks), 0.3))
    inks = InkTable.parse("vero-cmykw")
    rng = np.random.default_rng(2)
    vol = C.Volume.from_mixture(voxel_mm=(25.4 / 300,) * 3, mixture=rng.dirichlet(np.ones(5), (5, 7, 9)), inks=inks)
    d = RunDir.create(tmp_path / "r")
    d.save_volume(vol)
    assert main(["quantize", str(d.path), "--compensate", "--seed", "3"]) == 0
    got = d.load_quantized()
    expect = quantize_volume(vol, Quantization(seed=3, compensate=True))
    np.testing.assert_array_equal(got.labels, expect.labels)
    assert got.quantization.compensate is True and got.quantization == expect.quantization
    assert not np.array_equal(got.labels, quantize_volume(vol, Quantization(seed=3)).labels)
    assert main(["quantize", str(d.path), "--no-compensate", "--seed", "3"]) == 0
    assert d.load_quantized().quantization.compensate is False
    # the inks' order in the bands: a flag of its own, recorded, the compensation measured for that order
    assert main(["quantize", str(d.path), "--compensate", "--ink-order", "tint-first"]) == 0
    got = d.load_quantized()
    expect = quantize_volume(vol, Quantization(ink_order="tint-first", compensate=True))
    assert got.quantization.ink_order == "tint-first" and got.quantization == expect.quantization
    np.testing.assert_array_equal(got.labels, expect.labels)


def mixed(base: int, n: int, k: float, kappa: np.ndarray) -> C.ShareCompensation:
    """``scaled`` with the factors ``kappa`` (N, N) of each ink against the other inks, applied."""
    return replace(scaled(base, n, k), kappa=np.asarray(kappa, np.float64), pairs=True)


def test_effective_rows_without_kappa_is_the_single_ink_model():
    comp = scaled(base=4, n=5, k=0.3)
    rng = np.random.default_rng(2)
    rows = rng.dirichlet(np.ones(5), size=50)
    eff = comp.effective_rows(rows)
    np.testing.assert_allclose(eff.sum(-1), 1.0)
    for i in range(4):  # every other ink counted as base: p / (1 + k (1 - p))
        np.testing.assert_allclose(eff[:, i], comp.effective(rows[:, i], i), atol=1e-12)


def test_apply_with_kappa_inverts_the_mixed_model():
    kappa = np.array([[0, 0.5, -0.2, 0, 0], [0.1, 0, 0.3, 0.2, 0], [0.2, 0.1, 0, -0.1, 0], [0, 0, 0.4, 0, 0], [0] * 5])
    comp = mixed(base=4, n=5, k=0.3, kappa=kappa)
    rng = np.random.default_rng(3)
    rows = rng.dirichlet(np.ones(5) * 0.4, size=300) * np.array([0.3, 0.3, 0.3, 0.3, 1.0])
    rows[:, 4] += 1.0 - rows.sum(-1)  # mostly base, as an optimiser's rows are
    rows = np.concatenate([rows, np.zeros((1, 5))])  # an outside row
    out = comp.apply(rows)
    np.testing.assert_allclose(out.sum(-1), rows.sum(-1), atol=1e-12)
    np.testing.assert_allclose(comp.effective_rows(out), rows, atol=1e-10)
    # a factor against another ink lower than against the base asks for less of the ink where that ink is present
    one = np.array([[0.0, 0.0, 0.1, 0.3, 0.6]])
    assert comp.apply(one)[0, 2] < scaled(4, 5, 0.3).apply(one)[0, 2]
    # not applied unless ``pairs``: the single-ink model's closed form
    np.testing.assert_array_equal(replace(comp, pairs=False).apply(rows), scaled(4, 5, 0.3).apply(rows))
    # kappa equal to k everywhere: the closed form of the single-ink model
    same = mixed(base=4, n=5, k=0.3, kappa=np.full((5, 5), 0.3))
    np.testing.assert_allclose(same.apply(rows), scaled(4, 5, 0.3).apply(rows), atol=1e-10)


def test_fit_kappa_recovers_pair_factors_within_their_standard_errors():
    comp = scaled(base=3, n=4, k=0.3)
    truth = np.array([[0, 0.1, 0.5, 0], [0.2, 0, 0.0, 0], [0.05, 0.3, 0, 0], [0, 0, 0, 0]])
    rows = []
    for i, j in ((0, 1), (0, 2), (1, 2)):
        for pi, pj in C.PAIR_SHARES:
            r = np.zeros(4)
            r[i], r[j], r[3] = pi, pj, 1 - pi - pj
            rows.append(r)
    rows = np.array(rows)
    exact = mixed(3, 4, 0.3, truth).effective_rows(rows)
    se = np.where(rows > 0, 0.004, 0.0)
    se[:, 3] = 0.0
    rng = np.random.default_rng(4)
    z = []
    for _ in range(100):
        kappa, kse = C.fit_kappa(comp, rows, exact + rng.normal(0, 1, rows.shape) * se, se)
        z.append(((kappa - truth) / kse)[[0, 0, 1, 1, 2, 2], [1, 2, 0, 2, 0, 1]])
    z = np.array(z)
    # the fitted factors scatter about the truth as their standard errors say
    assert np.all(np.abs(z.mean(0)) < 5 / np.sqrt(len(z))), z.mean(0)
    assert np.all((0.7 < z.std(0)) & (z.std(0) < 1.3)), z.std(0)
    assert kse[3, 0] == np.inf and kappa[3].tolist() == [0, 0, 0, 0]  # the base has no factors


def test_the_default_inks_compensation_is_shipped_and_current(monkeypatch, tmp_path):
    """The package holds the compensation of the default inks on the default printer grid under the key the current
    settings give (a change of the measurement or its settings needs a new file), read without measuring; it holds
    the factors against other inks, and its yellow is the strong absorber (k > 5 standard errors)."""
    monkeypatch.setenv("INKOPT_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(C, "_MEMORY", {})
    monkeypatch.setattr(C, "measure_compensation", lambda *a, **k: pytest.fail("measured"))
    inks = InkTable.parse("vero-cmykw")
    key = C.compensation_key(inks, Quantization(), inks.g, 1.5)
    assert (C.PACKAGED / f"compensation_{key}.npz").is_file()
    comp = C.share_compensation(inks, Quantization(), inks.g, 1.5)
    assert comp.kappa is not None and comp.kappa.shape == (5, 5) and comp.base == 4
    assert comp.k[2] > 5 * comp.k_stderr[2] and np.all(np.isfinite(comp.kappa_stderr[:4, :4][~np.eye(4, dtype=bool)]))
    assert not list(tmp_path.iterdir())  # nothing measured or written


def test_float32_ink_tables_share_the_key():
    """A run's ink table (float32 coefficients, as read from its files) has the key of the table it came from."""
    inks = InkTable.parse("vero-cmykw")
    f32 = replace(inks, sigma_a=inks.sigma_a.astype(np.float32), sigma_s=inks.sigma_s.astype(np.float32))
    assert C.compensation_key(f32, Quantization(), inks.g, 1.5) == C.compensation_key(inks, Quantization(), 0.4, 1.5)


def test_taper_scales_the_correction_below_its_share():
    comp = scaled(base=2, n=3, k=0.3)
    mix = np.array([[0.01, 0.2, 0.79], [0.05, 0.1, 0.85]])
    full, tapered = comp.apply(mix), replace(comp, taper=0.05).apply(mix)
    np.testing.assert_allclose(tapered.sum(-1), 1.0)
    np.testing.assert_allclose(tapered[0, 0] - mix[0, 0], (full[0, 0] - mix[0, 0]) * 0.2)  # 0.01 / 0.05
    np.testing.assert_allclose(tapered[:, 1], full[:, 1])  # at or above the taper share: the whole correction
    np.testing.assert_allclose(tapered[1, 0], full[1, 0])


def test_base_only_corrects_against_the_base_share_alone():
    """With ``base_only`` an ink's dithered share p looks like p / (1 + k w), w the base's share: ``apply`` inverts
    it, leaves a row without the base as it is, and corrects less than the single-ink model where other inks stand
    in for the base."""
    comp = replace(scaled(base=4, n=5, k=0.3), base_only=True)
    rng = np.random.default_rng(5)
    rows = rng.dirichlet(np.ones(5) * 0.4, size=200) * np.array([0.3, 0.3, 0.3, 0.3, 1.0])
    rows[:, 4] += 1.0 - rows.sum(-1)
    out = comp.apply(rows)
    np.testing.assert_allclose(out.sum(-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(comp.effective_rows(out), rows, atol=1e-10)
    eff = comp.effective_rows(rows)
    np.testing.assert_allclose(eff[:, :4], rows[:, :4] / (1.0 + 0.3 * rows[:, 4:5]), atol=1e-12)
    no_base = np.array([[0.2, 0.3, 0.5, 0.0, 0.0]])
    np.testing.assert_allclose(comp.apply(no_base), no_base, atol=1e-12)
    single = scaled(4, 5, 0.3).apply(rows)
    assert np.all(out[:, :4] <= single[:, :4] + 1e-12) and np.any(out[:, :4] < single[:, :4] - 1e-3)
