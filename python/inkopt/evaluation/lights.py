"""Figures under several lights: a prediction's quality under each light a loss holds, the worst of them, and how
much the print's colour moves between lights.

Under each light (each colour map of the loss, ``spectral.viewing.Viewing``): the figures of
:func:`~inkopt.evaluation.metrics.prediction_metrics` (ΔE76, ΔE2000, SSIM, noise figures) against the target, whose
CIELAB is the same under every light (the texture as an adapted viewer sees it).

The metamerism figure is the print's **colour inconstancy** between two lights: per texel, the CIEDE2000 difference
between its CIELAB under the first light and under the other, each relative to its own light's white (CIELAB's
white normalisation as the viewer's adaptation, no further adaptation transform), averaged over texels. It is 0 for
a print whose reflectance is flat over wavelength (a grey) and grows as the print's spectra differ from the flat ones
the lights' whites are. It is not the CIE metamerism index (which compares two samples that match under a reference
light); the print's mismatch to its target under each light is the per-light ΔE2000.
"""

from __future__ import annotations

import numpy as np

from ..color import delta_e2000
from ..loss import TexelLoss
from . import sample as sampled
from .metrics import prediction_metrics


def light_figures(loss: TexelLoss, values, var_mean=None, names: tuple[str, ...] | None = None) -> dict:
    """Figures of predictions ``values`` (I, C) (variances ``var_mean`` (I, C) or None) under each of ``loss``'s
    colour maps, named by ``names`` (default the maps' names):

    ``by_light``: {name: ``Metrics.to_json()``}; ``worst_light``, ``worst_delta_e2000_mean``: the light where the
    mean ΔE2000 is largest and that mean; ``inconstancy_delta_e2000_mean``: {"<first>-<other>": mean ΔE2000 of the
    print between the two lights} (empty with one light)."""
    values = np.asarray(values, np.float64)
    names = tuple(names or (c.name for c in loss.colours))
    if len(names) != len(loss.colours):
        raise ValueError(f"{len(names)} names for {len(loss.colours)} lights")
    by_light = {n: prediction_metrics(loss.under(k), values, var_mean).to_json() for k, n in enumerate(names)}
    worst = max(names, key=lambda n: by_light[n]["delta_e2000_mean"])
    labs = [c.lab(values) for c in loss.colours]
    inconstancy = {f"{names[0]}-{names[k]}": float(delta_e2000(labs[0], labs[k]).mean()) for k in range(1, len(names))}
    return {
        "by_light": by_light,
        "worst_light": worst,
        "worst_delta_e2000_mean": by_light[worst]["delta_e2000_mean"],
        "inconstancy_delta_e2000_mean": inconstancy,
    }


def sampled_light_figures(loss: TexelLoss, windows, points, target_lab, sample, names: tuple[str, ...]):
    """``light_figures`` of a result rendered on a texel sample (``evaluation.sample``): ``loss`` built on the sample's
    window texels with every light's colour map, ``windows`` and ``points`` = (values, var_mean) of the two groups,
    ``target_lab`` (n, 3) the points' targets. Every light's figures from its own view of the loss
    (``TexelLoss.under``, ``sample.sampled_figures``) with their standard errors (``by_light[light]["stderr"]``), the
    colour inconstancy on the points with its standard error (``inconstancy_stderr``). Returns (the figures, the
    per-texel values of each light, for ``sample.differences``)."""
    if len(names) != len(loss.colours):
        raise ValueError(f"{len(names)} names for {len(loss.colours)} lights")
    values = [sampled.per_texel(loss.under(k), windows, points, target_lab, sample) for k in range(len(names))]
    by_light = {}
    for k, light in enumerate(names):
        m, err = sampled.sampled_figures(loss.under(k), values[k], sample)
        by_light[light] = {**m.to_json(), "stderr": err}
    labs = [c.lab(np.asarray(points[0], np.float64)) for c in loss.colours]
    moves = {
        f"{names[0]}-{names[k]}": sampled.mean_se(delta_e2000(labs[0], labs[k]), sample.population)
        for k in range(1, len(names))
    }
    worst = max(names, key=lambda n: by_light[n]["delta_e2000_mean"])
    figures = {
        "by_light": by_light,
        "worst_light": worst,
        "worst_delta_e2000_mean": by_light[worst]["delta_e2000_mean"],
        "inconstancy_delta_e2000_mean": {k: v[0] for k, v in moves.items()},
        "inconstancy_stderr": {k: v[1] for k, v in moves.items()},
    }
    return figures, values
