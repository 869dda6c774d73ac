"""The loss over band predictions under lights (TexelLoss with colour maps): its gradient against finite differences
for one light, the mean and the worst of two; a 3-band map equal to sRGB gives the RGB loss exactly."""

import numpy as np
import pytest

from inkopt.color import RGB, RGB_TO_XYZ, ColourMap
from inkopt.loss import TexelLoss
from inkopt.model import Texels
from inkopt.spectral.lights import named_light

WL = np.linspace(400.0, 700.0, 16)


def problem(seed=0):
    rng = np.random.default_rng(seed)
    pos = Texels.box_faces((3, 4, 5)).pos_vox
    n = len(pos)
    target = rng.uniform(0.05, 0.9, (n, 3))
    pred = rng.uniform(0.05, 0.9, (n, 16))
    return target, pos, pred


def fd_gradient(lf: TexelLoss, pred: np.ndarray, rows, h=1e-6) -> np.ndarray:
    out = np.zeros((len(rows), pred.shape[1]))
    for k, i in enumerate(rows):
        for c in range(pred.shape[1]):
            p = pred.copy()
            p[i, c] += h
            up = lf(p).value
            p[i, c] -= 2 * h
            out[k, c] = (up - lf(p).value) / (2 * h)
    return out


@pytest.mark.parametrize("lights,combine", [(("A",), "mean"), (("D65", "A"), "mean"), (("D65", "F11"), "worst")])
def test_band_loss_gradient_finite_differences(lights, combine):
    target, pos, pred = problem()
    maps = tuple(named_light(n).colour_map(WL) for n in lights)
    lf = TexelLoss(target, pos, gamma=(1.0, 2.0, 1.0), colours=maps, combine=combine)
    res = lf(pred)
    assert res.grad.shape == pred.shape
    rows = np.random.default_rng(1).choice(len(pred), 5, replace=False)
    fd = fd_gradient(lf, pred, rows)
    assert np.abs(res.grad[rows] - fd).max() <= 1e-5 * np.abs(fd).max(), (res.grad[rows], fd)


def test_several_lights_combine_the_single_light_losses():
    target, pos, pred = problem(2)
    maps = tuple(named_light(n).colour_map(WL) for n in ("D65", "A"))
    each = [TexelLoss(target, pos, gamma=(1.0, 1.0, 1.0), colours=(m,))(pred) for m in maps]
    mean = TexelLoss(target, pos, gamma=(1.0, 1.0, 1.0), colours=maps)(pred)
    worst = TexelLoss(target, pos, gamma=(1.0, 1.0, 1.0), colours=maps, combine="worst")(pred)
    assert mean.value == pytest.approx((each[0].value + each[1].value) / 2, rel=1e-12)
    assert worst.value == max(r.value for r in each)
    np.testing.assert_array_equal(mean.lab, each[0].lab)


def test_srgb_colour_map_is_the_rgb_loss():
    rng = np.random.default_rng(3)
    pos = Texels.box_faces((3, 4, 5)).pos_vox
    target = rng.uniform(0.05, 0.9, (len(pos), 3))
    pred = rng.uniform(0.05, 0.9, (len(pos), 3))
    var = rng.uniform(0, 1e-4, pred.shape)
    a = TexelLoss(target, pos, gamma=(1.0, 2.0, 1.0))(pred, var)
    b = TexelLoss(target, pos, gamma=(1.0, 2.0, 1.0), colours=(ColourMap(RGB_TO_XYZ, "copy"),))(pred, var)
    assert a.value == b.value
    np.testing.assert_array_equal(a.grad, b.grad)
    assert TexelLoss(target, pos).colours == (RGB,)


def test_checks():
    target, pos, pred = problem()
    with pytest.raises(ValueError, match="one channel count"):
        TexelLoss(target, pos, colours=(RGB, named_light("A").colour_map(WL)))
    with pytest.raises(ValueError, match="combine"):
        TexelLoss(target, pos, colours=(RGB,), combine="median")
    with pytest.raises(ValueError, match=r"\(94, 3\)"):
        TexelLoss(target, pos)(pred)
