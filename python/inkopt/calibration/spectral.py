"""Spectral calibration: fit a spectral ink table (σs and σa per wavelength band of every ink, the shared g) to
measured spectral reflectance of the chart's patches directly, band by band, with the adding-doubling model of
``calibration.stack``.

Light of different wavelengths travels independently, so a band is fitted as ``calibration.fit`` fits a channel:
the same stack, the same derivatives (:func:`fit._rgb_and_jacobian` on the table's bands in groups of three,
``SpectralInkTable.band_groups``), with the residual the relative difference of reflectance (predicted /
measured − 1: instruments' noise and the eye's sensitivity to lightness both scale with the reflectance) instead
of CIELAB. Only g couples the bands. Identifiability is the channel fit's, per band: every ink pure in at least
two patches that differ in thickness or backing (``chart.check_identifiable``); the designed chart has six
thicknesses over white and three alone per ink, which also covers bands where an ink absorbs strongly (its thin
patches over white still change with σa there).

Measurements reach the table's grid by band averaging (:func:`band_average`): the measured spectrum,
interpolated linearly onto 1 nm, averaged over each band (halfway to the neighbouring band centres, within the
measured range).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..model import InkTable
from ..model.spectral import SpectralInkTable, band_edges
from .chart import Chart, start_table
from .fit import G_BOUNDS, SIGMA_BOUNDS, _rgb_and_jacobian, predict_rgb, solve
from .stack import one_blas_thread


@dataclass
class SpectralFitResult:
    """A fitted spectral table: ``inks`` (chart order), ``predicted`` (P, B) reflectance of the fitted patches on
    the table's bands, ``iterations`` (model evaluations with derivatives), ``seconds``, ``cost`` (half the sum
    of squared relative residuals), ``converged`` and the optimiser's ``message``."""

    inks: SpectralInkTable
    predicted: np.ndarray
    iterations: int
    seconds: float
    cost: float
    converged: bool
    message: str


def band_average(wavelengths_nm, reflectance, grid_nm) -> np.ndarray:
    """Measured reflectance (P, W) at ``wavelengths_nm`` (W,) -> (P, B) on the band grid ``grid_nm`` (B,): each
    band's mean of the spectrum interpolated linearly onto 1 nm over the band (``model.spectral.band_edges``),
    over its measured part where the band reaches beyond the measured range (400-700 nm measured: the first and
    last 20 nm bands average 400-410 and 690-700 nm). ValueError for a band centre outside the measured range."""
    wl = np.asarray(wavelengths_nm, np.float64)
    refl = np.atleast_2d(np.asarray(reflectance, np.float64))
    grid = np.asarray(grid_nm, np.float64)
    if grid[0] < wl[0] - 1e-6 or grid[-1] > wl[-1] + 1e-6:
        raise ValueError(
            f"the table's bands {grid[0]:g}-{grid[-1]:g} nm lie beyond the measured {wl[0]:g}-{wl[-1]:g} nm"
        )
    lo, hi = band_edges(grid)
    lo, hi = np.maximum(lo, wl[0]), np.minimum(hi, wl[-1])
    out = np.empty((refl.shape[0], len(lo)))
    for b, (a, z) in enumerate(zip(lo, hi)):
        pts = np.linspace(a, z, max(2, int(np.ceil(z - a)) + 1))
        out[:, b] = np.stack([np.interp(pts, wl, r) for r in refl]).mean(axis=1)
    return out


def spectral_start(chart: Chart, start: InkTable | SpectralInkTable, grid_nm) -> SpectralInkTable:
    """The starting spectral table in the chart's ink order on ``grid_nm``: a spectral ``start`` resampled
    (inks it lacks from the ink library's spectral form), an RGB one in its spectral form (``from_rgb``)."""
    grid = np.asarray(grid_nm, np.float64)
    if isinstance(start, InkTable):
        return SpectralInkTable.from_rgb(start_table(chart, start), grid)
    spec = start.resampled(grid)
    missing = tuple(n for n in chart.inks if n not in spec.names)
    lib = spec
    if missing:
        lib = SpectralInkTable.from_rgb(start_table(Chart(missing, []), InkTable.from_names(["white"], start.g)), grid)
    rows = [(spec, spec.index(n)) if n in spec.names else (lib, lib.index(n)) for n in chart.inks]
    s = np.stack([t.sigma_s[k] for t, k in rows])
    a = np.stack([t.sigma_a[k] for t, k in rows])
    return SpectralInkTable(chart.inks, grid, s, a, start.g)


@one_blas_thread
def predict_reflectance(chart: Chart, inks: SpectralInkTable) -> np.ndarray:
    """(P, B) float64 reflectance of every patch of ``chart`` on the bands of ``inks`` (chart order)."""
    out = np.empty((len(chart), inks.bands))
    for group, bands in zip(inks.band_groups(), inks.group_bands()):
        out[:, list(bands)] = predict_rgb(chart, group)[:, : len(bands)]
    return out


@one_blas_thread
def _reflectance_and_jacobian(chart: Chart, inks: SpectralInkTable):
    """(P, B) reflectance and its derivatives (P, B, K) with respect to x = [log σs (N, B), log σa (N, B), g]
    flattened (σs block first, each in (ink, band) C order): each group of three bands by the channel fit's
    ``_rgb_and_jacobian``, its columns put where the group's bands sit."""
    n, nb = len(inks), inks.bands
    refl = np.empty((len(chart), nb))
    jac = np.zeros((len(chart), nb, 2 * n * nb + 1))
    ink = np.arange(n)
    for group, bands in zip(inks.band_groups(), inks.group_bands()):
        rgb, jg = _rgb_and_jacobian(chart, group)
        for c, b in enumerate(bands):
            refl[:, b] = rgb[:, c]
            jac[:, b, ink * nb + b] = jg[:, c, ink * 3 + c]
            jac[:, b, n * nb + ink * nb + b] = jg[:, c, 3 * n + ink * 3 + c]
            jac[:, b, -1] = jg[:, c, -1]
    return refl, jac


def _to_x(inks: SpectralInkTable) -> np.ndarray:
    lo, hi = SIGMA_BOUNDS
    s, a = np.clip(inks.sigma_s, lo, hi), np.clip(inks.sigma_a, lo, hi)
    return np.concatenate([np.log(s).ravel(), np.log(a).ravel(), [np.clip(inks.g, *G_BOUNDS)]])


def _from_x(x: np.ndarray, names, wavelengths_nm) -> SpectralInkTable:
    n, nb = len(names), len(wavelengths_nm)
    s = np.exp(x[: n * nb]).reshape(n, nb)
    a = np.exp(x[n * nb : 2 * n * nb]).reshape(n, nb)
    return SpectralInkTable(tuple(names), wavelengths_nm, s, a, float(x[-1]))


def fit_spectral_inks(
    chart: Chart, measured: np.ndarray, start: SpectralInkTable, max_iterations: int = 60, fit_g: bool = True
) -> SpectralFitResult:
    """Fit ``start`` (chart order, its bands the grid) to ``measured`` (P, B) reflectance of ``chart``'s patches
    on that grid (:func:`band_average`), minimising the squared relative differences over every ink's log σs and
    log σa per band and g (trust-region least squares with bounds). ``fit_g=False`` keeps g at the start's."""

    measured = np.asarray(measured, np.float64)
    if measured.shape != (len(chart), start.bands):
        raise ValueError(f"measured reflectance must be ({len(chart)}, {start.bands}), got {measured.shape}")
    weight = 1.0 / np.maximum(measured, 1e-3)
    t0 = time.perf_counter()
    names, wl = chart.inks, start.wavelengths_nm

    def model(x):
        refl, jac = _reflectance_and_jacobian(chart, _from_x(x, names, wl))
        return ((refl - measured) * weight).ravel(), (jac * weight[..., None]).reshape(-1, jac.shape[-1])

    res, evaluations = solve(model, _to_x(start), fit_g, max_iterations)
    inks = _from_x(res.x, names, wl)
    predicted = predict_reflectance(chart, inks)
    seconds = time.perf_counter() - t0
    return SpectralFitResult(inks, predicted, evaluations, seconds, float(res.cost), res.status > 0, res.message)


def spectral_form(inks: InkTable, grid_nm, chart: Chart | None = None, max_iterations: int = 40) -> SpectralFitResult:
    """Spectra for an RGB table that reproduce its colours: every patch of ``chart`` (default: the calibration
    chart of ``inks``, ``chart.design_chart``; its inks must be the table's, in its order) predicted by the RGB
    table (linear RGB reflectance), upsampled to a reflectance spectrum on ``grid_nm`` (B,) with the
    Mallett-Yuksel basis (``model.spectral.rgb_basis``: its colour under D65 is that RGB), and a spectral table
    fitted to those spectra band by band (:func:`fit_spectral_inks`, g kept), starting from the table's linear
    spectral form (``SpectralInkTable.from_rgb``)."""
    from ..model.spectral import rgb_basis
    from .chart import design_chart

    chart = design_chart(inks.names) if chart is None else chart
    if tuple(chart.inks) != tuple(inks.names):
        raise ValueError(f"the chart's inks {list(chart.inks)} are not the table's {list(inks.names)}")
    grid = np.asarray(grid_nm, np.float64)
    target = predict_rgb(chart, inks) @ rgb_basis(grid)
    return fit_spectral_inks(chart, target, SpectralInkTable.from_rgb(inks, grid), max_iterations, fit_g=False)
