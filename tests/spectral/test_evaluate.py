"""``inkopt evaluate`` of a spectral run: its continuous result, printed result and baselines under each light
(evaluation.spectral), the continuous one's figures the same as the run's own at the same seed and samples, other
lights on request, pictures under the first light; an RGB run asked for other lights is refused in one line."""

import json

import numpy as np
import pytest
from helpers import FAST_RUN
from PIL import Image

from inkopt.cli import main


@pytest.fixture(scope="module", autouse=True)
def small_spectral_table(tmp_path_factory):
    """The baselines' spectral colour table on a coarse lattice (step 1/2) with a 1 ΔE76 error target, cached for
    the module: the default one's build takes minutes (evaluation.spectral_table)."""
    from functools import partial

    from inkopt.evaluation import spectral as es

    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("INKOPT_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))
        mp.setattr(es, "spectral_patches", partial(es.spectral_patches, step=2, max_stderr=1.0))
        yield


@pytest.fixture(scope="module")
def spectral_run(tmp_path_factory):
    return make_spectral_run(tmp_path_factory.mktemp("spectral_eval"))


def make_spectral_run(tmp):
    Image.new("RGB", (12, 8), (40, 160, 90)).save(tmp / "p.png")
    out = tmp / "r"
    args = ["slab", str(tmp / "p.png"), "--size-mm", "1.5x1x0.5", "--out", str(out), *FAST_RUN]
    assert main([*args, "--inks", "vero-cmykw@spectral", "--illuminants", "D65,A"]) == 0
    return out


def test_evaluate_repeats_the_runs_figures(spectral_run, capsys):
    """The run's figures (seed 2**62, 4 spp, FAST_RUN) and evaluate's at the same seed and spp are one render."""
    capsys.readouterr()
    assert main(["evaluate", str(spectral_run), "--spp", "4", "--threads", "2", "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)
    rep = json.loads((spectral_run / "report.json").read_text())["viewing"]
    assert ev["viewing"]["illuminants"] == ["D65", "A"] and ev["continuous"]["spp"] == 4
    for light in ("D65", "A"):
        assert ev["continuous"]["by_light"][light] == rep["by_light"][light]
    assert json.loads((spectral_run / "evaluation_lights.json").read_text())["continuous"] == ev["continuous"]
    assert (spectral_run / "evaluation_lights_top.png").is_file()


def test_evaluate_under_other_lights(spectral_run, capsys):
    assert main(["evaluate", str(spectral_run), "--spp", "8", "--illuminants", "F11,D65", "--threads", "2"]) == 0
    out = capsys.readouterr().out
    assert "figures under F11; mean ΔE2000 under each light: F11" in out and "colour inconstancy F11-D65" in out
    assert "quantized: figures under F11" in out and "extrusion: figures under F11" in out
    assert "under each light: F11 " in out and "(colour table: spectral, looked up under D65,A)" in out
    ev = json.loads((spectral_run / "evaluation_lights.json").read_text())
    for light in ("F11", "D65"):
        won = ev["print_beats_baselines"][light]
        q = ev["quantized"]["by_light"][light]["delta_e2000_mean"]
        for b in ("surface", "extrusion"):
            assert won[b] == (q < ev[b]["by_light"][light]["delta_e2000_mean"])
            assert f"{'beats' if won[b] else 'does not beat'} {b} (" in out


def test_evaluate_judges_the_print_and_the_baselines(spectral_run, capsys):
    """Every result under each light with the continuous one's keys, its colour inconstancy, the printed results'
    method and printer samples; the printed ones come from quantized.npz (made first)."""
    assert main(["evaluate", str(spectral_run), "--spp", "4", "--threads", "2", "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)
    keys = set(ev["continuous"])
    for r in ("quantized", "surface", "extrusion"):
        assert set(ev[r]) == keys | {"method", "spp_printer"}, r
        assert ev[r]["method"] == "count-adaptive" and ev[r]["spp_printer"] >= 1
        assert set(ev[r]["by_light"]) == {"D65", "A"} and set(ev[r]["inconstancy_delta_e2000_mean"]) == {"D65-A"}
        for m in ev[r]["by_light"].values():
            assert 0 < m["delta_e2000_mean"] < 100 and 0 < m["ssim"] <= 1
    assert ev["quantized_digest"] is not None and (spectral_run / "quantized.npz").is_file()
    assert ev["quantization"]["method"] == "count-adaptive" and ev["printer_texels"] > 0
    assert set(ev["print_beats_baselines"]) == {"D65", "A"}
    # the baselines' mixtures come from the spectral colour table under the run's lights; the gamut floor per light
    assert ev["colour_table"]["spectral"] and ev["colour_table"]["lights"] == ["D65", "A"]
    assert ev["colour_table"]["step"] == 2 and set(ev["gamut_floor"]) == {"D65", "A"}
    for floor in ev["gamut_floor"].values():
        assert 0 <= floor["delta_e76_mean"] <= floor["delta_e76_p95"] + 1e-9  # a flat target: mean = p95


def test_evaluate_without_baselines(spectral_run, capsys):
    assert main(["evaluate", str(spectral_run), "--spp", "2", "--no-baselines", "--threads", "2", "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)
    assert "quantized" in ev and "surface" not in ev and ev["print_beats_baselines"] == {}


def test_texel_sample_agrees_with_every_texel(tmp_path, capsys):
    """A texel sample (120 of 384 texels, 30 SSIM windows) under each light: every figure with its standard error,
    the paired differences per light, and the mean ΔE2000 of each result within 4 standard errors of the
    every-texel evaluation's at the same samples (the sample's texels are rendered with other random numbers, so the
    render noise adds its own spread: the tolerance also takes the noise's contribution); no predictions written."""
    run = make_spectral_run(tmp_path)
    capsys.readouterr()
    before = (run / "predictions.npz").read_bytes()
    args = ["evaluate", str(run), "--spp", "16", "--threads", "2", "--json"]
    assert main([*args[:-1], "--texel-sample", "120", "--sample-windows", "30"]) == 0
    out = capsys.readouterr().out
    assert "under A: the print" in out and "paired difference" in out
    sampled = json.loads((run / "evaluation_lights.json").read_text())
    assert (run / "predictions.npz").read_bytes() == before
    assert sampled["texel_sample"]["texels"] == 120 and sampled["sampling_choice"]["forced"]
    assert set(sampled["differences"]) == {"D65", "A"} and "quantized - extrusion" in sampled["differences"]["A"]
    _check_sample_predictions(run, sampled)
    assert main(args) == 0
    full = json.loads(capsys.readouterr().out)
    assert "texel_sample" not in full and not (run / "predictions_sample.npz").exists()
    for r in ("continuous", "quantized", "surface", "extrusion"):
        assert sampled[r]["inconstancy_stderr"]["D65-A"] > 0
        for light in ("D65", "A"):
            got, want = sampled[r]["by_light"][light], full[r]["by_light"][light]
            se = got["stderr"]["delta_e2000_mean"]
            assert (
                se > 0
                and abs(got["delta_e2000_mean"] - want["delta_e2000_mean"])
                < 4 * se + 2 * want["delta_e76_noise_contribution"]
            ), (r, light, got["delta_e2000_mean"], want["delta_e2000_mean"], se)


def _check_sample_predictions(run, sampled: dict) -> None:
    """predictions_sample.npz of a sampled evaluation: every result's band values on the sample's 120 points (sorted
    scene texel indices), from which each light's mean ΔE2000 is the evaluation's (float32 storage)."""
    from inkopt.color import ColourMap, delta_e2000, linear_to_lab
    from inkopt.rundir import RunDir

    d = RunDir(run)
    pred = d.load_sample_predictions()
    assert pred is not None and pred.source == "evaluation" and len(pred.texels) == 120
    assert np.all(np.diff(pred.texels) > 0) and set(pred.bands.values) == {"continuous", "quantized", *BASELINE_NAMES}
    target_lab = linear_to_lab(d.load_scene().target_rgb.astype(np.float64))[pred.texels]
    for name, values in pred.bands.values.items():
        assert values.shape == (120, 16) and pred.rgb[name].shape == (120, 3)
        for light, m in pred.bands.lights.items():
            de = delta_e2000(ColourMap(m, light).lab(values), target_lab).mean()
            assert de == pytest.approx(sampled[name]["by_light"][light]["delta_e2000_mean"], abs=1e-3), (name, light)


BASELINE_NAMES = ("surface", "extrusion")


def test_predictions_keep_the_band_values(tmp_path, capsys):
    """predictions.npz of a spectral run holds every result's band values and the lights' band matrices: each
    result's sRGB is its bands under the first light, and its ΔE2000 under each light recomputed from the stored
    bands is evaluate's (float32 storage)."""
    from inkopt.color import ColourMap, delta_e2000, linear_to_lab
    from inkopt.rundir import RunDir
    from inkopt.spectral.lights import named_light
    from inkopt.spectral.viewing import display_under

    spectral_run = make_spectral_run(tmp_path)
    d = RunDir(spectral_run)
    run_pred = d.load_predictions()
    assert run_pred.source == "optimisation" and set(run_pred.bands.values) == {"continuous"}
    capsys.readouterr()
    assert main(["evaluate", str(spectral_run), "--spp", "4", "--threads", "2", "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)
    pred = d.load_predictions()
    b = pred.bands
    assert pred.source == "evaluation" and set(b.values) == set(pred.rgb) == {
        "continuous",
        "quantized",
        "surface",
        "extrusion",
    }
    assert list(b.lights) == ["D65", "A"] and b.wavelengths_nm.shape == (16,)
    np.testing.assert_allclose(b.lights["A"], named_light("A").colour_map(b.wavelengths_nm).matrix)
    target_lab = linear_to_lab(d.load_scene().target_rgb.astype(np.float64))
    for name, values in b.values.items():
        assert values.dtype == np.float32 and values.shape == (len(target_lab), 16)
        d65 = ColourMap(b.lights["D65"], "D65")
        np.testing.assert_allclose(pred.rgb[name], display_under(d65, values), rtol=1e-5, atol=1e-6)
        for light, m in b.lights.items():
            de = delta_e2000(ColourMap(m, light).lab(values), target_lab).mean()
            assert de == pytest.approx(ev[name]["by_light"][light]["delta_e2000_mean"], abs=1e-3)


def test_rgb_predictions_stay_version_1(tmp_path):
    """A predictions file without band values is written as before (version 1, the same arrays); a damaged band
    block is one line naming the file."""
    from inkopt.io import FORMAT_KEY
    from inkopt.rundir import BandValues, Predictions

    rgb = {"continuous": np.zeros((5, 3), np.float32)}
    arrays = Predictions(rgb, "evaluation", {"continuous": 4}, "abc", {"lighting": "uniform"}).arrays()
    assert int(arrays[FORMAT_KEY]) == 1
    assert set(arrays) == {FORMAT_KEY, "names", "source", "volume_digest", "lighting", "spp", "rgb_continuous"}
    bands = BandValues({"continuous": np.ones((5, 4), np.float32)}, np.arange(4.0), {"D65": np.ones((3, 4))})
    full = Predictions(rgb, "evaluation", {"continuous": 4}, "abc", {}, bands).arrays()
    assert int(full[FORMAT_KEY]) == 2
    back = Predictions.from_arrays(full)
    np.testing.assert_array_equal(back.bands.values["continuous"], 1.0)
    assert Predictions.from_arrays(arrays).bands is None
    for broken in ({"light_matrices": np.ones((1, 3, 5))}, {"bands_continuous": np.ones((5, 3))}):
        with pytest.raises(ValueError, match="predictions.npz"):
            Predictions.from_arrays({**full, **broken})
    short = dict(full)
    del short["bands_continuous"]
    with pytest.raises(ValueError, match="lacks bands_continuous"):
        Predictions.from_arrays(short)
