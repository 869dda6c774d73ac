"""``inkopt calibrate --illuminant`` with spectral measurements: any light of ``spectral.lights`` (A, F11, LED-B3, a
FILE.csv) integrates them as colour-science does, a perfect white is L* 100 under each, a light file keeps its path
in the report; CIELAB measurements stay under D50 or D65 (another light is one line naming --illuminant)."""

import warnings

import numpy as np
import pytest

from inkopt.calibration import cgats
from inkopt.calibration.chart import chart_from_table
from inkopt.calibration.measure import OBSERVER, illuminant_name, rgb_to_lab, spectral_to_lab, white_xy
from inkopt.calibration.report import CalibrationReport
from inkopt.calibration.spectral import predict_reflectance, spectral_start
from inkopt.cli import main
from inkopt.model.spectral import WAVELENGTHS_20NM, load_ink_table

pytest.importorskip("iadpython")
WL = np.arange(380.0, 731.0, 10.0)


def _colour():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    return colour


def _spectra(n=6, seed=0):
    rng = np.random.default_rng(seed)
    return np.clip(0.5 + 0.4 * np.sin(np.outer(rng.uniform(0.5, 3, n), WL / 100) + rng.uniform(0, 6, (n, 1))), 0, 1)


@pytest.mark.parametrize("name, table", [("A", "A"), ("F11", "FL11"), ("LED-B3", "LED-B3")])
def test_named_lights_integrate_as_colour_science(name, table):
    """CIELAB of reflectance under a named light: colour-science's sd_to_XYZ with its own table and the white of a
    perfect reflector under it (the light on a 1 nm grid: within 0.02 ΔE76); a flat 1 is L* 100, a* = b* = 0."""
    colour = _colour()
    refl = _spectra()
    got = spectral_to_lab(WL, refl, name.lower())
    cmfs, ill = colour.MSDS_CMFS[OBSERVER], colour.SDS_ILLUMINANTS[table]
    white = colour.XYZ_to_xy(colour.sd_to_XYZ(colour.SpectralDistribution(dict(zip(WL, np.ones(len(WL))))), cmfs, ill))
    for r, lab in zip(refl, got):
        xyz = colour.sd_to_XYZ(colour.SpectralDistribution(dict(zip(WL, r))), cmfs, ill) / 100
        assert np.abs(colour.XYZ_to_Lab(xyz, white) - lab).max() < 0.02
    np.testing.assert_allclose(spectral_to_lab(WL, np.ones((1, len(WL))), name)[0], [100, 0, 0], atol=0.02)
    np.testing.assert_allclose(rgb_to_lab(np.ones(3), name), [100, 0, 0], atol=1e-6)  # sRGB white, adapted
    assert illuminant_name(name.lower()) == name


def test_light_file_is_a_light(tmp_path):
    """A FILE.csv with D65's power at 5 nm: the colours of D65 (its tabulated white against the integrated one:
    within 0.05 ΔE76); its name is the path as given."""
    colour = _colour()
    d65 = colour.SDS_ILLUMINANTS["D65"]
    path = tmp_path / "my light.csv"
    path.write_text("".join(f"{w:g},{p:.6f}\n" for w, p in zip(d65.wavelengths, d65.values) if 360 <= w <= 830))
    refl = _spectra(seed=3)
    np.testing.assert_allclose(spectral_to_lab(WL, refl, str(path)), spectral_to_lab(WL, refl, "D65"), atol=0.05)
    np.testing.assert_allclose(white_xy(str(path)), white_xy("D65"), atol=2e-4)
    assert illuminant_name(str(path)) == str(path)


def _spectral_chart(d):
    """The cyan + white chart with 10 nm spectra of the library's spectral cyan and white (the start of the fit:
    it converges at once)."""
    assert main(["calibration-chart", "--inks", "cyan,white", "--out", str(d), "--patch-mm", "3"]) == 0
    table = cgats.read(d / "chart.txt")
    chart = chart_from_table(table)
    truth = spectral_start(chart, load_ink_table("cyan,white"), WAVELENGTHS_20NM)
    refl = np.stack([np.interp(WL, WAVELENGTHS_20NM, r) for r in predict_reflectance(chart, truth)])
    n = len(table.fields) - 3
    table.fields = table.fields[:n] + [f"SPECTRAL_NM{w:.0f}" for w in WL]
    table.rows = [r[:n] + [float(round(100 * v, 4)) for v in refl[k]] for k, r in enumerate(table.rows)]
    cgats.write(d / "spectral.txt", table)
    return d / "spectral.txt"


def test_calibrate_under_a_light_file(tmp_path, capsys, monkeypatch):
    """Spectral measurements calibrated under a light file: the report names it by its path and its figures are
    under it; CIELAB columns under A, or an unknown light, are refused in one line naming --illuminant. (The fit
    is capped at 2 evaluations: it starts at the measured model, and the fit itself is tested elsewhere.)"""
    import functools

    from inkopt.calibration import spectral

    monkeypatch.setattr(spectral, "fit_spectral_inks", functools.partial(spectral.fit_spectral_inks, max_iterations=2))
    measured = _spectral_chart(tmp_path)
    light = tmp_path / "Lamp.csv"
    light.write_text("".join(f"{w},{1 + w / 500:.4f}\n" for w in range(360, 831, 10)))
    out = tmp_path / "inks.json"
    args = ["calibrate", str(measured), "--out", str(out), "--illuminant", str(light), "--holdout", "0", "--fixed-g"]
    assert main(args) == 0, capsys.readouterr().err
    rep = CalibrationReport.from_json(tmp_path / "inks.report.json")
    assert rep.illuminant == str(light) and rep.measurement_kind == "spectral" and rep.fit_mean_delta_e2000 < 0.5
    table = cgats.read(measured)
    want = spectral_to_lab(WL, np.array([[float(v) / 100 for v in r[-len(WL) :]] for r in table.rows]), str(light))
    np.testing.assert_allclose([p.measured_lab for p in rep.patches], want, atol=1e-9)
    lab_file = tmp_path / "lab.txt"
    table = cgats.read(tmp_path / "chart.txt")
    table.rows = [r[:-3] + [50.0, 0.0, 0.0] for r in table.rows]
    cgats.write(lab_file, table)
    capsys.readouterr()
    assert main(["calibrate", str(lab_file), "--out", str(tmp_path / "x.json"), "--illuminant", "A"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--illuminant" in err[0] and "spectral measurements" in err[0], err
    assert main(["calibrate", str(measured), "--out", str(tmp_path / "y.json"), "--illuminant", "F2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--illuminant" in err[0] and "LED-B3" in err[0], err
