"""Fit an ink table to measured patches: least squares on the patches' CIELAB differences (ΔE76 components, in
the measurement's frame, ``calibration.measure``) over every ink's log σs and log σa per channel and the shared
Henyey-Greenstein g, with the adding-doubling model of ``calibration.stack`` and its derivatives.

A patch layer mixes its inks' coefficients linearly (``model.inks.mix``), so a reflectance depends on the ink
parameters only through the two layers' (σs, σa) per channel: its derivatives with respect to those four numbers
(forward differences of adding-doubling, relative step 1e-5) and g (one more evaluation) give the whole Jacobian
by the chain rule. ``scipy.optimize.least_squares`` (trust-region reflective, bounds on every parameter) minimises.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from ..model import InkTable
from .chart import Chart
from .measure import rgb_to_lab, rgb_to_lab_jacobian
from .stack import IOR, QUAD_PTS, channel_reflectance, one_blas_thread

SIGMA_BOUNDS = (1e-5, 500.0)  # mm^-1
G_BOUNDS = (0.0, 0.9)
REL_STEP = 1e-5
G_STEP = 1e-4


@dataclass
class FitResult:
    """A fitted table and how it got there: ``inks`` (the chart's ink order; a ``SpectralInkTable`` from the
    spectral path of ``calibrate``), ``predicted_lab`` (P, 3) of the
    fitted patches, ``iterations`` (model evaluations with derivatives), ``seconds``, ``cost`` (half the sum of
    squared Lab differences), ``converged`` and the optimiser's ``message``."""

    inks: InkTable
    predicted_lab: np.ndarray
    iterations: int
    seconds: float
    cost: float
    converged: bool
    message: str


def _layers(chart: Chart):
    """Per patch: (mixture (N,), thickness mm, backing ink index or None, backing mm)."""
    out = []
    for st in chart.stacks():
        out.append((np.asarray(st.mixture), st.thickness_mm, st.backing, st.backing_mm))
    return out


@one_blas_thread
def predict_rgb(chart: Chart, inks: InkTable, quad_pts: int = QUAD_PTS) -> np.ndarray:
    """(P, 3) float64 linear-RGB reflectance of every patch of ``chart`` with ``inks`` (chart order)."""
    out = np.empty((len(chart), 3))
    for p, (m, d, b, bmm) in enumerate(_layers(chart)):
        s, a = m @ inks.sigma_s, m @ inks.sigma_a
        for c in range(3):
            lay = [(s[c], a[c], d)] + ([(inks.sigma_s[b, c], inks.sigma_a[b, c], bmm)] if b is not None else [])
            out[p, c] = channel_reflectance(lay, inks.g, IOR, quad_pts)
    return out


def predict_lab(chart: Chart, inks: InkTable, illuminant: str) -> np.ndarray:
    return rgb_to_lab(predict_rgb(chart, inks), illuminant)


@one_blas_thread
def _rgb_and_jacobian(chart: Chart, inks: InkTable):
    """(P, 3) reflectance and its derivatives (P, 3, K) with respect to x = [log σs (N, 3), log σa (N, 3), g]
    flattened (σs block first, each in (ink, channel) C order)."""
    n = len(inks)
    k = 6 * n + 1
    rgb = np.empty((len(chart), 3))
    jac = np.zeros((len(chart), 3, k))
    g = inks.g
    for p, (m, d, b, bmm) in enumerate(_layers(chart)):
        s, a = m @ inks.sigma_s, m @ inks.sigma_a
        for c in range(3):
            back = [(inks.sigma_s[b, c], inks.sigma_a[b, c], bmm)] if b is not None else []
            r0 = channel_reflectance([(s[c], a[c], d)] + back, g)
            rgb[p, c] = r0
            hs, ha = REL_STEP * max(s[c], 1e-3), REL_STEP * max(a[c], 1e-3)
            d_s = (channel_reflectance([(s[c] + hs, a[c], d)] + back, g) - r0) / hs
            d_a = (channel_reflectance([(s[c], a[c] + ha, d)] + back, g) - r0) / ha
            # d sigma_layer / d log sigma_{n,c} = m_n sigma_{n,c}
            jac[p, c, np.arange(n) * 3 + c] += d_s * m * inks.sigma_s[:, c]
            jac[p, c, 3 * n + np.arange(n) * 3 + c] += d_a * m * inks.sigma_a[:, c]
            if b is not None:
                bs, ba = inks.sigma_s[b, c], inks.sigma_a[b, c]
                hbs, hba = REL_STEP * max(bs, 1e-3), REL_STEP * max(ba, 1e-3)
                lay = (s[c], a[c], d)
                db_s = (channel_reflectance([lay, (bs + hbs, ba, bmm)], g) - r0) / hbs
                db_a = (channel_reflectance([lay, (bs, ba + hba, bmm)], g) - r0) / hba
                jac[p, c, b * 3 + c] += db_s * bs
                jac[p, c, 3 * n + b * 3 + c] += db_a * ba
            jac[p, c, -1] = (channel_reflectance([(s[c], a[c], d)] + back, g + G_STEP) - r0) / G_STEP
    return rgb, jac


def _to_x(inks: InkTable) -> np.ndarray:
    lo, hi = SIGMA_BOUNDS
    s = np.clip(inks.sigma_s, lo, hi)
    a = np.clip(inks.sigma_a, lo, hi)
    return np.concatenate([np.log(s).ravel(), np.log(a).ravel(), [np.clip(inks.g, *G_BOUNDS)]])


def _from_x(x: np.ndarray, names) -> InkTable:
    n = len(names)
    s = np.exp(x[: 3 * n]).reshape(n, 3)
    a = np.exp(x[3 * n : 6 * n]).reshape(n, 3)
    return InkTable(tuple(names), s, a, float(x[-1]))


def solve(model, x0: np.ndarray, fit_g: bool, max_iterations: int):
    """Least squares over x = [log σ (K - 1 values), g] from ``x0`` (K,): ``model(x)`` -> (residuals (M,),
    Jacobian (M, K)), evaluated once per x; σ within ``SIGMA_BOUNDS``, g within ``G_BOUNDS`` (held at x0's with
    ``fit_g=False``). Trust-region reflective (``scipy.optimize.least_squares``); returns its result and the
    number of model evaluations."""
    from scipy.optimize import least_squares

    lo = np.concatenate([np.full(len(x0) - 1, np.log(SIGMA_BOUNDS[0])), [G_BOUNDS[0]]])
    hi = np.concatenate([np.full(len(x0) - 1, np.log(SIGMA_BOUNDS[1])), [G_BOUNDS[1]]])
    if not fit_g:
        lo[-1], hi[-1] = x0[-1] - 1e-9, x0[-1] + 1e-9
    cache: dict = {}
    evaluations = [0]

    def evaluated(x):
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            residuals, jac = model(x)
            if not fit_g:
                jac[:, -1] = 0.0
            cache[key] = (residuals, jac)
            evaluations[0] += 1
        return cache[key]

    res = least_squares(
        lambda x: evaluated(x)[0],
        x0,
        jac=lambda x: evaluated(x)[1],
        bounds=(lo, hi),
        method="trf",
        x_scale="jac",
        max_nfev=max_iterations,
        ftol=1e-10,
        xtol=1e-8,
        gtol=1e-10,
    )
    return res, evaluations[0]


def fit_inks(
    chart: Chart,
    measured_lab: np.ndarray,
    start: InkTable,
    illuminant: str,
    max_iterations: int = 60,
    fit_g: bool = True,
) -> FitResult:
    """Fit ``start`` (chart order) to ``measured_lab`` (P, 3, CIELAB under ``illuminant``) of ``chart``'s
    patches. ``fit_g=False`` keeps g at the start's value."""

    measured_lab = np.asarray(measured_lab, np.float64)
    if measured_lab.shape != (len(chart), 3):
        raise ValueError(f"measured_lab must be ({len(chart)}, 3), got {measured_lab.shape}")
    t0 = time.perf_counter()
    names = chart.inks

    def model(x):
        rgb, jr = _rgb_and_jacobian(chart, _from_x(x, names))
        jl = rgb_to_lab_jacobian(rgb, illuminant)
        jac = np.einsum("pij,pjk->pik", jl, jr).reshape(-1, jr.shape[-1])
        return (rgb_to_lab(rgb, illuminant) - measured_lab).ravel(), jac

    res, evaluations = solve(model, _to_x(start), fit_g, max_iterations)
    inks = _from_x(res.x, names)
    lab = predict_lab(chart, inks, illuminant)
    return FitResult(inks, lab, evaluations, time.perf_counter() - t0, float(res.cost), res.status > 0, res.message)


def choose_holdout(chart: Chart, fraction: float, seed: int = 0) -> np.ndarray:
    """Indices (sorted) of about ``fraction`` of the patches, drawn at random, such that the rest still identifies
    every parameter (``chart.check_identifiable``): a patch whose removal would break that stays in the fit."""
    from .chart import ChartError, check_identifiable

    if not 0 <= fraction < 1:
        raise ParameterError(f"`holdout` must lie in [0, 1), got {fraction}")
    want = int(round(fraction * len(chart)))
    order = np.random.default_rng(seed).permutation(len(chart))
    held: list[int] = []
    for i in order:
        if len(held) >= want:
            break
        keep = [j for j in range(len(chart)) if j not in held and j != i]
        try:
            check_identifiable(chart.subset(keep))
        except ChartError:
            continue
        held.append(int(i))
    return np.array(sorted(held), np.int64)
