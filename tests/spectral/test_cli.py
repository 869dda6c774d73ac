"""The lights on the command line: --illuminant / --illuminants refused with one line naming the flag when they need
a spectral ink table or name no light; --illuminant D65 with an RGB table is the RGB run, bit for bit; a spectral
table (--inks X@spectral, a spectral ink file) runs slab to its report under each light and resumes only under the
same lights; commands that cannot take a spectral table refuse it in one line."""

import json

import numpy as np
import pytest
from helpers import FAST_RUN
from PIL import Image

from inkopt.cli import main
from inkopt.model.spectral import load_ink_table, write_spectral_ink_file


@pytest.fixture
def picture(tmp_path):
    Image.new("RGB", (12, 8), (200, 30, 30)).save(tmp_path / "p.png")
    return str(tmp_path / "p.png")


@pytest.mark.parametrize(
    "flags,message",
    [
        (["--illuminants", "D65,A"], "--illuminants D65,A: a light other than D65 needs a spectral ink table"),
        (["--illuminant", "A"], "--illuminants A: a light other than D65 needs a spectral ink table"),
        (["--illuminant", "D93"], "--illuminant must be one of D50, D65, A, F11, LED-B3 or a .csv file"),
        (["--illuminants", "D65,D65"], "--illuminants names a light twice"),
    ],
)
def test_lights_refused_in_one_line(tmp_path, capsys, picture, flags, message):
    code = main(["slab", picture, "--size-mm", "1.5x1x0.5", "--out", str(tmp_path / "r"), *flags])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message in err[0], err
    assert not (tmp_path / "r").exists()


def test_d65_is_the_rgb_run(tmp_path, picture):
    for name, extra in (("plain", []), ("d65", ["--illuminant", "D65"])):
        args = ["slab", picture, "--size-mm", "1.5x1x0.5", "--out", str(tmp_path / name), *FAST_RUN, *extra]
        assert main(args) == 0
    a, b = (np.load(tmp_path / n / "volume.npz") for n in ("plain", "d65"))
    np.testing.assert_array_equal(a["mixture"], b["mixture"])


SPECTRAL = ["--inks", "vero-cmykw@spectral"]


def test_spectral_slab_runs_under_two_lights(tmp_path, capsys, picture):
    out = tmp_path / "r"
    args = ["slab", picture, "--size-mm", "1.5x1x0.5", "--out", str(out), *FAST_RUN, *SPECTRAL]
    assert main([*args, "--illuminants", "D65,A"]) == 0
    printed = capsys.readouterr()
    assert "figures under D65; mean ΔE2000 under each light: D65" in printed.out
    assert "the figures are under D65" in printed.err
    rep = json.loads((out / "report.json").read_text())
    v = rep["viewing"]
    assert v["colour"] == "spectral" and v["illuminants"] == ["D65", "A"] and v["headline"] == "D65"
    assert set(v["by_light"]) == {"D65", "A"} and v["worst_light"] in ("D65", "A")
    assert rep["delta_e2000_mean"] == v["by_light"]["D65"]["delta_e2000_mean"]  # the headline is the first light's
    assert set(v["inconstancy_delta_e2000_mean"]) == {"D65-A"}
    assert "stderr" not in v["by_light"]["D65"] and "inconstancy_stderr" not in v  # every texel's: no sample
    with np.load(out / "predictions.npz") as p:
        assert p["rgb_continuous"].shape == (len(np.load(out / "scene.npz")["target_rgb"]), 3)  # sRGB, as RGB runs keep
    assert main(["report", str(out)]) == 0
    capsys.readouterr()
    assert main(["render", str(out / "volume.npz"), "--spp", "1", "--json"]) == 0  # its stored RGB table, said so
    assert "is a spectral run's volume; render uses the RGB ink table" in capsys.readouterr().err
    # the lights are part of the run's identity: a resume under others is refused in one line
    capsys.readouterr()
    assert main([*args, "--illuminants", "D65", "--resume"]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]  # after the scene's log lines
    assert err.startswith("inkopt: error: ") and "different settings (viewing" in err, err


def test_a_sampled_result_gives_every_lights_figures_on_its_sample(tmp_path, picture):
    """A spectral run whose result is measured on a texel sample reports each light's figures on that sample, with
    their standard errors (not from the pictures' render of every texel)."""
    out = tmp_path / "r"
    args = ["slab", picture, "--size-mm", "1.5x1x0.5", "--out", str(out), *FAST_RUN, *SPECTRAL]
    assert main([*args, "--illuminants", "D65,A", "--figure-texel-sample", "30"]) == 0
    rep = json.loads((out / "report.json").read_text())
    v, sample = rep["viewing"], rep["texel_sample"]
    assert sample["sample"]["texels"] == 30
    for light in ("D65", "A"):
        assert v["by_light"][light]["stderr"]["delta_e2000_mean"] > 0, v["by_light"][light]
    assert rep["delta_e2000_mean"] == v["by_light"]["D65"]["delta_e2000_mean"]  # the headline: the sample's
    assert sample["stderr"] == v["by_light"]["D65"]["stderr"]
    assert v["inconstancy_stderr"]["D65-A"] > 0


def test_rgb_report_has_no_viewing(tmp_path, picture):
    out = tmp_path / "r"
    assert main(["slab", picture, "--size-mm", "1.5x1x0.5", "--out", str(out), *FAST_RUN]) == 0
    assert "viewing" not in json.loads((out / "report.json").read_text())


def test_spectral_ink_file_runs(tmp_path, picture):
    """A spectral ink file (not the library's form): the scene's RGB table is its stand-in."""
    table = load_ink_table("vero-cmykw@spectral")
    path = write_spectral_ink_file(tmp_path / "inks.json", table)
    out = tmp_path / "r"
    args = ["slab", picture, "--size-mm", "1.5x1x0.5", "--out", str(out), *FAST_RUN, "--inks", str(path)]
    assert main([*args, "--illuminant", "A"]) == 0
    assert json.loads((out / "report.json").read_text())["viewing"]["illuminants"] == ["A"]


def test_spectral_table_refused_where_not_taken(tmp_path, capsys):
    assert main(["calibration-chart", *SPECTRAL, "--out", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "calibration-chart does not take; slab and optimize do" in err[0], err


def test_rgb_table_other_light_says_spectral(tmp_path, capsys, picture):
    code = main(["slab", picture, "--size-mm", "1.5x1x0.5", "--out", str(tmp_path / "r"), "--illuminant", "A"])
    assert code == 2 and "--inks vero-cmykw@spectral" in capsys.readouterr().err


def test_combine_is_the_runs_identity_worst_by_default(tmp_path, capsys, picture):
    out = tmp_path / "r"
    args = [
        "slab",
        picture,
        "--size-mm",
        "1.5x1x0.5",
        "--out",
        str(out),
        *FAST_RUN,
        *SPECTRAL,
        "--illuminants",
        "D65,A",
    ]
    assert main(args) == 0
    assert json.loads((out / "report.json").read_text())["viewing"]["combine"] == "worst"
    capsys.readouterr()
    assert main([*args, "--combine", "mean", "--resume"]) == 2  # the mean of the lights is another run
    assert "different settings (viewing" in capsys.readouterr().err


def test_spectral_coarse_to_fine(tmp_path, picture):
    """Coarse to fine carries the viewing into both stages: each keeps the table and reports by light."""
    out = tmp_path / "r"
    args = ["slab", picture, "--size-mm", "1.5x1x0.5", "--out", str(out), *FAST_RUN, *SPECTRAL, "--illuminant", "A"]
    assert main([*args, "--coarse-dpi", "150"]) == 0
    for d in (out, out / "coarse"):
        assert json.loads((d / "report.json").read_text())["viewing"]["illuminants"] == ["A"]
        assert (d / "spectral_inks.json").is_file()
