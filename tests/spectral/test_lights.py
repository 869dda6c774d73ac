"""Lights and colour under them (inkopt.spectral.lights): band matrices against colour-science's sd_to_XYZ, the white
at Y = 1, light files read as hostile input (fuzzed), and the RGB colour map equal to the sRGB functions."""

import warnings

import colour
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from inkopt.color import RGB, RGB_TO_XYZ, WHITE_XYZ, ColourMap, linear_to_lab, xyz_to_lab
from inkopt.errors import ParameterError
from inkopt.spectral.lights import NAMED, Light, load_light, named_light, parse_lights

CMFS = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
GRIDS = [np.arange(400.0, 701.0, 10.0), np.linspace(400.0, 700.0, 16)]


def reflectances(wl: np.ndarray, n: int = 6) -> np.ndarray:
    """n smooth reflectance spectra (n, B) on ``wl``: Gaussian bumps and a sigmoid over a floor."""
    rng = np.random.default_rng(3)
    out = [0.05 + 0.9 / (1.0 + np.exp(-(wl - 560.0) / 25.0))]
    for _ in range(n - 1):
        c, w = rng.uniform(420.0, 680.0), rng.uniform(25.0, 120.0)
        out.append(0.08 + 0.85 * np.exp(-0.5 * ((wl - c) / w) ** 2))
    return np.array(out)


@pytest.mark.parametrize("name", list(NAMED))
@pytest.mark.parametrize("grid", range(len(GRIDS)))
def test_band_matrix_equals_colour_science(name, grid):
    wl = GRIDS[grid]
    cmap = named_light(name).colour_map(wl)
    illuminant = colour.SDS_ILLUMINANTS[NAMED[name]]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # colour-science warns that it aligns the shapes
        for r in reflectances(wl):
            ref = colour.sd_to_XYZ(colour.SpectralDistribution(r, wl), CMFS, illuminant, method="Integration") / 100
            assert np.abs(cmap.xyz(r) - ref).max() < 1e-3


@pytest.mark.parametrize("name", list(NAMED))
def test_white_is_y1_and_lab_100(name):
    cmap = named_light(name).colour_map(GRIDS[1])
    white = cmap.xyz(np.ones(16))
    assert white[1] == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(cmap.lab(np.ones(16)), [100.0, 0.0, 0.0], atol=1e-9)
    # a grey reflector is grey under every light (the viewer is adapted to it)
    lab = cmap.lab(np.full(16, 0.2))
    assert abs(lab[1]) < 1e-9 and abs(lab[2]) < 1e-9


def test_lights_differ_on_a_coloured_spectrum():
    wl = GRIDS[0]
    r = reflectances(wl)[1]
    labs = [named_light(n).colour_map(wl).lab(r) for n in ("D65", "A")]
    assert np.linalg.norm(labs[0] - labs[1]) > 0.5  # the same reflectance looks different under A (no adaptation)


def test_rgb_map_is_the_srgb_functions():
    rng = np.random.default_rng(0)
    rgb = rng.uniform(0.0, 1.0, (50, 3))
    np.testing.assert_array_equal(RGB.white, WHITE_XYZ)
    np.testing.assert_array_equal(RGB.lab(rgb), xyz_to_lab(rgb @ RGB_TO_XYZ.T))
    np.testing.assert_array_equal(linear_to_lab(rgb), RGB.lab(rgb))


def test_colour_map_jacobian_and_vjp_match_differences():
    cmap = named_light("A").colour_map(GRIDS[1])
    rng = np.random.default_rng(1)
    r = rng.uniform(0.05, 0.9, 16)
    jac = cmap.lab_jacobian(r)
    h = 1e-6
    num = np.stack([(cmap.lab(r + h * e) - cmap.lab(r - h * e)) / (2 * h) for e in np.eye(16)], axis=1)
    np.testing.assert_allclose(jac, num, rtol=1e-5, atol=1e-6)
    g = rng.normal(size=3)
    np.testing.assert_allclose(cmap.lab_vjp(r, g), g @ jac, rtol=1e-12, atol=1e-12)


def test_colour_map_checks_shapes():
    with pytest.raises(ValueError, match=r"\(3, C\)"):
        ColourMap(np.ones((2, 4)))
    with pytest.raises(ValueError, match=r"\(\.\.\., 16\)"):
        named_light("D65").colour_map(GRIDS[1]).lab(np.ones(3))


def test_light_file_and_lists(tmp_path):
    f = tmp_path / "lamp.csv"
    f.write_text("nm,power\n# a flat lamp\n380, 1\n780, 1\n")
    light = load_light(f)
    assert light.name == "lamp.csv"
    flat = light.colour_map(GRIDS[0])
    assert flat.xyz(np.ones(31))[1] == pytest.approx(1.0)
    # a flat lamp is colour-science's equal-energy light E within its rows (380-780 nm)
    e = Light("E", np.array([380.0, 780.0]), np.array([1.0, 1.0])).colour_map(GRIDS[0])
    np.testing.assert_array_equal(flat.matrix, e.matrix)
    assert [x.name for x in parse_lights(f"D65,A,{f}")] == ["D65", "A", "lamp.csv"]
    for bad in ("D65,D65", "D65,,A", "D93"):
        with pytest.raises(ParameterError, match="illuminant"):
            parse_lights(bad)


BAD_FILES = [
    b"",
    b"nm,power\n",
    b"400,1\n",
    b"400,1\n390,1\n",
    b"400,1\n500,-1\n",
    b"400,0\n500,0\n",
    b"400,1\n500,nan\n",
    b"400,1\n500,inf\n",
    b"400,1,2\n500,1\n",
    b"400,1\nx,y\n",
    b"100,1\n500,1\n",
    b"\xff\xfe\x00garbage",
    b"400,1\n" * 20_000,
]


@pytest.mark.parametrize("raw", BAD_FILES, ids=range(len(BAD_FILES)))
def test_bad_light_files_give_one_clean_error(tmp_path, raw):
    f = tmp_path / "bad.csv"
    f.write_bytes(raw)
    with pytest.raises(ParameterError) as err:
        load_light(f)
    assert "`illuminant`" in err.value.template and "\n" not in str(err.value)


def test_missing_and_too_big_files(tmp_path):
    with pytest.raises(ParameterError, match="cannot read"):
        load_light(tmp_path / "none.csv")
    big = tmp_path / "big.csv"
    big.write_bytes(b"#" * (2 << 20))
    with pytest.raises(ParameterError, match="larger than"):
        load_light(big)


@settings(max_examples=150, derandomize=True, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.binary(max_size=400) | st.text(alphabet="0123456789.,;-e \n#nmaIf", max_size=200).map(str.encode))
def test_fuzzed_light_files(tmp_path_factory, raw):
    f = tmp_path_factory.mktemp("fuzz") / "light.csv"
    f.write_bytes(raw)
    try:
        light = load_light(f)
    except ParameterError as exc:
        assert "\n" not in str(exc)
        return
    try:
        cmap = light.colour_map(GRIDS[1])
    except ParameterError as exc:  # power only outside 360-830 nm
        assert "illuminant" in str(exc)
        return
    assert np.all(np.isfinite(cmap.matrix)) and cmap.white[1] == pytest.approx(1.0)
