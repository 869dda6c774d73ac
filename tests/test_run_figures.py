"""Tests of the choice of a texel sample for a run's figures (``inkopt.runfigures``): no pilot where no sample can be
twice as fast, a resumed run's baseline and result on the sample its start's figures recorded, and the result's time
shared between the sample and every texel's render for the pictures. The figures themselves, sampled and whole, are
tested through runs in tests/test_baseline_guard.py and tests/evaluation/test_finish.py."""

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from inkopt.evaluation.noise import PILOT_SPP, PROBE_SPP
from inkopt.evaluation.sample import TexelSample
from inkopt.model import Texels
from inkopt.optim import OptimizeConfig
from inkopt.run import RunOptions
from inkopt.runfigures import (
    FINAL_FIGURES_SHARE,
    RESULT_SAMPLE_MIN_GAIN,
    RESULT_SAMPLE_SHARE,
    RunFigures,
    _sample_can_win,
)


def sheet(side: int) -> Texels:
    """side² texels on the top face of a one-voxel-thick sheet."""
    return Texels.box_faces((1, side, side), ["top"])


def test_no_sample_can_win_on_a_small_object():
    """The fewest points (1000) and 100 windows of ~120 texels are more than half of a 6 mm Spot's 8349 texels or a
    demo slab's 2304, and far less than half of 160 000."""
    assert not _sample_can_win(sheet(48), seed=1)
    assert not _sample_can_win(sheet(91), seed=1)
    assert _sample_can_win(sheet(400), seed=1)


def no_pilot(*args):
    raise AssertionError("a recorded sample is drawn again, with no pilot")


def _figures(texels, start_figures=None, cfg=None, wall=0.0, **options) -> RunFigures:
    """The figures of a stand-in run of ``texels`` (only what ``RunFigures`` reads), its time so far ``wall`` s."""
    run = SimpleNamespace(
        start_figures=start_figures,
        loss=SimpleNamespace(colours=(None,), target_lab=np.zeros((len(texels), 3))),
        wall_seconds=lambda: wall,
        history=SimpleNamespace(seconds=[]),  # no iteration yet
    )
    scene = SimpleNamespace(texels=texels)
    job = SimpleNamespace(run=run, scene=scene, cfg=cfg or OptimizeConfig(), options=RunOptions(**options))
    figures = RunFigures(job)
    figures._pass = no_pilot
    return figures


@pytest.mark.parametrize("when", ["start", "result"])
def test_a_resumed_run_takes_the_sample_its_start_recorded(when):
    """A run whose start's figures were measured on a sample (kept in its checkpoint) measures the baseline and its
    result on the same texels: the sample is drawn again from its recorded size, windows and seed."""
    texels = sheet(400)
    recorded = TexelSample.draw(texels, 3000, 40, seed=11)
    figures = _figures(texels, {"texel_sample": {"sample": recorded.to_json()}})
    if when == "start":
        figures._choose_sample(renderer=None, max_spp=64)
    again = figures.choice.sample if when == "start" else figures._result_sample()
    for name in ("points", "centres", "windows"):
        np.testing.assert_array_equal(getattr(again, name), getattr(recorded, name))
    assert _figures(texels, {"texel_sample": None})._result_sample() is None  # a start of every texel: every texel


def test_the_result_takes_the_sample_only_where_it_is_far_smaller():
    """The result's figures are of the start's sample where its texels are at most 1 / ``RESULT_SAMPLE_MIN_GAIN``
    of every texel (else every texel: the pictures need them, and the sample would gain little), or where the user
    asked for the sample."""
    recorded = {"texel_sample": {"sample": TexelSample.draw(sheet(400), 3000, 40, seed=11).to_json()}}
    s = _figures(sheet(400), recorded)._result_sample()
    assert RESULT_SAMPLE_MIN_GAIN * (len(s.points) + len(s.windows)) <= s.population
    recorded = {"texel_sample": {"sample": TexelSample.draw(sheet(200), 3000, 40, seed=11).to_json()}}
    assert _figures(sheet(200), recorded)._result_sample() is None  # 3000 points and 4319 window texels of 40 000
    assert len(_figures(sheet(200), recorded, figure_texel_sample=3000)._result_sample().points) == 3000


def test_the_result_shares_its_time_between_the_sample_and_the_pictures():
    """Without a run budget the result's figures on a sample take at most ``RESULT_SAMPLE_SHARE`` of
    ``FINAL_FIGURES_SHARE`` of the run's time, their 64-spp pilot beside it (the finishing choice renders that pass);
    every texel's render for the pictures gets what they leave, its pilot within it. The user's samples per texel
    are taken as given."""
    figures = _figures(sheet(20), wall=1000.0)
    share = FINAL_FIGURES_SHARE * 1000.0
    on_sample, pictures = figures._sample_figures_sampling(), figures._final_sampling(left=share - 30.0)
    assert on_sample.time_budget == pytest.approx(RESULT_SAMPLE_SHARE * share) and not on_sample.pilot_in_budget
    assert on_sample.pilot_spp == PILOT_SPP
    assert pictures.time_budget == pytest.approx(share - 30.0) and pictures.pilot_in_budget
    assert figures._final_sampling(left=-5.0).time_budget == 0.0
    whole = figures._final_sampling()  # no sample: the figures' own render, its pilot outside the time as before
    assert whole.time_budget == pytest.approx(share) and not whole.pilot_in_budget
    fixed = _figures(sheet(20), eval_spp=32)
    assert fixed._sample_figures_sampling().spp == fixed._final_sampling(left=5.0).spp == 32


def test_under_a_budget_the_samples_pilot_is_what_fits():
    """Under a run budget the pilot of the result's figures on a texel sample has as many samples per texel as the
    measured seconds per sample say fit in their share, from the probe's 4 to 64 (a probe where nothing was
    measured)."""
    texels = sheet(400)
    drawn = TexelSample.draw(texels, 3000, 40, seed=11)
    kept = {"texel_sample": {"sample": drawn.to_json()}}
    figures = _figures(texels, kept, cfg=replace(OptimizeConfig(), time_budget=1000.0))
    assert figures._result_sample() is not None
    seconds = RESULT_SAMPLE_SHARE * figures.final_budget
    assert figures._sample_figures_sampling().pilot_spp == PROBE_SPP  # no cost measured, no iteration yet
    sampled = len(drawn.points) + len(drawn.windows)
    for want in (PROBE_SPP, 10, PILOT_SPP):  # seconds per sample of every texel for a pilot of `want` to fit
        figures.per_spp = seconds / (want + 0.5) / sampled * len(texels)
        assert figures._sample_figures_sampling().pilot_spp == want
    figures.per_spp = seconds / 1000 / sampled * len(texels)  # 1000 spp would fit: 64
    assert figures._sample_figures_sampling().pilot_spp == PILOT_SPP
    figures.per_spp = seconds / sampled * len(texels)  # not even one: the probe
    assert figures._sample_figures_sampling().pilot_spp == PROBE_SPP
