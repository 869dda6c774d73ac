"""Spectral ink tables for the tests of inkopt.spectral (tests/spectral/): made-up spectra, not calibrations."""

import numpy as np

from inkopt.model import InkTable, Volume
from inkopt.model.spectral import SpectralInkTable

INKS = InkTable.parse("vero-cmykw")
VOX = 0.0847  # mm: a 300-DPI voxel


def random_volume(shape=(6, 7, 8), seed=0) -> Volume:
    """A volume of random mixtures (Dirichlet) of ``INKS``, ``shape`` voxels of ``VOX`` mm."""
    rng = np.random.default_rng(seed)
    m = rng.dirichlet(np.ones(len(INKS)), size=shape).astype(np.float32)
    return Volume.from_mixture(voxel_mm=(VOX,) * 3, mixture=m, inks=INKS)


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
