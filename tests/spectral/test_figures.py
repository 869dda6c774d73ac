"""Figures under several lights (evaluation.lights): per-light figures equal a one-light loss's, the worst light,
a grey print's colour inconstancy 0 and a coloured one's positive; metrics of an RGB loss unchanged by the colour
map generalisation (the same values as the sRGB functions give)."""

import numpy as np
import pytest
from spectral_helpers import INKS, smooth_table

from inkopt.color import delta_e2000, linear_to_lab
from inkopt.evaluation import sample as sampled
from inkopt.evaluation.lights import light_figures, sampled_light_figures
from inkopt.evaluation.metrics import prediction_metrics
from inkopt.loss import TexelLoss
from inkopt.model import Texels
from inkopt.spectral.lights import named_light
from inkopt.spectral.viewing import Viewing

WL = np.linspace(400.0, 700.0, 16)


def setup(seed=0):
    rng = np.random.default_rng(seed)
    pos = Texels.box_faces((3, 4, 5)).pos_vox
    target = rng.uniform(0.05, 0.9, (len(pos), 3))
    return pos, target, rng


def test_per_light_figures_equal_one_light_losses():
    pos, target, rng = setup()
    values = rng.uniform(0.05, 0.9, (len(pos), 16))
    var = rng.uniform(0, 1e-4, values.shape)
    lights = ("D65", "A", "F11")
    maps = tuple(named_light(n).colour_map(WL) for n in lights)
    fig = light_figures(TexelLoss(target, pos, colours=maps), values, var)
    for n, m in zip(lights, maps):
        alone = prediction_metrics(TexelLoss(target, pos, colours=(m,)), values, var).to_json()
        got = fig["by_light"][n]
        assert got.keys() == alone.keys()
        assert all(got[k] == (v if v is None else pytest.approx(v, rel=1e-12)) for k, v in alone.items())
    worst = max(lights, key=lambda n: fig["by_light"][n]["delta_e2000_mean"])
    assert fig["worst_light"] == worst and set(fig["inconstancy_delta_e2000_mean"]) == {"D65-A", "D65-F11"}


def test_a_sample_of_every_texel_gives_every_lights_figures():
    """A texel sample that holds every texel (points and windows) estimates each light's figures as every texel's
    do, with standard errors 0 (the finite-population correction), light by light: a light's view is its own."""
    texels = Texels.box_faces((3, 4, 5))
    pos, target, rng = setup(3)
    values = rng.uniform(0.05, 0.9, (len(pos), 16))
    var = np.zeros_like(values)  # noise-free: no noise terms between the two estimates
    lights = ("D65", "A", "F11")
    maps = tuple(named_light(n).colour_map(WL) for n in lights)
    every = light_figures(TexelLoss(target, pos, colours=maps), values, var, lights)
    s = sampled.TexelSample.draw(texels, len(pos), len(pos), seed=0)
    assert len(s.windows) == len(pos)
    loss = TexelLoss(target[s.windows], pos[s.windows], sigma=sampled.SIGMA, colours=maps)
    target_lab = linear_to_lab(target[s.points])
    points = (values[s.points], var[s.points])
    got, per_light = sampled_light_figures(loss, (values, var), points, target_lab, s, lights)
    assert len(per_light) == 3
    for n in lights:
        for key in ("delta_e76_mean", "delta_e2000_mean", "ssim"):
            assert got["by_light"][n][key] == pytest.approx(every["by_light"][n][key], rel=1e-9), (n, key)
            assert got["by_light"][n]["stderr"][key] == pytest.approx(0.0, abs=1e-12)
    assert got["worst_light"] == every["worst_light"]
    for pair, v in every["inconstancy_delta_e2000_mean"].items():
        assert got["inconstancy_delta_e2000_mean"][pair] == pytest.approx(v, rel=1e-9)
    with pytest.raises(ValueError, match="2 names for 3 lights"):
        sampled_light_figures(loss, (values, var), points, target_lab, s, lights[:2])


def test_inconstancy_of_grey_and_coloured_prints():
    pos, target, rng = setup(1)
    maps = tuple(named_light(n).colour_map(WL) for n in ("D65", "A"))
    loss = TexelLoss(target, pos, colours=maps)
    grey = np.repeat(rng.uniform(0.1, 0.8, (len(pos), 1)), 16, axis=1)
    assert light_figures(loss, grey)["inconstancy_delta_e2000_mean"]["D65-A"] < 1e-6
    bump = 0.1 + 0.7 * np.exp(-0.5 * ((WL - 480.0) / 30.0) ** 2)
    coloured = np.broadcast_to(bump, (len(pos), 16))
    got = light_figures(loss, coloured)["inconstancy_delta_e2000_mean"]["D65-A"]
    want = delta_e2000(maps[0].lab(bump), maps[1].lab(bump))
    assert got == pytest.approx(float(want), rel=1e-12) and got > 1.0


def test_rgb_metrics_are_the_srgb_functions():
    pos, target, rng = setup(2)
    rgb = rng.uniform(0.05, 0.9, (len(pos), 3))
    m = prediction_metrics(TexelLoss(target, pos), rgb)
    assert m.delta_e2000_mean == pytest.approx(float(delta_e2000(linear_to_lab(rgb), linear_to_lab(target)).mean()))


def test_viewing_choice():
    assert not Viewing().spectral and Viewing(lights=(named_light("D65"),)).colours()[0].channels == 3
    with pytest.raises(ValueError, match="needs a spectral ink table"):
        Viewing(lights=(named_light("A"),))
    v = Viewing(smooth_table(), (named_light("D65"), named_light("A")), "worst")
    assert v.spectral and [c.channels for c in v.colours()] == [6, 6] and v.key() != Viewing(smooth_table()).key()
    assert Viewing().key() is None and v.describe()["illuminants"] == ["D65", "A"]
    assert tuple(INKS.names) == v.table.names
