"""The lights on the command line: --illuminant / --illuminants refused with one line naming the flag when they need
a spectral ink table or name no light; --illuminant D65 with an RGB table is the RGB run, bit for bit."""

import numpy as np
import pytest
from helpers import FAST_RUN
from PIL import Image

from inkopt.cli import main


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
