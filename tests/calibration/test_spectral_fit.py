"""Spectral calibration: band averaging of measured spectra onto the table's grid, the per-band Jacobian against
central differences, recovery of a hidden spectral table from noise-free adding-doubling reflectance (the model is
exact there), ``inkopt calibrate`` on spectral measurements writing a spectral ink file (``--rgb``: the CIELAB fit
of an RGB table), and the spectral columns' reader fuzzed."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from inkopt.calibration import cgats
from inkopt.calibration.chart import chart_from_table, design_chart
from inkopt.calibration.fit import predict_rgb
from inkopt.calibration.measure import MeasurementError, measured_reflectance, rgb_to_lab, spectral_to_lab
from inkopt.calibration.report import CalibrationReport
from inkopt.calibration.spectral import (
    _from_x,
    _reflectance_and_jacobian,
    _to_x,
    band_average,
    fit_spectral_inks,
    predict_reflectance,
    spectral_form,
    spectral_start,
)
from inkopt.cli import main
from inkopt.color import delta_e2000
from inkopt.model import InkTable
from inkopt.model.inks import read_ink_file
from inkopt.model.spectral import WAVELENGTHS_20NM, SpectralInkTable, load_ink_table

pytest.importorskip("iadpython")
INKS = InkTable.parse("cyan,white")
CHART = design_chart(INKS.names)
GRID = np.array([450.0, 500.0, 550.0, 600.0, 650.0])  # 5 bands: two groups of three, the last padded


def hidden(grid=GRID, seed=2, g=0.4):
    start = SpectralInkTable.from_rgb(INKS, grid)
    rng = np.random.default_rng(seed)
    shape = start.sigma_s.shape
    return SpectralInkTable(
        start.names, grid, start.sigma_s * rng.uniform(0.6, 1.6, shape), start.sigma_a * rng.uniform(0.6, 1.6, shape), g
    )


def test_band_average():
    wl = np.arange(380.0, 731.0, 10.0)
    flat = np.full((2, wl.size), 0.3)
    np.testing.assert_allclose(band_average(wl, flat, WAVELENGTHS_20NM), 0.3)
    line = (wl / 1000)[None]  # linear in wavelength: a symmetric band's mean is its centre's value
    np.testing.assert_allclose(band_average(wl, line, WAVELENGTHS_20NM)[0], WAVELENGTHS_20NM / 1000, rtol=1e-12)
    # a 400-700 nm measurement: the end bands average their measured halves
    inner = np.arange(400.0, 701.0, 20.0)
    out = band_average(inner, (inner / 1000)[None], WAVELENGTHS_20NM)[0]
    assert out[0] == pytest.approx(0.405) and out[-1] == pytest.approx(0.695) and out[3] == pytest.approx(0.46)
    with pytest.raises(ValueError, match="beyond the measured"):
        band_average(np.arange(420.0, 701.0, 20.0), np.ones((1, 15)), WAVELENGTHS_20NM)


def test_jacobian_matches_central_differences():
    chart = CHART.subset([0, 7, 10, 15])  # over white, alone, diluted, white alone
    truth = hidden()
    x = _to_x(truth)
    _, jac = _reflectance_and_jacobian(chart, truth)
    rng = np.random.default_rng(0)
    for k in rng.choice(len(x) - 1, 4, replace=False).tolist() + [len(x) - 1]:
        h = 1e-4
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        fd = (
            predict_reflectance(chart, _from_x(xp, truth.names, GRID))
            - predict_reflectance(chart, _from_x(xm, truth.names, GRID))
        ) / (2 * h)
        np.testing.assert_allclose(jac[..., k], fd, atol=2e-4 * max(np.abs(fd).max(), 1e-3))


def test_recovers_a_hidden_spectral_table():
    truth = hidden()
    refl = predict_reflectance(CHART, truth)
    held = [8, 12, 16]
    keep = np.setdiff1d(np.arange(len(CHART)), held)
    res = fit_spectral_inks(CHART.subset(keep), refl[keep], SpectralInkTable.from_rgb(INKS, GRID))
    assert res.converged and res.inks.bands == len(GRID)
    assert np.abs(res.predicted / refl[keep] - 1).max() < 1e-3
    assert np.abs(predict_reflectance(CHART.subset(held), res.inks) / refl[held] - 1).max() < 2e-3
    assert res.inks.g == pytest.approx(0.4, abs=0.05)


def test_spectral_start_from_rgb_or_spectral_tables():
    rgb = spectral_start(CHART, InkTable.parse("vero-cmykw"), GRID)
    assert rgb.names == ("cyan", "white") and rgb.bands == 5
    cyan = load_ink_table("cyan@spectral")
    spec = spectral_start(CHART, cyan, GRID)  # cyan resampled, white from the library
    np.testing.assert_allclose(spec.sigma_a[0], np.interp(GRID, cyan.wavelengths_nm, cyan.sigma_a[0]))
    np.testing.assert_allclose(spec.sigma_s[1], rgb.sigma_s[1])


def _d65_miss(chart, rgb: InkTable, spectral: SpectralInkTable) -> np.ndarray:
    """ΔE2000 (P,) under D65 between the RGB table's colours of ``chart`` and the spectral table's."""
    ref = rgb_to_lab(predict_rgb(chart, rgb), "D65")
    return delta_e2000(spectral_to_lab(spectral.wavelengths_nm, predict_reflectance(chart, spectral), "D65"), ref)


def test_spectral_form_reproduces_the_rgb_colours_better_than_the_linear_one():
    grid = np.arange(400.0, 701.0, 30.0)  # 11 bands: a quick fit
    fit = spectral_form(INKS, grid, max_iterations=12)
    linear = _d65_miss(CHART, INKS, SpectralInkTable.from_rgb(INKS, grid))
    fitted = _d65_miss(CHART, INKS, fit.inks)
    assert fitted.mean() < 0.5 * linear.mean() and fitted.max() < linear.max()
    assert fit.inks.g == INKS.g
    with pytest.raises(ValueError, match="are not the table's"):
        spectral_form(InkTable.parse("white,cyan"), grid, CHART)


def test_stored_library_spectra_reproduce_the_rgb_table():
    """The presets' spectral form (data/ink_spectra_20nm.json, experiments/spectral_library.py) against the RGB
    table on the CMYKW chart: the figures docs/inks.md gives, within 0.05 ΔE2000."""
    vero = InkTable.parse("vero-cmykw")
    miss = _d65_miss(design_chart(vero.names), vero, load_ink_table("vero-cmykw@spectral"))
    assert miss.mean() < 1.43 + 0.05 and miss.max() < 3.80 + 0.05


@pytest.fixture(scope="module")
def spectral_chart(tmp_path_factory):
    """The cyan + white chart with SPECTRAL_NM380 ... 730 (10 nm, percent) from a hidden 20 nm table."""
    d = tmp_path_factory.mktemp("spectral")
    assert main(["calibration-chart", "--inks", "cyan,white", "--out", str(d), "--patch-mm", "3"]) == 0
    table = cgats.read(d / "chart.txt")
    chart = chart_from_table(table)
    truth = hidden(WAVELENGTHS_20NM, seed=4)
    wl = np.arange(380, 731, 10)
    refl = np.stack([np.interp(wl, WAVELENGTHS_20NM, r) for r in predict_reflectance(chart, truth)])
    n = len(table.fields) - 3
    table.fields = table.fields[:n] + [f"SPECTRAL_NM{w}" for w in wl]
    table.rows = [r[:n] + [float(round(100 * v, 4)) for v in refl[k]] for k, r in enumerate(table.rows)]
    cgats.write(d / "measured.txt", table)
    return d


def test_calibrate_spectral_measurements(spectral_chart, tmp_path, capsys):
    out = tmp_path / "spec.json"
    assert main(["calibrate", str(spectral_chart / "measured.txt"), "--out", str(out), "--holdout", "0.1"]) == 0
    assert "a spectral ink table, 16 bands" in capsys.readouterr().out
    inks = load_ink_table(str(out))
    assert isinstance(inks, SpectralInkTable) and inks.names == ("cyan", "white") and inks.bands == 16
    assert read_ink_file(out)["provenance"]["measurement_kind"] == "spectral"
    rep = CalibrationReport.from_json(tmp_path / "spec.report.json")
    assert rep.model == "spectral" and rep.wavelengths_nm == [float(w) for w in WAVELENGTHS_20NM]
    # the model's own reflectance, linearly interpolated to 10 nm and band-averaged back: small residuals
    assert rep.fit_mean_delta_e2000 < 0.3 and rep.holdout_mean_delta_e2000 < 0.5
    rgb = tmp_path / "rgb.json"
    args = ["calibrate", str(spectral_chart / "measured.txt"), "--out", str(rgb), "--rgb", "--holdout", "0"]
    assert main(args) == 0
    assert isinstance(load_ink_table(str(rgb)), InkTable)
    assert CalibrationReport.from_json(tmp_path / "rgb.report.json").model == "rgb"


def test_a_spectral_start_for_a_lab_fit_is_refused(tmp_path, capsys):
    table = CHART.table(header={"ORIGINATOR": "test"})
    table.rows = [r[:-3] + [50.0, 0.0, 0.0] for r in table.rows]
    cgats.write(tmp_path / "lab.txt", table)
    args = ["calibrate", str(tmp_path / "lab.txt"), "--out", str(tmp_path / "x.json"), "--start", "vero-cmykw@spectral"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--start" in err[0] and "spectral ink table" in err[0], err


# ------------------------------------------------------------------------------------------- fuzzing
CELL = st.one_of(
    st.floats(-1, 200, allow_nan=False).map(lambda v: f"{v:.4g}"),
    st.sampled_from(["", "nan", "inf", "-", "1e400", "x"]),
)
KEYWORDS = st.dictionaries(
    st.sampled_from(["SPECTRAL_BANDS", "SPECTRAL_START_NM", "SPECTRAL_END_NM", "SPECTRAL_NORM"]),
    st.sampled_from(["16", "31", "36", "380", "400", "700", "730", "100", "0", "-1", "x", ""]),
    max_size=4,
)


@settings(max_examples=200, deadline=None, derandomize=True, database=None, suppress_health_check=list(HealthCheck))
@given(
    start=st.sampled_from([380, 390, 400, 410]),
    step=st.sampled_from([5, 10, 20, 3]),
    count=st.integers(1, 40),
    prefix=st.sampled_from(["SPECTRAL_NM", "SPEC_", "nm", "SPECTRAL_NM_", "R"]),
    rows=st.integers(0, 3),
    keywords=KEYWORDS,
    data=st.data(),
)
def test_fuzzed_spectral_columns(start, step, count, prefix, rows, keywords, data):
    """Spectral columns of any spelling, spacing, range, header keywords and cell values: measured reflectance
    (W,) nm evenly spaced over 400-700 nm and (P, W) in [-0.01, 1.5], band-averaged to the 20 nm grid, or one
    MeasurementError line."""
    wl = [start + step * k for k in range(count)]
    fields = ["SAMPLE_ID", *(f"{prefix}{w:03d}" for w in wl)]
    cells = [[str(i + 1), *(data.draw(CELL) for _ in wl)] for i in range(rows)]
    table = cgats.CgatsTable(fields, cells, keywords)
    try:
        got_wl, refl = measured_reflectance(table)
    except MeasurementError as exc:
        assert str(exc) and "\n" not in str(exc)
        return
    assert got_wl[0] <= 400 and got_wl[-1] >= 700 and refl.shape == (rows, len(got_wl)) and rows > 0
    assert np.all(np.isfinite(refl)) and refl.min() >= -0.01 and refl.max() <= 1.5
    out = band_average(got_wl, refl, WAVELENGTHS_20NM)
    assert out.shape == (rows, 16) and np.all(np.isfinite(out))
