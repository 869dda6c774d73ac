"""A spectral optimisation's band plan (``spectral.allocation``): made by a pilot render of the run's start before its
first step (``Viewing.pilot``, the default), recorded in the checkpoint and report.json (``format_version`` 1),
reused bit for bit by a resume (no second pilot: 3 + 3 iterations through a checkpoint are the 6 in one go) and by
``inkopt evaluate``; an RGB run has none."""

import json

import numpy as np
import pytest
from helpers import FAST_RUN, small_chart_scene
from PIL import Image

from inkopt.cli import main
from inkopt.errors import ParameterError
from inkopt.model.spectral import load_ink_table
from inkopt.optim import Optimization, OptimizeConfig
from inkopt.spectral import viewing as viewing_module
from inkopt.spectral.allocation import PLAN_FORMAT, BandPlan
from inkopt.spectral.lights import named_light
from inkopt.spectral.viewing import Viewing

TABLE = load_ink_table("vero-cmykw@spectral")


def spectral_run(scene, viewing: Viewing, iterations: int = 6) -> Optimization:
    cfg = OptimizeConfig(iterations=iterations, spp=2, forward_spp=2, decay=0.5, seed=3)
    return Optimization(scene, cfg.for_scene(scene.kind), threads=2, viewing=viewing)


def test_the_plan_is_the_starts_pilot_and_a_resume_reuses_it_bit_for_bit(tmp_path, monkeypatch):
    scene = small_chart_scene(12, 8, 0.3)
    viewing = Viewing(TABLE, (named_light("D65"), named_light("A")))
    assert viewing.needs_pilot and viewing.key().endswith(":pilot")
    a = spectral_run(scene, viewing)
    a.run()
    want = viewing.planned(a.initial_volume(), scene.texels, threads=1).plan  # the start's pilot, any threads
    assert a.viewing.plan == want and a.viewing.plan.measured["paths"] > 0
    assert a.viewing.plan.measured["effort_hero"] > 0 and a.viewing.plan.measured["effort_bands"] > 0
    b = spectral_run(scene, viewing)
    for _ in range(3):
        b.step()
    b.save_checkpoint(tmp_path / "ck.npz")
    stored = json.loads(str(np.load(tmp_path / "ck.npz")["band_plan"]))
    assert stored["format_version"] == PLAN_FORMAT and BandPlan.from_json(stored) == want
    assert BandPlan.from_json(stored).weights == want.weights  # the floats themselves, through JSON

    def no_pilot(*args, **kwargs):
        raise AssertionError("a resumed run made a new pilot")

    monkeypatch.setattr(viewing_module, "pilot", no_pilot)
    c = spectral_run(scene, viewing)
    c.load_checkpoint(tmp_path / "ck.npz")
    c.run(tmp_path / "ck.npz")
    np.testing.assert_array_equal(a.x, c.x)
    assert a.history.loss == c.history.loss and c.viewing.plan == want
    # the mid grey's weights (no pilot) are another run: its checkpoint is refused
    d = spectral_run(scene, Viewing(TABLE, viewing.lights, pilot=False))
    with pytest.raises(ParameterError, match="different settings"):
        d.load_checkpoint(tmp_path / "ck.npz")


def test_a_damaged_plan_is_refused_in_one_line():
    with pytest.raises(ParameterError, match="plan has format version 2"):
        BandPlan.from_json({"format_version": 2, "groups": [[0]], "weights": None, "hero": False})
    with pytest.raises(ParameterError, match="plan is malformed"):
        BandPlan.from_json({"format_version": PLAN_FORMAT, "groups": [[0, 1]], "hero": False})
    with pytest.raises(ParameterError, match="groups must"):
        BandPlan.from_json({"format_version": PLAN_FORMAT, "groups": [[0, 2]], "weights": None, "hero": False})


def test_the_run_folder_records_the_plan_and_evaluate_reuses_it(tmp_path, capsys):
    Image.new("RGB", (12, 8), (40, 160, 90)).save(tmp_path / "p.png")
    out = tmp_path / "r"
    args = ["slab", str(tmp_path / "p.png"), "--size-mm", "1.5x1x0.5", "--out", str(out), *FAST_RUN]
    assert main([*args, "--inks", "vero-cmykw@spectral", "--illuminants", "D65,A"]) == 0
    assert "band plan: groups (" in capsys.readouterr().err
    plan = json.loads((out / "report.json").read_text())["viewing"]["plan"]
    assert plan["format_version"] == PLAN_FORMAT and sorted(sum(plan["groups"], [])) == list(range(TABLE.bands))
    assert json.loads(str(np.load(out / "checkpoint.npz")["band_plan"])) == plan
    assert main(["evaluate", str(out), "--spp", "4", "--threads", "2", "--no-baselines", "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)
    assert BandPlan.from_json(ev["viewing"]["plan"]) == BandPlan.from_json(plan)
    rgb = tmp_path / "rgb"
    assert main([*args[: -len(FAST_RUN) - 2], "--out", str(rgb), *FAST_RUN]) == 0
    assert "viewing" not in json.loads((rgb / "report.json").read_text())
    assert "band_plan" not in np.load(rgb / "checkpoint.npz")
