"""Tests of the choice of a texel sample for a run's start and baseline figures (``inkopt.runfigures``): no pilot
where no sample can be twice as fast, and a resumed run's baseline on the sample its start's figures recorded. The
figures themselves, sampled and whole, are tested through runs in tests/test_baseline_guard.py."""

from types import SimpleNamespace

import numpy as np

from inkopt.evaluation.sample import TexelSample
from inkopt.model import Texels
from inkopt.optim import OptimizeConfig
from inkopt.run import RunOptions
from inkopt.runfigures import RunFigures, _sample_can_win


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


def test_a_resumed_run_takes_the_sample_its_start_recorded():
    """A run whose start's figures were measured on a sample (kept in its checkpoint) measures the baseline on the
    same texels: the sample is drawn again from its recorded size, windows and seed."""
    texels = sheet(200)
    recorded = TexelSample.draw(texels, 3000, 40, seed=11)
    run = SimpleNamespace(
        start_figures={"texel_sample": {"sample": recorded.to_json()}},
        loss=SimpleNamespace(colours=(None,), target_lab=np.zeros((len(texels), 3))),
        wall_seconds=lambda: 0.0,
    )
    job = SimpleNamespace(run=run, scene=SimpleNamespace(texels=texels), cfg=OptimizeConfig(), options=RunOptions())
    figures = RunFigures(job)
    figures._pass = no_pilot
    figures._choose_sample(renderer=None, max_spp=64)
    again = figures.choice.sample
    for name in ("points", "centres", "windows"):
        np.testing.assert_array_equal(getattr(again, name), getattr(recorded, name))
