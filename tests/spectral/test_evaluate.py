"""``inkopt evaluate`` of a spectral run: its continuous result, printed result and baselines under each light
(evaluation.spectral), the continuous one's figures the same as the run's own at the same seed and samples, other
lights on request, pictures under the first light; an RGB run asked for other lights is refused in one line."""

import json

import pytest
from helpers import FAST_RUN
from PIL import Image

from inkopt.cli import main


@pytest.fixture(scope="module")
def spectral_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("spectral_eval")
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
        assert ev[r]["method"] == "blue-noise" and ev[r]["spp_printer"] >= 1
        assert set(ev[r]["by_light"]) == {"D65", "A"} and set(ev[r]["inconstancy_delta_e2000_mean"]) == {"D65-A"}
        for m in ev[r]["by_light"].values():
            assert 0 < m["delta_e2000_mean"] < 100 and 0 < m["ssim"] <= 1
    assert ev["quantized_digest"] is not None and (spectral_run / "quantized.npz").is_file()
    assert ev["quantization"]["method"] == "blue-noise" and ev["printer_texels"] > 0
    assert set(ev["print_beats_baselines"]) == {"D65", "A"}


def test_evaluate_without_baselines_and_refuses_a_texel_sample(spectral_run, capsys):
    assert main(["evaluate", str(spectral_run), "--spp", "2", "--no-baselines", "--threads", "2", "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)
    assert "quantized" in ev and "surface" not in ev and ev["print_beats_baselines"] == {}
    assert main(["evaluate", str(spectral_run), "--spp", "2", "--texel-sample", "50"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--texel-sample" in err[0] and "every texel" in err[0], err


def test_rgb_run_refuses_other_lights(tmp_path, capsys):
    Image.new("RGB", (12, 8), (40, 160, 90)).save(tmp_path / "p.png")
    out = tmp_path / "r"
    assert main(["slab", str(tmp_path / "p.png"), "--size-mm", "1.5x1x0.5", "--out", str(out), *FAST_RUN]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(out), "--illuminants", "D65,A"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is an RGB run" in err[0] and "--inks vero-cmykw@spectral" in err[0], err
