"""The colour-difference terms of experiments/figure_disagreement.py and the ΔE2000-weighted colour term of
experiments/loss_de2000.py: the terms add up to the totals, and the weighted term's gradient is its value's."""

import numpy as np
from helpers import REPO, load_file_module

from inkopt.color import delta_e76, delta_e2000, linear_to_lab

FIG = load_file_module(REPO / "experiments" / "figure_disagreement.py", "figure_disagreement")
LOSS = load_file_module(REPO / "experiments" / "loss_de2000.py", "loss_de2000")


def _colours(n=500, seed=0):
    rng = np.random.default_rng(seed)
    ref = linear_to_lab(rng.uniform(0, 1, (n, 3)))
    ref[:20, 1:] = 0.0  # grey references: no hue, CIEDE2000's special cases
    return ref, ref + rng.normal(0, 8, (n, 3))


def test_ciede2000_terms_match_the_total():
    ref, lab = _colours()
    t = FIG.ciede2000_terms(ref, lab)
    np.testing.assert_allclose(t["de"], delta_e2000(ref, lab), atol=1e-9)
    total = np.sqrt(np.maximum(t["dL"] ** 2 + t["dC"] ** 2 + t["dH"] ** 2 + t["rot"], 0))
    np.testing.assert_allclose(total, t["de"], atol=1e-12)
    assert np.all(t["SC"] >= 1) and np.all(t["SL"] >= 1)


def test_cie76_terms_add_up():
    ref, lab = _colours(seed=1)
    t = FIG.cie76_terms(ref, lab)
    np.testing.assert_allclose(t["dL"] ** 2 + t["dC"] ** 2 + t["dH"] ** 2, delta_e76(ref, lab) ** 2, rtol=1e-9)


def test_weighted_loss_gradient_and_small_errors():
    assert LOSS.check_gradient(seed=5) < 1e-5
    rng = np.random.default_rng(2)
    target = linear_to_lab(rng.uniform(0.05, 1, (400, 3)))
    target = target[np.hypot(target[:, 1], target[:, 2]) > 30]  # saturated: CIEDE2000's a* stretch is small there
    d = rng.normal(0, 0.05, target.shape)
    metric = LOSS.de2000_metric(target)
    weighted = np.sqrt(np.einsum("ik,ikl,il->i", d, metric, d))
    # for small errors on saturated targets the form is CIEDE2000 but for G (<= ~5 % there) and the rotation term
    np.testing.assert_allclose(np.median(weighted / delta_e2000(target, target + d)), 1.0, atol=0.05)
