"""Tests of the baseline guard (``inkopt.evaluation.guard`` and its steps in ``run.run_optimisation``): a run measures
the extrusion baseline's figures once at its start (the start's own when it starts from it), keeps them in its
checkpoints, and reports a result worse than them beyond the figures' noise in a warning line and report.json.

The runs are a 24 x 16-voxel colour chart on a 0.5 mm slab in CMYKW (the package ships that ink set's colour table),
~1 s each. From white, a run of one iteration stays near its start, ~70 ΔE76 against the baseline's ~40: worse far
beyond the figures' noise (their uncertainty is ~0.1-0.4 ΔE76 at these samples)."""

import json
import math

import numpy as np
import pytest
from helpers import small_chart_scene

from inkopt import runfigures
from inkopt.cli.runargs import print_run_summary
from inkopt.errors import ParameterError
from inkopt.evaluation import guard
from inkopt.evaluation.guard import BaselineCheck, figure_error
from inkopt.evaluation.metrics import Metrics
from inkopt.evaluation.results import Report
from inkopt.model import Volume
from inkopt.optim import OptimizeConfig
from inkopt.run import RunOptions, run_optimisation

pytest.importorskip("inkopt._core")

FIGURE_KEYS = {"delta_e76_mean_corrected", "delta_e76_error", "ssim", "eval_spp", "loss"}


@pytest.fixture(scope="module")
def scene():
    return small_chart_scene()


def _cfg(**kw) -> OptimizeConfig:
    return OptimizeConfig(**{"iterations": 1, "spp": 4, "forward_spp": 16, **kw})


def _run(scene, out, cfg, lines=None, **kw):
    log = lines.append if lines is not None else lambda m: None
    return run_optimisation(scene, out, cfg, RunOptions(threads=2, log=log, **kw))


@pytest.fixture
def renders(monkeypatch):
    """The figures' renders of the runs in the test, one entry (their ``Sampling``) each."""
    calls, real = [], runfigures.adaptive_render

    def counted(render, target_lab, sampling, log=None, **kw):
        calls.append(sampling)
        return real(render, target_lab, sampling, log=log, **kw)

    monkeypatch.setattr(runfigures, "adaptive_render", counted)
    return calls


def test_a_worse_result_is_warned_about_and_reported(scene, tmp_path, renders, capsys):
    lines = []
    rep = _run(scene, tmp_path / "r", _cfg(init="white"), lines)
    assert len(renders) == 3  # the start, the baseline, the result
    warnings = [m for m in lines if m.startswith("warning: the result")]
    assert len(warnings) == 1 and "worse than the extrusion baseline" in warnings[0], lines
    assert rep.beats_baseline is False
    base = rep.baseline["extrusion"]
    assert FIGURE_KEYS <= set(base) and base["eval_spp"] == 64  # one pilot, like the start's
    assert base["difference_delta_e76"] > base["tolerance_delta_e76"] > 0
    assert base["difference_delta_e76"] == pytest.approx(
        rep.metrics.delta_e76_mean_corrected - base["delta_e76_mean_corrected"]
    )
    on_disk = json.loads((tmp_path / "r" / "report.json").read_text())
    assert on_disk["beats_baseline"] is False and on_disk["baseline"] == rep.baseline
    kept = json.loads(str(np.load(tmp_path / "r" / "checkpoint.npz")["baseline_figures"]))
    assert kept["extrusion"]["delta_e76_mean_corrected"] == base["delta_e76_mean_corrected"]
    print_run_summary(Report.read(tmp_path / "r" / "report.json"), "white")
    assert "against the extrusion baseline's" in capsys.readouterr().out.replace("\n", " ")


def test_a_run_from_the_baseline_measures_it_once_and_beats_it(scene, tmp_path, renders, capsys):
    """Started from the extrusion baseline, the start's figures are the baseline's (not rendered twice); 20
    iterations improve on it by far more than the noise: no warning, no note."""
    lines = []
    rep = _run(scene, tmp_path / "r", _cfg(init="extrusion", iterations=20), lines)
    assert len(renders) == 2  # the start (= the baseline) and the result
    base = rep.baseline["extrusion"]
    assert base["delta_e76_mean_corrected"] == rep.initial_delta_e76_mean_corrected
    assert rep.beats_baseline is True and base["difference_delta_e76"] < -base["tolerance_delta_e76"]
    assert not [m for m in lines if m.startswith(("warning", "note"))], lines
    print_run_summary(rep, "extrusion")
    assert ": better" in capsys.readouterr().out


def test_resume_does_not_measure_the_baseline_again(scene, tmp_path, renders):
    out = tmp_path / "r"
    first = _run(scene, out, _cfg(init="white", iterations=2))
    assert len(renders) == 3
    resumed = _run(scene, out, _cfg(init="white", iterations=4), resume=True)
    assert len(renders) == 4  # the result's figures only
    assert resumed.iterations == 4
    kept = ("delta_e76_mean_corrected", "delta_e76_error", "eval_spp")
    assert [resumed.baseline["extrusion"][k] for k in kept] == [first.baseline["extrusion"][k] for k in kept]


def test_figures_of_a_texel_sample_agree_with_every_texels_and_keep_the_guard(scene, tmp_path, renders, capsys):
    """Told to measure its figures on a texel sample (``figure_texel_sample``), a run measures its start, the baseline
    and its result on the same texels, keeps their standard errors (no loss: the sample's is not the run's), reports
    the sample, and still warns about a result far worse than the baseline. Its figures agree with a run's over
    every texel from the same white start within four of their combined uncertainties (the difference is which
    texels were drawn and the render noise; four: a two-sided chance of ~6e-5 under a normal error)."""
    every = _run(scene, tmp_path / "every", _cfg(init="white"), figure_texel_sample=0)
    lines = []
    rep = _run(scene, tmp_path / "sample", _cfg(init="white"), lines, figure_texel_sample=200)
    assert len(renders) == 4  # every texel: the start, the baseline, the result; the sample's run: the result
    assert every.initial_texel_sample is None and every.baseline["extrusion"]["texel_sample"] is None
    drawn = rep.initial_texel_sample["sample"]
    assert (drawn["texels"], drawn["population"]) == (200, len(scene.texels))
    assert rep.initial_texel_sample["stderr"]["delta_e76_mean_corrected"] > 0
    base = rep.baseline["extrusion"]
    assert base["texel_sample"]["sample"] == drawn and base["loss"] is None
    assert rep.beats_baseline is False and any("on 200 sampled texels" in m for m in lines), lines
    kept = {d: json.loads(str(np.load(tmp_path / d / "checkpoint.npz")["start_figures"])) for d in ("every", "sample")}
    for a, b in ((kept["sample"], kept["every"]), (base, every.baseline["extrusion"])):
        diff = a["delta_e76_mean_corrected"] - b["delta_e76_mean_corrected"]
        assert abs(diff) <= 4 * math.hypot(a["delta_e76_error"], b["delta_e76_error"]), (a, b)
    assert kept["sample"]["delta_e76_error"] > kept["every"]["delta_e76_error"]  # 200 of 384 texels
    # the result (the same mixture in both runs) on the start's texels, its pictures of every texel
    assert rep.texel_sample["sample"] == drawn and every.texel_sample is None
    assert rep.texel_sample["stderr"]["delta_e76_mean_corrected"] > 0 and rep.pictures_spp >= 1
    errors = [r.baseline["extrusion"]["result_delta_e76_error"] for r in (rep, every)]
    diff = rep.metrics.delta_e76_mean_corrected - every.metrics.delta_e76_mean_corrected
    assert abs(diff) <= 4 * math.hypot(*errors) and errors[0] > errors[1], (diff, errors)
    print_run_summary(Report.read(tmp_path / "sample" / "report.json"), "white")
    assert "; both on 200 sampled texels) after" in capsys.readouterr().out
    with pytest.raises(ParameterError, match="figure_texel_sample"):
        _run(scene, tmp_path / "bad", _cfg(), figure_texel_sample=1)


def test_a_sample_a_pilot_chose_takes_the_time_every_texel_would(scene, tmp_path, monkeypatch):
    """A sample chosen by the pilot's prediction renders beyond the pilot's 64 spp, adaptively, within the time the
    prediction gave every texel's pass (the chart is too small for the pilot to choose one: the choice is given)."""

    def chosen(seconds):
        def choose(render, texels, target_lab, options, seed, cmap, target):
            drawn = runfigures.TexelSample.draw(texels, 200, 50, seed)
            return runfigures.SamplingChoice(drawn, False, full_seconds=seconds, sample_seconds=seconds / 4)

        return choose

    spp = {}
    for name, seconds in (("long", 60.0), ("spent", 0.0)):
        monkeypatch.setattr(runfigures, "_sample_can_win", lambda texels, seed: True)
        monkeypatch.setattr(runfigures, "choose_sampling", chosen(seconds))
        rep = _run(scene, tmp_path / name, _cfg(init="white"))
        spp[name] = (rep.initial_eval_spp, rep.baseline["extrusion"]["eval_spp"])
        assert rep.initial_texel_sample["sample"]["texels"] == 200
    # the white start's large errors meet the noise target at the pilot's 64 spp, the baseline's need more; with no
    # time, a probe pass alone
    assert spp["long"][0] >= 64 and spp["long"][1] > 64 and max(spp["spent"]) < 64, spp


def test_the_guard_changes_no_result(scene, tmp_path):
    """The baseline's render uses the evaluation's seeds and leaves the optimisation as it was: the same mixture
    with the guard on and off, and (at fixed samples: adaptive ones follow the run's time) the same figures."""
    on = _run(scene, tmp_path / "on", _cfg(init="white", iterations=3), eval_spp=16)
    off = _run(scene, tmp_path / "off", _cfg(init="white", iterations=3), eval_spp=16, baseline_guard=False)
    assert off.baseline is None and off.beats_baseline is None and on.beats_baseline is not None
    a, b = (Volume.load(tmp_path / d / "volume.npz").mixture for d in ("on", "off"))
    np.testing.assert_array_equal(a, b)
    assert on.metrics.delta_e76_mean == off.metrics.delta_e76_mean


def test_no_cached_table_no_check(scene, tmp_path, renders, monkeypatch):
    """Without a cached colour table the run builds none for the guard: a note, no report fields."""
    monkeypatch.setattr(guard, "table_available", lambda volume: False)
    lines = []
    rep = _run(scene, tmp_path / "r", _cfg(init="white"), lines)
    assert len(renders) == 2 and rep.baseline is None and rep.beats_baseline is None
    assert any(m.startswith("note: the colour table of these inks is not cached") for m in lines), lines
    assert not any(m.startswith("warning") for m in lines)


def test_the_default_inks_table_is_available(scene):
    assert guard.table_available(scene.volume)  # shipped with the package (colour_table.PACKAGED)


def test_check_tells_noise_from_a_loss():
    base = {"delta_e76_mean_corrected": 9.0, "delta_e76_error": 0.4, "eval_spp": 64}
    worse = BaselineCheck("extrusion", 10.0, 0.3, base)
    assert worse.tolerance == pytest.approx(0.5) and worse.difference == pytest.approx(1.0)
    assert not worse.beats and worse.note() is None
    assert worse.warning().startswith(
        "warning: the result (noise-corrected ΔE76 10.00 ± 0.30) is worse than the extrusion baseline (9.00 ± 0.40"
    )
    close = BaselineCheck("extrusion", 9.4, 0.3, base)  # above it, within the noise
    assert close.beats and close.warning() is None and "not told apart" in close.note()
    better = BaselineCheck("extrusion", 8.0, 0.3, base)
    assert better.beats and better.warning() is None and better.note() is None


def test_figure_error():
    m = Metrics(10.0, 20.0, 9.0, 0.9, 0.01, 100.0, 0.0, 0.0, None, None, 0, 3.0, 2.0, 8.0)
    assert figure_error(m, 300) == pytest.approx(0.35 * 2.0 + 3.0 / 30.0)
    assert figure_error(Metrics(10.0, 20.0, 9.0, 0.9, 0.01, 100.0, 0.0, 0.0, None, None, 0), 300) == 0.0


def test_older_reports_read_without_the_fields(scene, tmp_path):
    rep = _run(scene, tmp_path / "r", _cfg(init="white"))
    data = rep.to_json()
    again = Report.from_json(data)
    assert again.baseline == rep.baseline and again.beats_baseline is False
    old = {k: v for k, v in data.items() if k not in ("baseline", "beats_baseline")}
    read = Report.from_json(old)
    assert read.baseline is None and read.beats_baseline is None and read.scene == again.scene
