"""The fit: its Jacobian against finite differences of the model, and recovery of a hidden ink table from
noise-free adding-doubling measurements of a two-ink chart (the model is exact there, so what remains is the
optimiser's tolerance). Recovering g itself is the synthetic study's (experiments/calibration_synthetic.py)."""

import numpy as np
import pytest

from inkopt.calibration.chart import check_identifiable, design_chart
from inkopt.calibration.fit import _from_x, _rgb_and_jacobian, _to_x, choose_holdout, fit_inks, predict_lab
from inkopt.color import delta_e2000
from inkopt.model import InkTable

pytest.importorskip("iadpython")
INKS = InkTable.parse("cyan,white")
CHART = design_chart(INKS.names)


def hidden(seed=0, g=0.4):
    rng = np.random.default_rng(seed)
    return InkTable(
        INKS.names, INKS.sigma_s * rng.uniform(0.6, 1.6, (2, 3)), INKS.sigma_a * rng.uniform(0.6, 1.6, (2, 3)), g
    )


def test_jacobian_matches_central_differences():
    chart = CHART.subset([0, 7, 10, 15])  # over white, alone, diluted, white alone
    x = _to_x(hidden(1))
    _, jac = _rgb_and_jacobian(chart, _from_x(x, INKS.names))
    rng = np.random.default_rng(0)
    for k in rng.choice(len(x), 3, replace=False).tolist() + [len(x) - 1]:
        h = 1e-4
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        fd = (
            _rgb_and_jacobian(chart, _from_x(xp, INKS.names))[0] - _rgb_and_jacobian(chart, _from_x(xm, INKS.names))[0]
        ) / (2 * h)
        # forward differences with relative step 1e-5 against central ones: agree to ~1e-4 of the largest entry
        np.testing.assert_allclose(jac[..., k], fd, atol=2e-4 * max(np.abs(fd).max(), 1e-3))


def test_recovers_a_hidden_table():
    truth = hidden(2)
    lab = predict_lab(CHART, truth, "D50")
    held = [8, 12, 16]  # patches the fit does not see: predicted as well as the fitted ones
    keep = np.setdiff1d(np.arange(len(CHART)), held)
    res = fit_inks(CHART.subset(keep), lab[keep], INKS, "D50")
    assert res.converged
    assert delta_e2000(res.predicted_lab, lab[keep]).max() < 0.02
    assert delta_e2000(predict_lab(CHART.subset(held), res.inks, "D50"), lab[held]).max() < 0.05


def test_holdout_keeps_the_chart_identifiable():
    held = choose_holdout(CHART, 0.5, seed=3)
    assert 0 < len(held) <= round(0.5 * len(CHART))
    check_identifiable(CHART.subset(np.setdiff1d(np.arange(len(CHART)), held)))
    assert len(choose_holdout(CHART, 0.0)) == 0
    with pytest.raises(ValueError, match="holdout must lie"):
        choose_holdout(CHART, 1.0)
