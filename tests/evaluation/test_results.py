"""The typed results files (inkopt.evaluation.results): a fresh report.json has exactly the keys scripts read
plus ``format_version``, reads back into the same ``Report``, and files without a version (0) or of a newer one
load or fail as ``io.upgrade_format`` says."""

import json
from dataclasses import replace

import pytest
from helpers import FAST_RUN

from inkopt import charts
from inkopt.cli import main
from inkopt.evaluation.results import Evaluation, Report
from inkopt.io import FormatError

pytest.importorskip("inkopt._core")

# report.json of a slab run as bench/ and the tests read it (the metrics, the run, the scene's and the lighting's
# entries, the settings)
SLAB_REPORT_KEYS = {
    "adjoint_ema",
    "decay",
    "delta_e2000_mean",
    "delta_e76_max",
    "delta_e76_mean",
    "delta_e76_mean_corrected",
    "delta_e76_noise",
    "delta_e76_noise_contribution",
    "delta_e76_p95",
    "delta_e76_rms",
    "delta_e76_rms_denoised",
    "e1",
    "e2",
    "e3",
    "eval_spp",
    "eval_spp_passes",
    "flat_texels",
    "gamma",
    "gradient",
    "init",
    "initial_delta_e76_mean",
    "initial_delta_e76_mean_corrected",
    "initial_eval_spp",
    "initial_ssim",
    "inks",
    "iterations",
    "lighting",
    "lighting_rotate_deg",
    "loss",
    "lr",
    "mottle_l2",
    "mottle_l2_target",
    "optimizer",
    "param",
    "peak_rss_gb",
    "seconds",
    "seconds_iterations",
    "seconds_total",
    "estimate",
    "seconds_per_iteration",
    "seed",
    "size_mm",
    "smooth",
    "spp",
    "spp_adaptive",
    "ssim",
    "texels",
    "threads",
    "time_split",
    "voxels",
    "colour_source",
}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    d = tmp_path_factory.mktemp("run")
    chart = charts.save(charts.colour_chart(24, 16), d / "chart.png")
    assert (
        main(
            [
                "slab",
                str(chart),
                "--size-mm",
                "2x1.333x0.5",
                "--out",
                str(d / "r"),
                *FAST_RUN,
            ]
        )
        == 0
    )
    return d / "r"


def test_report_keys_and_round_trip(run):
    data = json.loads((run / "report.json").read_text())
    # "stop" (why the run ended), "finish_smooth", the baseline guard's "baseline" and "beats_baseline" and the
    # finishing choice's "finish", the loss's "colour_term", the start figures' "initial_texel_sample", the result
    # figures' "texel_sample" and the pictures' "pictures_spp" are the keys added since the files carried a version
    added = {"format_version", "stop", "finish_smooth", "baseline", "beats_baseline", "finish", "colour_term"}
    added |= {"initial_texel_sample", "texel_sample", "pictures_spp"}
    assert set(data) == SLAB_REPORT_KEYS | added and data["format_version"] == 1
    assert data["finish_smooth"] == 0 and data["finish"] is None  # a slab's default: no pass, nothing chosen
    assert data["stop"]["reason"] == "iterations" and data["stop"]["iterations"] == 2
    rep = Report.read(run / "report.json")
    assert rep.to_json() == data and list(rep.to_json()) == list(data)  # the same keys in the same order
    assert rep.scene == {
        "voxels": 24 * 16 * 6,
        "texels": 24 * 16,
        "size_mm": [2.0, 1.333, 0.5],
        "colour_source": "top picture chart.png (24 x 16 px, RGB)",
    }
    assert rep.lighting == {"lighting": "uniform", "lighting_rotate_deg": 0.0}
    assert rep.metrics.delta_e76_mean == data["delta_e76_mean"]
    old = {k: v for k, v in data.items() if k not in ("format_version", "stop")}  # before files carried a version
    assert Report.from_json(old) == replace(rep, stop=None)
    unguarded = {k: v for k, v in data.items() if k not in ("baseline", "beats_baseline")}  # before the guard
    assert Report.from_json(unguarded) == replace(rep, baseline=None, beats_baseline=None)
    assert data["colour_term"] == "squared"
    before_term = {k: v for k, v in data.items() if k != "colour_term"}  # before the colour term was a choice
    assert Report.from_json(before_term) == replace(rep, colour_term=None)
    assert data["initial_texel_sample"] is None  # a small slab's start: every texel
    before_sample = {k: v for k, v in data.items() if k != "initial_texel_sample"}  # before the start's sample
    assert Report.from_json(before_sample) == rep
    assert data["texel_sample"] is None and data["pictures_spp"] == data["eval_spp"]  # every texel: one render
    before_result_sample = {k: v for k, v in data.items() if k not in ("texel_sample", "pictures_spp")}
    assert Report.from_json(before_result_sample) == replace(rep, pictures_spp=None)


def test_newer_format_is_a_one_line_error(run, tmp_path):
    data = json.loads((run / "report.json").read_text())
    (tmp_path / "report.json").write_text(json.dumps({**data, "format_version": 2}))
    with pytest.raises(FormatError, match="format version 2") as err:
        Report.read(tmp_path / "report.json")
    assert "\n" not in str(err.value)


def test_evaluation_json_round_trip(run, capsys):
    assert main(["evaluate", str(run), "--spp", "2", "--no-baselines", "--threads", "2", "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    ev = Evaluation.read(run / "evaluation.json")
    assert ev.to_json() == printed and printed["format_version"] == 2
    assert ev.baselines is None and ev.quantized.spp_printer > 0 and ev.continuous.spp_printer is None
    assert ev.texel_sample is None and ev.differences is None and ev.continuous.stderr is None  # every texel
    # a version-1 file (before texel samples) reads as the same evaluation
    assert Evaluation.from_json({**printed, "format_version": 1}, where="x.json") == ev
    with pytest.raises(FormatError, match="evaluation of format version 7"):
        Evaluation.from_json({**printed, "format_version": 7}, where="x.json")
