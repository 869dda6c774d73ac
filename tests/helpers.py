"""Shared test helpers: where the shared data lives, and the gradient-vs-finite-difference checks.

Shared data (test meshes) is found relative to the repository: ``../shared`` beside the project root, as CI
and every developer machine lay it out.
"""
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"
SPOT = SHARED_DATA / "spot" / "spot.obj"


def central_differences(f, x, h=1e-3) -> np.ndarray:
    """Central finite differences of a deterministic scalar function ``f`` at every entry of ``x``."""
    g = np.zeros_like(x)
    for i in np.ndindex(x.shape):
        e = np.zeros_like(x)
        e[i] = h
        g[i] = (f(x + e) - f(x - e)) / (2 * h)
    return g


def assert_same_mean(estimates, references, rel_bias: float = 0.02, false_alarm: float = 1e-4, what=""):
    """Two unbiased Monte Carlo estimators of one quantity (e.g. a replay gradient and central finite differences
    with common random numbers), one pair per independent seed: their paired difference must have mean ~0.

    The bound is the Student-t quantile for a two-sided false-alarm rate ``false_alarm`` times the standard error
    estimated from the seeds (a normal 4-sigma bound would fire ~1 % of the time with 12 seeds), plus
    ``rel_bias`` of |mean(references)| for a known deterministic bias (e.g. the O(h^2) error of a difference
    quotient), plus 1e-5 absolute for estimates that are exactly zero."""
    from scipy.stats import t as student_t

    d = np.asarray(estimates, np.float64) - np.asarray(references, np.float64)
    if len(d) < 2:
        raise ValueError("assert_same_mean needs at least two seeds")
    t_crit = student_t.ppf(1 - false_alarm / 2, len(d) - 1)
    se = d.std(ddof=1) / np.sqrt(len(d))
    bound = t_crit * se + rel_bias * abs(np.mean(references)) + 1e-5
    assert abs(d.mean()) < bound, (what, float(np.mean(estimates)), float(np.mean(references)), float(se))
