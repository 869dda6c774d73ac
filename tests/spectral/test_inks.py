"""The run's ink tables from an ink spec (spectral.inks) and a spectral prediction shown as sRGB
(Viewing.display): a flat spectrum's RGB stand-in has equal channels, the library form keeps the library's RGB
table, a perfect white stays white under any light after the chromatic adaptation."""

import numpy as np
import pytest

from inkopt.model import InkTable
from inkopt.model.spectral import SpectralInkTable, load_ink_table
from inkopt.spectral.inks import rgb_stand_in, run_inks
from inkopt.spectral.lights import parse_lights
from inkopt.spectral.viewing import Viewing


def test_run_inks_kinds():
    rgb, table = run_inks("vero-cmykw")
    assert isinstance(rgb, InkTable) and table is None
    rgb, table = run_inks("vero-cmykw@spectral")
    base = InkTable.parse("vero-cmykw")
    np.testing.assert_array_equal(rgb.sigma_s, base.sigma_s)
    assert isinstance(table, SpectralInkTable) and table.names == base.names


def test_stand_in_of_flat_spectra_is_flat():
    wl = np.arange(400.0, 701.0, 20.0)
    s = np.outer([1.0, 3.0], np.ones(wl.size))
    table = SpectralInkTable(("white", "black"), wl, s, 0.5 * s)
    rgb = rgb_stand_in(table)
    np.testing.assert_allclose(rgb.sigma_s, [[1.0] * 3, [3.0] * 3], rtol=1e-12)
    np.testing.assert_allclose(rgb.sigma_a, 0.5 * rgb.sigma_s, rtol=1e-12)


@pytest.mark.parametrize("lights", ["D65", "A", "F11,D65", "LED-B3"])
def test_display_white_and_grey_are_neutral(lights):
    table = load_ink_table("vero-cmykw@spectral")
    v = Viewing(table, parse_lights(lights))
    shown = v.display(np.array([np.ones(table.bands), np.full(table.bands, 0.18)]))
    np.testing.assert_allclose(shown, [[1.0] * 3, [0.18] * 3], atol=2e-3)


def test_display_rgb_path_is_identity():
    x = np.random.default_rng(0).random((5, 3))
    np.testing.assert_array_equal(Viewing().display(x), x)


def test_display_matches_the_lights_colour():
    """Under D65 the shown sRGB's CIELAB is the bands' CIELAB under D65 (no adaptation but the white's Y scale)."""
    from inkopt.color import linear_to_lab

    table = load_ink_table("vero-cmykw@spectral")
    v = Viewing(table, parse_lights("D65"))
    bands = np.random.default_rng(1).uniform(0.05, 0.9, (20, table.bands))
    np.testing.assert_allclose(linear_to_lab(v.display(bands)), v.colours()[0].lab(bands), atol=0.05)
