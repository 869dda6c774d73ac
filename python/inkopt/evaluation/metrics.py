"""Quality figures of a predicted appearance against its target, the same for every report (report.json of a
run, evaluation.json of ``inkopt evaluate``, benchmarks)."""
from __future__ import annotations

import numpy as np

from ..color import delta_e76, delta_e2000, lab_stderr, linear_to_lab
from ..loss import TexelLoss


def prediction_metrics(loss: TexelLoss, rgb, var_mean=None) -> dict:
    """Figures of predictions ``rgb`` (I, 3) linear against ``loss``'s target (I, 3) linear.

    Always: ``delta_e76_mean``, ``delta_e76_p95``, ``delta_e2000_mean``, ``ssim`` (mean texel SSIM), and the
    loss's ``loss``, ``e1``, ``e2``, ``e3`` at its weights. With ``var_mean`` (I, 3), the Monte Carlo variance of
    each prediction: SSIM with that noise removed from its statistics (an estimate for the noise-free
    prediction), ``delta_e76_noise`` (mean standard error of a texel's CIELAB colour, ΔE), ``delta_e76_rms`` and
    ``delta_e76_rms_denoised`` (an unbiased estimate of the noise-free RMS ΔE76: E|c + n - t|² = |c - t|² +
    tr(cov n) to first order in Lab)."""
    rgb = np.asarray(rgb, np.float64)
    res = loss(rgb, var_mean)
    lab_t = loss.target_lab
    de = delta_e76(res.lab, lab_t)
    out = {"delta_e76_mean": float(de.mean()), "delta_e76_p95": float(np.percentile(de, 95)),
           "delta_e2000_mean": float(delta_e2000(res.lab, lab_t).mean()),
           "ssim": float(loss.ssim_mean(rgb, var_mean)), "loss": res.value, "e1": res.e1, "e2": res.e2,
           "e3": res.e3}
    if var_mean is not None:
        se = lab_stderr(rgb, np.asarray(var_mean, np.float64))
        out["delta_e76_noise"] = float(se.mean())
        out["delta_e76_rms"] = float(np.sqrt(np.mean(de * de)))
        out["delta_e76_rms_denoised"] = float(np.sqrt(max(0.0, np.mean(de * de - se * se))))
    return out


def delta_e76_map(loss: TexelLoss, rgb) -> np.ndarray:
    """Per-texel ΔE76 (I,) of predictions ``rgb`` (I, 3) linear against ``loss``'s target."""
    return delta_e76(linear_to_lab(rgb), loss.target_lab)
