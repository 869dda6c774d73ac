"""The spectral gradient end to end on a tiny slab: d(loss adjoint . band values)/d(ink share) by per-group path
replay and the spectral table's chain rule through the mixing, against central finite differences of band renders
with common random numbers (``helpers.assert_same_mean``: Student-t bound over 12 seeds, false-alarm rate 1e-4 per
probe, plus 2 % for the difference quotient's O(h^2) bias)."""

import numpy as np
import pytest
from helpers import assert_same_mean
from spectral_helpers import INKS, smooth_table

from inkopt.model import Texels, Volume, mix_grad
from inkopt.spectral.allocation import BandPlan
from inkopt.spectral.lights import named_light
from inkopt.spectral.render import SpectralRenderer
from inkopt.spectral.viewing import Viewing


@pytest.mark.parametrize("hero", [False, True])
def test_spectral_share_gradient_matches_finite_differences(hero):
    """Per band path (hero False) and hero paths carrying a group's three bands (hero True)."""
    table = smooth_table()
    rng = np.random.default_rng(4)
    m = (0.3 + rng.dirichlet(np.ones(5), size=(4, 2, 2))).astype(np.float32)
    vol = Volume.from_mixture((0.1, 0.1, 0.1), m, INKS, boundary="periodic-xy")
    tex = Texels.for_volume(vol, ["top"])
    viewing, plan = Viewing(table, (named_light("D65"), named_light("A"))), BandPlan.in_order(table, hero=hero)
    target = np.full((len(tex), 3), 0.3)
    loss = viewing.loss(target, tex.pos_vox, (1.0, 0.0, 0.0))
    pred = SpectralRenderer(vol, table, threads=2).render(tex, spp=2000, seed=99)
    adj = loss(pred.rgb).grad.astype(np.float32)  # fixed: the test is of the gradient of adj . values
    h = 0.25
    for z, n in ((3, 0), (1, 4)):
        g, fd = [], []
        for seed in range(11, 23):
            gs, ga, _ = SpectralRenderer(vol, table, threads=2, plan=plan).gradient(tex, adj, spp=2000, seed=seed)
            g.append(float(mix_grad(gs, ga, table)[z, :, :, n].sum()))  # the layer's voxels share one change
            vals = []
            for sign in (1, -1):
                m2 = m.copy()
                m2[z, :, :, n] += sign * h
                r = SpectralRenderer(vol.with_mixture(m2), table, threads=2, plan=plan).render(tex, 2000, seed=seed)
                vals.append(float(np.sum(r.rgb * adj)))
            fd.append((vals[0] - vals[1]) / (2 * h))
        assert abs(np.mean(fd)) > 0
        assert_same_mean(g, fd, rel_bias=0.02, false_alarm=1e-4, what=(z, n))
