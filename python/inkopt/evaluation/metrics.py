"""Quality figures of a predicted appearance against its target, the same for every report (report.json of a
run, evaluation.json of ``inkopt evaluate``, benchmarks).

**Mottle** (``mottle``): high-frequency L* power where the target is flat. For each texel, h_i = L*_i - (W L*)_i
with W the loss's texel Gaussian window (``TexelLoss``: sigma 1.5 voxels, built from the texel positions, the
texel itself included with weight w_ii). A texel is *flat* when the target's windowed standard deviation of L*
is below ``FLAT_L_STD`` = 1 and that of its chroma, sqrt(var a* + var b*), below ``FLAT_CHROMA_STD`` = 2 (about
the 8-bit quantization of a flat picture region). The figure is the mean of h_i² over flat texels, in (ΔL*)²,
minus the Monte Carlo noise's expected share: with v_j the variance of texel j's L* (delta method from the
linear-RGB variance, ``color.linear_to_lab_jacobian``), E h_i² gains (1 - w_ii)² v_i + Σ_{j≠i} w_ij² v_j.
``mottle_l2_target`` is the target's own figure (no noise), ``flat_texels`` the count (figures None when 0).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..color import delta_e76, delta_e2000
from ..loss import FLAT_CHROMA_STD, FLAT_L_STD, TexelLoss  # noqa: F401 (the thresholds, re-exported)
from .noise import NoiseModel


def flat_texels(loss: TexelLoss) -> np.ndarray:
    """Boolean (I,): texels whose target neighbourhood is flat (module docstring; ``TexelLoss.flat``)."""
    return loss.flat


def _mottle_columns(loss: TexelLoss, rgb: np.ndarray, var_mean) -> tuple[np.ndarray, np.ndarray | None]:
    """The mottle's windowed inputs: (I, 2) float64 the L* of predictions ``rgb`` (I, C) (the loss's first colour
    map) and the target's L*, to be windowed by K; (I, 1) the predictions' L* variance (delta method from
    ``var_mean``, the linear channels' variance), to be windowed by K^2, or None without ``var_mean``."""
    cmap = loss.colours[0]
    lum = np.stack([cmap.lab(rgb)[:, 0], loss.target_lab[:, 0]], axis=1)
    if var_mean is None:
        return lum, None
    jl = cmap.lab_jacobian(rgb)[:, 0, :]
    return lum, np.einsum("ij,ij->i", jl * jl, np.asarray(var_mean, np.float64))[:, None]


def _mottle_from(loss: TexelLoss, lum, var_l, k_lum, k2_var) -> tuple[np.ndarray, np.ndarray]:
    """h_i^2 (I,) of the prediction less the noise's expected share (``var_l`` given), and the target's h_i^2 (I,),
    from ``_mottle_columns``'s ``lum`` (I, 2), ``var_l`` (I, 1) or None and their products K @ lum, K^2 @ var_l.

    h_i = L*_i - (W L*)_i; the noise's share for independent per-texel L* variances v:
    (1 - w_ii)^2 v_i + sum_{j != i} w_ij^2 v_j = sum_j w_ij^2 v_j + (1 - 2 w_ii) v_i (w_ii = 1 / wsum_i)."""
    h = lum - k_lum / loss.wsum[:, None]
    p, pt = h[:, 0] * h[:, 0], h[:, 1] * h[:, 1]
    if var_l is not None:
        w2v = k2_var[:, 0] / loss.wsum**2
        p = p - (w2v + (1.0 - 2.0 / loss.wsum) * var_l[:, 0])
    return p, pt


def mottle_per_texel(loss: TexelLoss, rgb, var_mean=None) -> tuple[np.ndarray, np.ndarray]:
    """h_i² (I,) of predictions ``rgb`` (I, C) (the loss's first colour map: linear RGB unless spectral), minus the
    noise's expected share when ``var_mean`` is given, and the target's h_i² (I,); every texel (the figure takes the
    flat ones)."""
    lum, var_l = _mottle_columns(loss, np.asarray(rgb, np.float64), var_mean)
    k, k2, _ = loss.products(lum, var_l)
    return _mottle_from(loss, lum, var_l, k, k2)


def _mottle_figures(loss: TexelLoss, per_texel: tuple | None) -> dict:
    """``mottle_l2``, ``mottle_l2_target``, ``flat_texels`` from ``per_texel`` = (p, pt) (``mottle_per_texel``; None
    when no texel is flat)."""
    flat = flat_texels(loss)
    n = int(flat.sum())
    if n == 0:
        return {"mottle_l2": None, "mottle_l2_target": None, "flat_texels": 0}
    p, pt = per_texel
    return {"mottle_l2": float(p[flat].mean()), "mottle_l2_target": float(pt[flat].mean()), "flat_texels": n}


def mottle(loss: TexelLoss, rgb, var_mean=None) -> dict:
    """``mottle_l2`` (noise-corrected when ``var_mean`` is given), ``mottle_l2_target``, ``flat_texels``."""
    return _mottle_figures(loss, mottle_per_texel(loss, rgb, var_mean) if loss.flat.any() else None)


@dataclass
class Metrics:
    """The figures of one prediction against its target (``prediction_metrics``); ΔE in CIELAB units, mottle in
    (ΔL*)². The noise figures are None when the prediction's Monte Carlo variance was not given; the mottle
    figures are None when no texel is flat."""

    delta_e76_mean: float
    delta_e76_p95: float
    delta_e2000_mean: float
    ssim: float
    loss: float
    e1: float
    e2: float
    e3: float
    mottle_l2: float | None
    mottle_l2_target: float | None
    flat_texels: int
    delta_e76_noise: float | None = None
    delta_e76_noise_contribution: float | None = None
    delta_e76_mean_corrected: float | None = None
    delta_e76_rms: float | None = None
    delta_e76_rms_denoised: float | None = None

    NOISE_KEYS = (
        "delta_e76_noise",
        "delta_e76_noise_contribution",
        "delta_e76_mean_corrected",
        "delta_e76_rms",
        "delta_e76_rms_denoised",
    )

    def to_json(self) -> dict:
        """The figures by name; the noise figures only when they were estimated."""
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        return {k: v for k, v in d.items() if not (k in self.NOISE_KEYS and v is None)}

    @classmethod
    def from_json(cls, d: dict) -> Metrics:
        """The metrics among the entries of ``d`` (other keys, e.g. a report's, are ignored)."""
        return cls(**{f.name: d[f.name] for f in fields(cls) if f.name in d})


def prediction_metrics(loss: TexelLoss, rgb, var_mean=None) -> Metrics:
    """Figures of predictions ``rgb`` (I, C) against ``loss``'s target (I, 3) linear, in CIELAB by the loss's first
    colour map (linear RGB, or a spectral prediction's bands under a light: ``TexelLoss.under``).

    Always: ``delta_e76_mean``, ``delta_e76_p95``, ``delta_e2000_mean``, ``ssim`` (mean texel SSIM), the loss's
    ``loss``, ``e1``, ``e2``, ``e3`` at its weights, and the mottle (module docstring). With ``var_mean`` (I, 3),
    the Monte Carlo variance of each prediction: SSIM with that noise removed from its statistics (an estimate
    for the noise-free prediction), ``delta_e76_noise`` (mean standard error of a texel's CIELAB colour, ΔE),
    ``delta_e76_noise_contribution`` (the noise's estimated inflation of ``delta_e76_mean``, ``evaluation.noise``)
    and ``delta_e76_mean_corrected`` (the mean minus it), ``delta_e76_rms`` and ``delta_e76_rms_denoised`` (an
    unbiased estimate of the noise-free RMS ΔE76: E|c + n - t|² = |c - t|² + tr(cov n) to first order in Lab)."""
    rgb = np.asarray(rgb, np.float64)
    lum, var_l = _mottle_columns(loss, rgb, var_mean)
    # the loss, its SSIM and the mottle's windowed L* from one pass over the texels' neighbourhoods per light, no
    # operator held (``TexelLoss.figures``); no gradient: none of its temporaries
    fig = loss.figures(rgb, var_mean, lum, var_l)
    res = fig.loss
    lab_t = loss.target_lab
    de = delta_e76(res.lab, lab_t)
    out = {
        "delta_e76_mean": float(de.mean()),
        "delta_e76_p95": float(np.percentile(de, 95)),
        "delta_e2000_mean": float(delta_e2000(res.lab, lab_t).mean()),
        "ssim": fig.ssim,
        "loss": res.value,
        "e1": res.e1,
        "e2": res.e2,
        "e3": res.e3,
    }
    out.update(_mottle_figures(loss, _mottle_from(loss, lum, var_l, fig.window, fig.window_sq)))
    del fig, lum, var_l
    if var_mean is not None:
        var = np.asarray(var_mean, np.float64)
        se = loss.colours[0].lab_stderr(rgb, var)
        out["delta_e76_noise"] = float(se.mean())
        contrib = NoiseModel.of(rgb, var, lab_t, loss.colours[0]).contribution()
        out["delta_e76_noise_contribution"] = contrib
        out["delta_e76_mean_corrected"] = float(de.mean()) - contrib
        out["delta_e76_rms"] = float(np.sqrt(np.mean(de * de)))
        out["delta_e76_rms_denoised"] = float(np.sqrt(max(0.0, np.mean(de * de - se * se))))
    return Metrics(**out)


def delta_e76_map(loss: TexelLoss, rgb) -> np.ndarray:
    """Per-texel ΔE76 (I,) of predictions ``rgb`` (I, C) (the loss's first colour map) against its target."""
    return delta_e76(loss.colours[0].lab(rgb), loss.target_lab)
