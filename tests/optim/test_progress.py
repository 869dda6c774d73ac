"""Progress as log lines when stderr is not a terminal, the whole run's time across resumes, and the names of the
settings that make a checkpoint unresumable."""

import json
import subprocess
import sys

import numpy as np
import pytest

from inkopt import charts
from inkopt.optim.progress import ProgressLines, changed_settings
from inkopt.units import format_duration


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def test_a_line_at_least_every_30_s_with_an_eta():
    clock, lines = Clock(), []
    p = ProgressLines(total=100, start=10, log=lines.append, every_s=30, clock=clock)
    for it in range(11, 101):  # 7 s per iteration
        clock.t += 7.0
        p.update(it, 0.5, 3.0)
    assert lines[0] == "iteration 11/100: loss 0.5, ΔE76 3.00, 7.0 s/iteration, ETA 10 min 23 s"
    assert lines[-1].startswith("iteration 100/100") and lines[-1].endswith("ETA 0 s")
    its = [int(line.split()[1].split("/")[0]) for line in lines]
    # after the first line, one as soon as 30 s have passed: every 5th iteration (35 s) -> never more than 35 s
    assert all(7 * (b - a) <= 35 for a, b in zip(its, its[1:]))
    assert len(lines) <= 2 + 90 * 7 / 30


def test_format_duration():
    assert [format_duration(s) for s in (42, 185, 3720)] == ["42 s", "3 min 05 s", "1 h 02 min"]


def test_changed_settings_names_them():
    old = {"lr": 0.5, "decay": 0.25, "problem": "ab", "lighting": "uniform"}
    new = {"lr": 0.5, "decay": 0.5, "problem": "cd", "lighting": "uniform"}
    assert changed_settings(old, new) == "decay 0.25 -> 0.5, the target, texels or constraints (scene)"


def test_slab_logs_progress_lines_without_a_terminal(tmp_path):
    chart = charts.save(charts.colour_chart(24, 16), tmp_path / "chart.png")
    out = tmp_path / "run"
    args = ["slab", str(chart), "--size-mm", "2x1.333x0.5", "--out", str(out), "--iterations", "3"]
    args += ["--spp", "1", "--forward-spp", "2", "--eval-spp", "2", "--threads", "1", "--log-every", "0"]
    r = subprocess.run([sys.executable, "-m", "inkopt.cli", *args], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    lines = [line for line in r.stderr.splitlines() if line.startswith("iteration ")]
    assert [line.split(":")[0] for line in lines] == ["iteration 1/3", "iteration 2/3", "iteration 3/3"]
    assert all("ETA" in line for line in lines)
    first = float(np.load(out / "checkpoint.npz")["wall_seconds"])
    r2 = subprocess.run(
        [sys.executable, "-m", "inkopt.cli", *args[:7], "5", *args[8:], "--resume"], capture_output=True, text=True
    )
    assert r2.returncode == 0, r2.stderr
    assert "whole run across resumes" in r2.stdout
    rep = json.loads((out / "report.json").read_text())
    assert rep["seconds_total"] >= first + rep["seconds"]


def test_dry_run_prints_the_estimate_and_writes_nothing(tmp_path):
    chart = charts.save(charts.colour_chart(24, 16), tmp_path / "chart.png")
    out = tmp_path / "run"
    args = ["slab", str(chart), "--size-mm", "2x1.333x0.5", "--out", str(out), "--iterations", "7", "--threads", "1"]
    r = subprocess.run([sys.executable, "-m", "inkopt.cli", *args, "--dry-run"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert (
        r.stdout.startswith("estimate: up to 7 iterations x ") and "peak memory ~" in r.stdout and "disk ~" in r.stdout
    )
    assert len(r.stdout.strip().splitlines()) == 1 and not out.exists()
    assert "time budget" not in r.stdout
    r = subprocess.run(
        [sys.executable, "-m", "inkopt.cli", *args, "--iterations", "100000", "--time-budget", "2s", "--dry-run"],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().endswith("; the time budget (2 s) ends the run sooner"), r.stdout


def test_estimate_counts_the_iterations_left_and_is_recorded(tmp_path):
    from inkopt.estimate import Estimate

    chart = charts.save(charts.colour_chart(24, 16), tmp_path / "chart.png")
    out = tmp_path / "run"
    args = ["slab", str(chart), "--size-mm", "2x1.333x0.5", "--out", str(out), "--threads", "1"]
    args += ["--spp", "1", "--forward-spp", "1", "--eval-spp", "2", "--checkpoint-every", "1"]
    r = subprocess.run([sys.executable, "-m", "inkopt.cli", *args, "--iterations", "2"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    est = Estimate.from_json(json.loads((out / "report.json").read_text())["estimate"])
    assert est.iterations == 2 and est.seconds == est.seconds_per_iteration * 2 and est.seconds_per_iteration > 0
    # 24 x 16 x 6 voxels, 5 inks: volume (4 B per ink per voxel) and checkpoint (12 B per ink per voxel) bound
    assert est.disk_bytes >= 16 * 5 * 24 * 16 * 6 and est.quantized_bytes > 6 * 24 * 16 * 6
    r = subprocess.run(
        [sys.executable, "-m", "inkopt.cli", *args, "--iterations", "5", "--resume", "--dry-run"],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0 and r.stdout.startswith("estimate: up to 3 iterations x "), r.stderr


def test_an_estimate_says_whether_it_was_measured_or_scaled():
    """A scaled estimate (a coarse-to-fine job's fine stage) says so in its line; a report's estimate recorded before
    ``scaled`` was kept reads as measured."""
    from inkopt.estimate import Estimate

    measured = Estimate(3, 2.0, 6.0, 0.5, 10**6, 10**6, 1.5)
    assert "; measured in 1.5 s" in measured.line()
    old = measured.to_json()
    del old["scaled"]
    assert Estimate.from_json(old) == measured
    scaled = Estimate(3, 2.0, 6.0, 0.5, 10**6, 10**6, 0.2, scaled=True)
    assert "; scaled from the coarse stage's iterations in 0.2 s" in scaled.line()
    assert Estimate.from_json(scaled.to_json()) == scaled


@pytest.mark.parametrize(
    "fixed, per_texel, n_tex",
    [
        (0.7, 250e-6, 386_829),  # Spot 40 mm's fine stage: the fixed part dwarfs 512 texels' passes
        (0.001, 70e-6, 40_000),  # a slab: hardly any fixed part
        (0.05, 1e-4, 300),  # fewer texels than the first subset: all of them measured
    ],
)
@pytest.mark.parametrize("stall", [None, 1, 3])
def test_calibration_extrapolates_the_texels_past_the_fixed_part(fixed, per_texel, n_tex, stall):
    """Passes taking fixed + per_texel n seconds, each with up to 30 ms of jitter (a shared machine's), the first 3 s
    longer (one-off set-up) and, with ``stall``, pass number ``stall`` (from 0) 1.3 s longer (a stall seen on a resumed
    40 mm run, which made a 24x over-estimate; 1: a one-texel pass, 3: the first subset's): the calibration's
    figure for all texels is within 30 ms x n_tex / n of the truth, n being the subset it grew to (its passes last >=
    max(MIN_TEXEL_SECONDS, FIXED_MULTIPLE x fixed) beyond the fixed part, so within ~25 % here), and it never measures
    more than 16x the subset it needed."""
    from inkopt.estimate import FIXED_MULTIPLE, MIN_TEXEL_SECONDS, texel_passes_seconds

    rng = np.random.default_rng(5)
    sizes = []

    def passes(n):
        sizes.append(n)
        extra = 3.0 if len(sizes) == 1 else 1.3 if len(sizes) == 1 + (stall or -2) else 0.0
        return fixed + per_texel * n + rng.uniform(0.0, 0.03) + extra

    got = texel_passes_seconds(passes, n_tex)
    truth = fixed + per_texel * n_tex
    n = sizes[-1]
    enough = max(MIN_TEXEL_SECONDS, FIXED_MULTIPLE * fixed)
    assert abs(got - truth) <= 0.03 * n_tex / n + 0.03, (got, truth, sizes)
    assert sizes[:3] == [1, 1, 1] and (n == n_tex or per_texel * n >= enough - 0.03)
    assert n <= max(16 * enough / per_texel, 256)


@pytest.mark.parametrize("n_tex, n", [(386_829, 256), (386_829, 16_384), (5_000, 4_999), (300, 300), (1_000, 100)])
def test_calibration_samples_runs_of_consecutive_texels_over_the_whole_order(n_tex, n):
    """The calibration's subsets: n distinct sorted texels in at most SAMPLE_RUNS runs of consecutive ones, each of
    at least 64 (or all), one in each equal stretch of the texel order, so every part of the surface is timed."""
    from inkopt.estimate import SAMPLE_RUNS, texel_runs

    rng = np.random.default_rng(2)
    for _ in range(20):
        idx = texel_runs(n_tex, n, rng)
        assert len(idx) == n and idx[0] >= 0 and idx[-1] < n_tex and np.all(np.diff(idx) > 0)
        breaks = np.flatnonzero(np.diff(idx) > 1)
        runs = np.split(idx, breaks + 1)
        assert len(runs) <= min(SAMPLE_RUNS, max(1, n // 64)) and min(map(len, runs)) >= min(64, n)
        stretch = n_tex / max(1, min(SAMPLE_RUNS, n // 64))
        assert len({int(r[0] // stretch) for r in runs}) == len(runs)  # no two runs begin in one stretch
