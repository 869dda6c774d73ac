"""Spectral ink tables for the tests of inkopt.spectral (tests/spectral/): made-up spectra, not calibrations."""

import numpy as np

from inkopt.model import InkTable
from inkopt.model.spectral import SpectralInkTable

INKS = InkTable.parse("vero-cmykw")


def rgb_as_bands(inks: InkTable, repeat: int = 1) -> SpectralInkTable:
    """The RGB table as a band table, each channel ``repeat`` bands wide, bands in wavelength order (B, G, R)."""
    order = np.repeat([2, 1, 0], repeat)
    wl = np.linspace(400.0, 700.0, 3 * repeat)
    return SpectralInkTable(inks.names, wl, inks.sigma_s[:, order], inks.sigma_a[:, order], inks.g)


def smooth_table() -> SpectralInkTable:
    """Six bands of made-up smooth spectra for the five Vero inks (an assumption of the test, not a calibration)."""
    wl = np.linspace(410.0, 690.0, 6)
    x = (wl - 400.0) / 300.0
    flat = np.ones_like(x)
    bump = np.sin(np.pi * x) ** 2
    sigma_a = np.array([0.2 + 3.0 * x**2, 0.3 + 3.0 * bump, 3.0 * (1 - x) ** 2 + 0.1, 4.0 * flat, 0.02 * flat])
    sigma_s = np.array([1.0 + x, 1.2 * flat, 1.5 - x, 0.5 * flat, 8.0 - 2.0 * x])
    return SpectralInkTable(INKS.names, wl, sigma_s, sigma_a, INKS.g)
