"""When a run ends (``optim/stopping.py``): the training curve's trend, the convergence rule, the time budget, and a
stopped run that resumes exactly."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from helpers import small_chart_scene
from helpers import small_run as run

from inkopt.optim import OptimizeConfig
from inkopt.optim.stopping import CHECK_FROM, Schedule, training_trend
from inkopt.units import parse_duration


def ar1(rng, n: int, rho: float) -> np.ndarray:
    e = np.empty(n)
    e[0] = rng.standard_normal() / math.sqrt(1 - rho**2)
    for i in range(1, n):
        e[i] = rho * e[i - 1] + rng.standard_normal()
    return e


@pytest.mark.parametrize("rho", [0.0, 0.5])
def test_trend_slope_and_its_standard_error(rho):
    """A falling line with AR(1) noise: the slope is unbiased and slope +- 2 standard errors covers the true slope
    about as often as it should. 1000 draws: the coverage's own standard error is ~0.7 %; the serial-correlation
    allowance is first-order (95.5 % measured at rho 0, 92 % at rho 0.5 for the nominal 95.4 %), so the bounds are
    0.88-0.99; without the allowance, rho 0.5 covers only ~75 %."""
    rng = np.random.default_rng(1)
    n, hits, slopes = 60, 0, []
    for _ in range(1000):
        tr = training_trend(10 - 0.05 * np.arange(n) + 0.1 * ar1(rng, n, rho), n)
        slopes.append(tr.slope)
        hits += abs(tr.slope + 0.05) < 2 * tr.slope_se
    assert 0.88 <= hits / 1000 <= 0.99
    se_mean = np.std(slopes) / math.sqrt(len(slopes))
    assert abs(np.mean(slopes) + 0.05) < 4 * se_mean
    assert training_trend(np.ones(10)) is None  # shorter than the window


def simulate(cfg, curve, per_s=1.0, setup_s=0.0, reserve=0.0, schedule=None):
    """Drive a Schedule over a synthetic training curve as the loop does: plan, step, until the planned end."""
    s = schedule or Schedule.for_config(cfg)
    de, secs, it = [], [], 0
    while True:
        s.plan(cfg, it, de, secs, setup_s + sum(secs), reserve)
        if it >= min(cfg.iterations, s.end):
            return s, it, setup_s + sum(secs)
        de.append(curve(it))
        secs.append(per_s)
        it += 1


def test_converged_rule_fires_once_little_is_left_and_the_decay_follows():
    """An exponential curve with noise: the rule fires only once the true fall over the next 50 iterations is below
    the stop gain (it errs towards running longer), and then the run ends a decay's length later. It fires late on
    such a curve (at a true fall of 0.01-0.02 over 20 noise draws, where 0.2 is at iteration 111): the window's
    slope is its middle's, steeper than the end's on a convex curve, and the noise's two standard errors add
    ~0.08. Real curves bend less (Spot 20 mm's fires at 154 with 0.075 left)."""
    rng = np.random.default_rng(2)
    noise = 0.05 * ar1(rng, 400, 0.5)

    def curve(t):
        return 10 + 20 * math.exp(-t / 25) + noise[t]

    cfg = OptimizeConfig(iterations=300)
    s, end, _ = simulate(cfg, curve)
    p = s.converged_at
    assert s.reason == "converged" and CHECK_FROM <= p < 300
    true_gain = 20 * math.exp(-p / 25) * (1 - math.exp(-50 / 25))
    assert true_gain < cfg.stop_gain
    assert true_gain > 0.005  # not absurdly late: 0.005 is 92 iterations after 0.2
    assert end == s.end == math.ceil(p / (1 - cfg.decay))
    # off: the run goes to its maximum
    s0, end0, _ = simulate(OptimizeConfig(iterations=300, stop_gain=0.0), curve)
    assert end0 == 300 and s0.reason == "iterations" and s0.fixed


def test_still_falling_runs_to_the_maximum():
    cfg = OptimizeConfig(iterations=120)
    s, end, _ = simulate(cfg, lambda t: 30 - 0.1 * t)
    assert end == 120 and s.reason == "iterations" and s.converged_at is None


def test_time_budget_places_the_decay_and_ends_in_time():
    """1 s per iteration, 12 s of set-up, a 200 s budget with 20 s kept for afterwards: the run ends at the last
    iteration that fits (168), and the decay (its last quarter) was planned for that end."""
    cfg = OptimizeConfig(iterations=1000, time_budget=200.0, stop_gain=0.0)
    s, end, elapsed = simulate(cfg, lambda t: 30 - 0.1 * t, setup_s=12.0, reserve=20.0)
    assert s.reason == "time budget" and end == 168 and elapsed == 180.0
    assert s.frozen  # the decay began at iteration 126 and its plan held


def test_time_budget_slower_iterations_during_the_decay_still_stop_in_time():
    cfg = OptimizeConfig(iterations=1000, time_budget=100.0, stop_gain=0.0)
    s = Schedule.for_config(cfg)
    secs = [1.0] * 80
    s.plan(cfg, 80, [0.0] * 80, secs, 80.0)
    assert s.frozen and s.end == 100
    secs += [5.0] * 10  # the machine slows down: the next iteration would not fit
    s.plan(cfg, 90, [0.0] * 90, secs, 96.0)
    assert s.end == 90 and s.reason == "time budget"


def test_a_reserve_given_as_a_function_of_the_set_up_is_kept():
    """A reserve given as a function gets the run's seconds outside its iterations (12 s of set-up here, every
    time) and the run ends where that many seconds are kept: as the 20 s reserve of the test above."""
    cfg = OptimizeConfig(iterations=1000, time_budget=200.0, stop_gain=0.0)
    seen = set()

    def reserve(setup_s: float) -> float:
        seen.add(setup_s)
        return setup_s + 8.0

    s, end, elapsed = simulate(cfg, lambda t: 30 - 0.1 * t, setup_s=12.0, reserve=reserve)
    assert seen == {12.0} and s.reason == "time budget" and end == 168 and elapsed == 180.0


def test_a_fixed_schedule_is_not_moved():
    cfg = OptimizeConfig(iterations=40, schedule_iterations=300)
    s, end, _ = simulate(cfg, lambda t: 10.0)  # flat: would converge at once
    assert s.fixed and s.end == 300 and end == 40


def test_the_loop_stops_when_converged_and_resumes_exactly(tmp_path):
    """A small chart with a generous stop gain: the rule fires at its first check and the decay runs to
    ceil(30 / 0.75) = 40; a run stopped at 35 and resumed from its checkpoint ends at the same iteration with
    bit-identical variables."""
    scene = small_chart_scene(12, 8, 0.3)
    kw = dict(iterations=500, stop_gain=100.0, forward_spp=4, spp=2)
    a = run(scene, **kw)
    a.run()
    assert a.iteration == 40 and a.schedule.reason == "converged" and a.schedule.converged_at == CHECK_FROM
    assert "converged at iteration 30" in a.plan_line()
    b = run(scene, **kw)
    for _ in range(35):
        b.plan()
        b.step()
    b.save_checkpoint(tmp_path / "ck.npz")
    c = run(scene, **kw)
    c.load_checkpoint(tmp_path / "ck.npz")
    assert c.schedule == b.schedule
    c.run(tmp_path / "ck.npz")
    assert c.iteration == 40
    np.testing.assert_array_equal(a.x, c.x)
    # a larger maximum does not move a converged run's end
    d = run(scene, **{**kw, "iterations": 900})
    d.load_checkpoint(tmp_path / "ck.npz")
    d.run()
    assert d.iteration == 40


@pytest.mark.parametrize("coarse", [None, "0"])
def test_slab_cli_time_budget_and_report(tmp_path, coarse):
    """`inkopt slab --time-budget 6s` with a maximum far out of reach ends by the budget and says so; with a budget
    the run goes coarse to fine by default (the coarse stage in DIR/coarse/), `--coarse-dpi 0` runs plain."""
    from inkopt import charts
    from inkopt.cli import main

    chart = charts.save(charts.colour_chart(24, 16), tmp_path / "chart.png")
    out = tmp_path / "r"
    args = ["slab", str(chart), "--size-mm", "2x1.333x0.5", "--out", str(out), "--threads", "2"]
    args += ["--iterations", "100000", "--time-budget", "6s", "--stop-gain", "0", "--spp", "1", "--forward-spp", "2"]
    assert main(args + (["--coarse-dpi", coarse] if coarse else [])) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["stop"]["reason"] == "time budget" and rep["stop"]["time_budget_s"] == 6.0
    assert 0 < rep["iterations"] < 100000
    assert (out / "coarse" / "report.json").is_file() == (coarse is None)
    if coarse is None:
        assert rep["init"] == str(out / "coarse" / "fine_start.npz")
    # the budget is spent, not cut short (a lower bound holds on a loaded machine too; an upper bound on wall
    # time would not): the plan fills at least half of it
    assert rep["seconds_total"] >= 0.5 * rep["stop"]["time_budget_s"]


@pytest.mark.parametrize(
    "text,seconds", [("1800", 1800), ("90s", 90), ("30m", 1800), ("1h", 3600), ("1h30m", 5400), ("2.5m", 150)]
)
def test_parse_duration(text, seconds):
    assert parse_duration(text) == seconds


@pytest.mark.parametrize("text", ["", "soon", "0", "-5m", "30x", "m"])
def test_parse_duration_refuses(text):
    with pytest.raises(ValueError, match="duration"):
        parse_duration(text)


def test_coarse_to_fine_from_the_command_line(tmp_path, capsys):
    """`inkopt slab --coarse-dpi 150`: a coarse run in DIR/coarse/, its result moved unsmoothed onto the 300-DPI grid as
    the start of the fine run (whose report names it), and a resume of the finished job does not redo the coarse
    stage."""
    from inkopt import charts
    from inkopt.cli import main

    chart = charts.save(charts.colour_chart(48, 32), tmp_path / "chart.png")
    out = tmp_path / "r"
    args = ["slab", str(chart), "--size-mm", "4.064x2.709x0.5", "--out", str(out), "--threads", "2"]
    args += ["--iterations", "3", "--spp", "1", "--forward-spp", "2", "--eval-spp", "4", "--finish-smooth", "1"]
    args += ["--coarse-dpi", "150"]
    assert main(args) == 0
    coarse = json.loads((out / "coarse" / "report.json").read_text())
    fine = json.loads((out / "report.json").read_text())
    assert coarse["voxels"] * 8 == fine["voxels"] and coarse["iterations"] == 3
    assert coarse["finish_smooth"] == 0 and fine["finish_smooth"] == 1  # the fine stage's start is not smoothed
    assert fine["init"] == str(out / "coarse" / "fine_start.npz") and fine["iterations"] == 3
    capsys.readouterr()
    assert main(args + ["--resume"]) == 0
    assert "coarse stage" not in capsys.readouterr().err
    assert main(args[:-1] + ["600"]) == 2  # not coarser than the run's own grid: one line, exit 2
    assert "--coarse-dpi must lie between 0 and the run's DPI" in capsys.readouterr().err
