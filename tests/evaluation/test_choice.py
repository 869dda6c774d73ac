"""Tests of inkopt.evaluation.choice: every texel or a texel sample, from the time predicted at equal accuracy of the
mean ΔE76 (fake cost models and fake pilot renders: no render here but one small evaluation)."""

import json
import math

import numpy as np
import pytest
from slab_run import make_run

from inkopt.color import linear_to_lab
from inkopt.evaluation.choice import (
    MIN_SAMPLE_TEXELS,
    PILOT_TEXELS,
    SAMPLE_MIN_GAIN,
    TARGET_STDERR_DE76,
    CostModel,
    choose_sampling,
    pilot,
    predict,
)
from inkopt.evaluation.evaluate import evaluate_run
from inkopt.evaluation.noise import ESTIMATE_RANGE, PILOT_SPP, TARGET_NOISE_DE76
from inkopt.evaluation.options import EvaluateOptions
from inkopt.model import Texels

#: what the pilot measured on Spot 20 mm (adaptive): ΔE76 spread, spp of every texel / points / windows
SPOT20 = dict(texels=2000, spp=64, seconds=1.7, delta_e76_std=8.2, spp_full=375, spp_points=183, spp_windows=125)


def sheet(side: int) -> Texels:
    """side² texels on the top face of a one-voxel-thick sheet."""
    return Texels.box_faces((1, side, side), ["top"])


def no_render(*args):
    raise AssertionError("a forced choice renders no pilot")


def test_the_target_is_the_noise_corrections_residual():
    assert TARGET_STDERR_DE76 == pytest.approx((ESTIMATE_RANGE[1] - 1) * TARGET_NOISE_DE76) == 0.175


def test_sample_size_reaches_the_target_standard_error():
    cost = CostModel(**SPOT20)
    for population in (5_000, 96_002, 386_829):
        n = cost.sample_texels(population)
        se = cost.delta_e76_std / math.sqrt(n) * math.sqrt(1 - n / population)
        assert se <= TARGET_STDERR_DE76 < cost.delta_e76_std / math.sqrt(n - 1) * math.sqrt(1 - (n - 1) / population)
    flat = CostModel(**{**SPOT20, "delta_e76_std": 0.5})  # a tiny spread: the floor, at most the population
    assert flat.sample_texels(10**6) == MIN_SAMPLE_TEXELS and flat.sample_texels(300) == 300


def test_small_scene_renders_every_texel_large_one_a_sample():
    """The same per-texel costs: a slab of 2304 texels is rendered whole (its sample would be most of it, windows
    included), a 160 000-texel object by a sample, with both predictions recorded."""
    cost = CostModel(**SPOT20)
    small = predict(cost, sheet(48), None, seed=3)
    assert small.sample is None and small.name == "every texel" and not small.forced
    assert small.sample_seconds * SAMPLE_MIN_GAIN > small.full_seconds
    big = predict(cost, sheet(400), None, seed=3)
    n = cost.sample_texels(160_000)
    assert big.sample is not None and len(big.sample.points) == n and len(big.sample.centres) == 100
    assert big.sample_seconds * SAMPLE_MIN_GAIN <= big.full_seconds and small.to_json()["sample"]["window_texels"] > 0
    per = cost.seconds / (cost.texels * cost.spp)
    assert big.full_seconds == pytest.approx(160_000 * cost.spp_full * per)
    w = len(big.sample.windows)
    assert big.sample_seconds == pytest.approx((n * cost.spp_points + w * cost.spp_windows) * per)
    j = json.loads(json.dumps(big.to_json()))
    assert j["choice"] == "texel sample" and j["target_stderr_delta_e76"] == TARGET_STDERR_DE76
    assert j["every_texel"]["seconds"] > j["sample"]["seconds"] and j["sample"]["window_texels"] == w
    assert "every texel" in big.describe() and "texel sample" in big.describe()


def test_fixed_spp_compares_texel_counts():
    """With a fixed spp every group has it: a demo-sized object (8000 texels) stays whole, its sample (points and
    windows) being no less than half of it; costly per-texel spp does not change that."""
    cost = CostModel(**{**SPOT20, "spp_full": 128, "spp_points": 128, "spp_windows": 128})
    assert predict(cost, sheet(90), None, seed=0).sample is None
    assert predict(cost, sheet(400), None, seed=0).sample is not None


def fake_render(noise: float):
    """A pilot render: grey texels whose variance of the mean is noise² / spp."""
    calls = []

    def render(texels, spp, seed):
        calls.append((len(texels), spp, seed))
        rng = np.random.default_rng(len(calls))
        rgb = rng.uniform(0.2, 0.6, (len(texels), 3))
        return rgb, np.full_like(rgb, noise**2 / spp)

    return render, calls


def test_pilot_predicts_more_samples_for_noisier_renders_and_forced_choices_skip_it():
    tex = sheet(200)
    target = linear_to_lab(np.full((len(tex), 3), 0.4))
    quiet, calls = fake_render(0.05)
    c = pilot(quiet, tex, target, None, 4096, seed=5)
    assert calls == [(PILOT_TEXELS, PILOT_SPP, calls[0][2])] and (c.texels, c.spp) == (PILOT_TEXELS, PILOT_SPP)
    loud = pilot(fake_render(0.5)[0], tex, target, None, 4096, seed=5)
    assert loud.spp_full > c.spp_full >= c.spp_points >= PILOT_SPP and loud.spp_windows <= loud.spp_full
    fixed = pilot(quiet, sheet(40), target[:1600], 16, 4096, seed=5)  # a quarter of a small scene, at its spp
    assert (fixed.texels, fixed.spp, fixed.spp_full, fixed.spp_points, fixed.spp_windows) == (400, 16, 16, 16, 16)
    whole = choose_sampling(no_render, tex, target, EvaluateOptions(texel_sample=0), seed=1)
    assert whole.sample is None and whole.forced and whole.to_json() == {"choice": "every texel", "forced": True}
    part = choose_sampling(no_render, tex, target, EvaluateOptions(texel_sample=500, sample_windows=7), seed=1)
    assert len(part.sample.points) == 500 and len(part.sample.centres) == 7 and "as asked" in part.describe()


def test_a_small_run_is_evaluated_whole_by_the_rule(tmp_path, table3):
    """A slab run with the default options: the pilot's prediction keeps every texel, with pictures."""
    make_run(tmp_path / "run", table3, "extrusion")
    lines = []
    ev = evaluate_run(tmp_path / "run", EvaluateOptions(spp=4, table=table3, baselines=False), log=lines.append)
    choice = ev.to_json()["sampling_choice"]
    assert choice["choice"] == "every texel" and not choice["forced"] and choice["pilot"]["spp"] == 4
    assert ev.texel_sample is None and ev.pictures and any(line.startswith("sampling: every texel") for line in lines)


def test_a_smaller_standard_error_asks_for_more_texels():
    """The run's start figures ask for a third of the evaluation's standard error: about nine times the points, and
    the choice records the target it was made for."""
    cost = CostModel(**SPOT20)
    tex = sheet(1000)
    loose, tight = predict(cost, tex, None, seed=3), predict(cost, tex, None, seed=3, target=TARGET_STDERR_DE76 / 3)
    assert len(tight.sample.points) == cost.sample_texels(len(tex), TARGET_STDERR_DE76 / 3)
    assert 8 * len(loose.sample.points) < len(tight.sample.points) < 10 * len(loose.sample.points)
    assert tight.to_json()["target_stderr_delta_e76"] == TARGET_STDERR_DE76 / 3
    assert tight.to_json()["sample"]["texels"] == len(tight.sample.points)
