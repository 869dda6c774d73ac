"""Coarse to fine as a job (``coarse.run_coarse_to_fine``): from a print-shop baseline the fine stage starts from the
correction transfer (the fine grid's baseline plus the coarse stage's change), and its baseline guard takes that
baseline as made; from white it starts from the plain transfer of the coarse result."""

import numpy as np
import pytest

import inkopt.coarse
import inkopt.run
from inkopt import charts
from inkopt.coarse import (
    COARSE_BUDGET_SHARE,
    COARSE_MIN_SHARE,
    FINE_FIXED_SECONDS,
    FINE_ITERATION_EXPONENT,
    FINE_SETUP_FACTOR,
    coarse_reserve,
    fine_iteration_seconds,
    fine_stage_seconds,
    run_coarse_to_fine,
)
from inkopt.evaluation.baselines import baseline_layers
from inkopt.model import InkTable, Volume
from inkopt.optim import OptimizeConfig
from inkopt.optim.transfer import Baseline, destination, write_transferred_volume
from inkopt.run import RunOptions
from inkopt.rundir import RunDir
from inkopt.scenes import build_scene
from inkopt.scenes.spec import SlabSpec

INKS = InkTable.parse("vero-cmykw")


@pytest.fixture(scope="module")
def spec(tmp_path_factory):
    chart = charts.save(charts.colour_chart(24, 16), tmp_path_factory.mktemp("chart") / "chart.png")
    return SlabSpec(str(chart), (2.0, 4 / 3, 0.5))


def job(spec, out, init: str, monkeypatch) -> dict:
    """A 2 + 2 iteration coarse-to-fine job (150 then 300 DPI) from ``init``; returns how often each module made a
    baseline."""
    made = {"coarse": 0, "run": 0}

    def counted(where):
        def make(*args, **kw):
            made[where] += 1
            return baseline_layers(*args, **kw)

        return make

    monkeypatch.setattr(inkopt.coarse, "baseline_layers", counted("coarse"))
    monkeypatch.setattr(inkopt.run, "baseline_layers", counted("run"))
    cfg = OptimizeConfig(iterations=2, spp=2, forward_spp=4, init=init)
    rep = run_coarse_to_fine(spec, INKS, out, cfg, 150.0, RunOptions(eval_spp=4, threads=1, log=lambda m: None))
    assert rep.iterations == 2 and rep.baseline is not None  # the fine stage's guard measured the baseline
    return made


def start_rows(job_dir, fine) -> tuple[np.ndarray, np.ndarray]:
    """The fine stage's start of the job in ``job_dir``: its free voxels (F,), checked to be the run of the scene
    ``fine``'s, and their mixtures (F, N)."""
    with np.load(job_dir / "coarse" / "fine_start.npz") as f:
        index, rows = f["free_index"], f["free_rows"]
    np.testing.assert_array_equal(index, destination(fine.volume, fine.fixed_share).free_index)
    return index, rows


def test_a_job_from_the_extrusion_baseline_starts_its_fine_stage_from_the_correction(spec, tmp_path, monkeypatch):
    made = job(spec, tmp_path / "job", "extrusion", monkeypatch)
    # the coarse and fine grids' baselines (coarse), the coarse one also the coarse run's start; the runs make none
    assert made == {"coarse": 2, "run": 0}
    coarse, fine = build_scene(SlabSpec(spec.top, spec.size_mm, dpi=150.0), INKS), build_scene(spec, INKS)
    b_c = baseline_layers("extrusion", coarse.volume, coarse.texels, coarse.target_rgb, coarse.fixed_share)
    b_f = baseline_layers("extrusion", fine.volume, fine.texels, fine.target_rgb, fine.fixed_share)
    result = RunDir(tmp_path / "job" / "coarse").load_volume()
    want = write_transferred_volume(
        result,
        fine.volume,
        fine.fixed_share,
        tmp_path / "want.npz",
        baseline=Baseline(coarse.volume.with_mixture(b_c.array()), b_f),
    )
    index, got = start_rows(tmp_path / "job", fine)
    np.testing.assert_array_equal(got, Volume.load(want).mixture.reshape(-1, len(INKS))[index])
    plain = Volume.load(write_transferred_volume(result, fine.volume, fine.fixed_share, tmp_path / "p.npz")).mixture
    assert np.abs(got - plain.reshape(-1, len(INKS))[index]).max() > 0.05  # the baseline's detail: not the plain one


def test_a_job_from_white_starts_its_fine_stage_from_the_plain_transfer(spec, tmp_path, monkeypatch):
    made = job(spec, tmp_path / "job", "white", monkeypatch)
    assert made == {"coarse": 0, "run": 1}  # the fine stage's guard only
    fine = build_scene(spec, INKS)
    result = RunDir(tmp_path / "job" / "coarse").load_volume()
    want = write_transferred_volume(result, fine.volume, fine.fixed_share, tmp_path / "want.npz")
    index, got = start_rows(tmp_path / "job", fine)
    np.testing.assert_array_equal(got, Volume.load(want).mixture.reshape(-1, len(INKS))[index])


def test_the_deadline_plan_takes_meshes_coarse_to_fine_from_the_extrusion_baseline():
    """With a time budget and no coarse grid given: a mesh whose settings name no start goes coarse to fine at half
    its DPI from the extrusion baseline (whatever its thickness); a mesh with a start, and a slab, go coarse to fine
    from their own start, unless the slab is thinner than a voxel of the coarse grid."""
    from inkopt.coarse import DEADLINE_COARSE_FACTOR, DEADLINE_MESH_START, deadline_plan
    from inkopt.scenes.spec import MeshSpec

    assert DEADLINE_MESH_START == "extrusion"
    cfg = OptimizeConfig(time_budget=60.0)
    lines = []
    for mesh in (MeshSpec("thin.obj", height_mm=10.0), MeshSpec("thick.obj", height_mm=40.0, dpi=200)):
        dpi, got = deadline_plan(mesh, cfg, log=lines.append)
        assert dpi == DEADLINE_COARSE_FACTOR * mesh.dpi and got == OptimizeConfig(time_budget=60.0, init="extrusion")
        assert "coarse to fine from the extrusion baseline" in lines[-1]
    given = OptimizeConfig(time_budget=60.0, init="white")
    mesh = MeshSpec("m.obj")
    assert deadline_plan(mesh, given, log=lines.append) == (DEADLINE_COARSE_FACTOR * mesh.dpi, given)
    slab = SlabSpec("chart.png", (40.0, 40.0, 10.0))
    assert deadline_plan(slab, cfg, log=lines.append) == (DEADLINE_COARSE_FACTOR * slab.dpi, cfg)
    assert len(lines) == 2
    sheet = SlabSpec("chart.png", (40.0, 40.0, 0.1))  # one voxel at 300 DPI, less than one at the coarse 150
    assert deadline_plan(sheet, cfg, log=lines.append) == (0.0, cfg) and "no coarse stage" in lines[-1]


def test_the_fine_stage_is_predicted_from_the_coarse_set_up():
    assert fine_stage_seconds(0.0) == FINE_FIXED_SECONDS
    assert fine_stage_seconds(20.0) == pytest.approx(FINE_FIXED_SECONDS + 20.0 * FINE_SETUP_FACTOR)
    assert fine_stage_seconds(30.0) > fine_stage_seconds(20.0)


def test_the_coarse_stage_shrinks_when_the_fine_stage_is_predicted_expensive():
    """A 5-minute job: a cheap fine stage fits in the 40 % the share leaves (nothing kept); the box's set-up
    (21.7 s, 48 + 5.2 x 21.7 = 161 s predicted) takes 41 s more from the coarse stage; a huge one stops at the
    least share."""
    budget = 300.0
    assert coarse_reserve(budget, 0.0) == 0.0  # 48 s < 120 s
    box = coarse_reserve(budget, 21.7)
    assert box == pytest.approx(fine_stage_seconds(21.7) - (1 - COARSE_BUDGET_SHARE) * budget)
    assert 35.0 < box < 45.0
    assert coarse_reserve(budget, 30.0) > box
    assert coarse_reserve(budget, 1e4) == pytest.approx((COARSE_BUDGET_SHARE - COARSE_MIN_SHARE) * budget)


def test_a_tiny_deadline_job_keeps_its_fine_stage_and_says_what_it_predicted(spec, tmp_path):
    """A tiny job with a short budget: the prediction exceeds what the budget leaves the fine stage (the coarse
    stage keeps its least share and says the job may overrun), and both stages still run their iterations."""
    lines = []
    cfg = OptimizeConfig(iterations=3, spp=2, forward_spp=4, init="extrusion", time_budget=20.0)
    rep = run_coarse_to_fine(spec, INKS, tmp_path / "job", cfg, 150.0, RunOptions(threads=1, log=lines.append))
    said = [m for m in lines if m.startswith("fine stage predicted")]
    assert len(said) == 1 and "least share" in said[0]
    coarse = RunDir(tmp_path / "job" / "coarse").read_report()
    assert rep.iterations >= 1 and coarse["iterations"] >= 1
    # the fine stage's estimate is the coarse stage's measured iterations scaled, not timed again
    assert rep.estimate["scaled"] and not coarse["estimate"]["scaled"]
    assert rep.estimate["seconds_per_iteration"] == pytest.approx(
        fine_iteration_seconds(coarse["seconds_per_iteration"], 150.0, spec.dpi)
    )


def test_a_job_without_a_budget_times_its_fine_stage(spec, tmp_path, monkeypatch):
    """Without a time budget the fine stage's estimate is measured on its own renderer, as any run's."""
    job(spec, tmp_path / "job", "white", monkeypatch)
    assert not RunDir(tmp_path / "job").read_report()["estimate"]["scaled"]


def test_the_fine_iteration_is_scaled_by_the_dpi_ratio():
    assert fine_iteration_seconds(2.0, 150.0, 300.0) == pytest.approx(2.0 * 2**FINE_ITERATION_EXPONENT)
    assert 5.0 < fine_iteration_seconds(1.0, 150.0, 300.0) < 6.0  # the suite's fine / coarse ratios: 4.3-8.0
    assert fine_iteration_seconds(1.0, 300.0, 300.0) == 1.0


def test_a_run_releases_the_baselines_it_was_given_before_its_iterations(spec, tmp_path):
    """The baselines a run is given (a coarse-to-fine job's fine grid baseline) serve its start and its guard, then
    the run lets them go: none is held through the iterations."""
    from inkopt.run import run_optimisation

    scene = build_scene(spec, INKS)
    given = {"extrusion": baseline_layers("extrusion", scene.volume, scene.texels, scene.target_rgb)}
    seen = []
    options = RunOptions(
        eval_spp=4, threads=1, log=lambda m: None, baselines=given, on_step=lambda r: seen.append(len(given))
    )
    cfg = OptimizeConfig(iterations=2, spp=2, forward_spp=4, init="extrusion")
    rep = run_optimisation(scene, tmp_path / "run", cfg, options)
    assert seen == [0, 0] and rep.baseline is not None
