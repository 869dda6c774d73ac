"""A job's footprint from its mesh alone: counts against the voxelized mesh, the refusal of a job the memory cannot
hold (one line, the largest height that fits, nothing built or written), a dry run that never voxelizes, and the
time plan of a run given neither --time-budget nor --iterations."""

import re

import numpy as np
import pytest
from helpers import SPOT

from inkopt import footprint
from inkopt.cli import main
from inkopt.coarse import PLAN_ITERATIONS, PLAN_MAX_SECONDS, PLAN_MIN_SECONDS, default_time_budget
from inkopt.footprint import mesh_footprint, mesh_shape, spec_footprint
from inkopt.model import InkTable
from inkopt.scenes import build_scene
from inkopt.scenes.mesh import load_spec_mesh
from inkopt.scenes.spec import MeshSpec

INKS = InkTable.parse("vero-cmykw")


@pytest.mark.parametrize(("height", "shell"), [(6.0, None), (10.0, None), (10.0, 0.5)])
def test_counts_match_the_voxelized_mesh(height, shell):
    """Grid exact; inside voxels within 1 % (V / h^3; the voxel centres' sampling error falls with size); texels
    within 3 % (measured -1.5 % at 6 mm, -0.9 % at 10 mm, -0.2 % at 40 mm: the depth correction holds for a ball,
    Spot's ears and legs are thinner); free voxels of a shell within 3 % (the equal-ratio ball's shell; -0.6 % at
    20 and 60 mm)."""
    spec = MeshSpec(str(SPOT), height_mm=height, shell_mm=shell)
    fp, _ = spec_footprint(spec, len(INKS))
    scene = build_scene(spec, INKS)
    shape = scene.volume.shape  # (z, y, x)
    assert fp.grid == shape[::-1]
    assert fp.grid_voxels == int(np.prod(shape))
    inside = scene.volume.inside.count
    assert fp.inside_voxels == pytest.approx(inside, rel=0.01)
    assert fp.texels == pytest.approx(len(scene.texels), rel=0.03)
    assert fp.free_voxels == pytest.approx(int(scene.free.sum()), rel=0.03 if shell else 0.01)


def test_scaled_shape_scales_the_counts():
    shape = mesh_shape(load_spec_mesh(MeshSpec(str(SPOT), height_mm=10.0)))
    small, large = (mesh_footprint(shape.scaled(k), 300.0, None, 5) for k in (1.0, 4.0))
    assert large.inside_voxels == pytest.approx(64 * small.inside_voxels, rel=1e-6)
    # like the area, less the depth correction, which shrinks with the size (h / 2r: 1.9 % at 10 mm)
    assert 16 * small.texels < large.texels < 16 * 1.04 * small.texels
    assert large.peak_bytes() > small.peak_bytes() and large.seconds_per_iteration() > small.seconds_per_iteration()


def test_a_shell_costs_its_band_not_the_volume():
    """With a shell the core's medium exists only for the band (``BandMedium``): Spot 60 mm with a 1 mm shell measured
    3.75 GiB through its iterations (bench/results/mesh_60mm_shell1_band.json) and must not be estimated above what
    every voxel free needs; growing the height grows a shell job less than an every-voxel-free one."""
    shape = mesh_shape(load_spec_mesh(MeshSpec(str(SPOT), height_mm=10.0))).scaled(6.0)
    free, shell = (mesh_footprint(shape, 300.0, d, 5, band=12.0 if d else 3.0) for d in (None, 1.0))
    assert shell.free_voxels < 0.3 * free.free_voxels
    assert shell.peak_bytes() < free.peak_bytes()
    big_free, big_shell = (mesh_footprint(shape.scaled(2.0), 300.0, d, 5, band=12.0 if d else 3.0) for d in (None, 1.0))
    assert big_shell.peak_bytes() / shell.peak_bytes() < big_free.peak_bytes() / free.peak_bytes()


def _refuse(monkeypatch, capsys, tmp_path, extra=()):
    """Run optimize of Spot 40 mm with every voxel free (``--shell-mm 0``; the band's refusal:
    tests/test_shell_choice.py) with 1 GiB available (80 % may be used) and voxelize patched to fail: the one-line
    error and the output folder."""
    import inkopt.scenes.mesh.scene as mesh_scene

    def no_voxelize(*a, **k):
        raise AssertionError("voxelize called")

    monkeypatch.setattr(mesh_scene, "voxelize", no_voxelize)
    monkeypatch.setattr(footprint, "available_bytes", lambda: 2.0**30)
    monkeypatch.delenv(footprint.MEMORY_ENV, raising=False)
    out = tmp_path / "run"
    argv = ["optimize", str(SPOT), "--height-mm", "40", "--out", str(out), "--iterations", "1", "--shell-mm", "0"]
    argv += extra
    code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    return code, err, out


def test_a_job_beyond_the_memory_is_refused_naming_the_height_that_fits(monkeypatch, capsys, tmp_path):
    code, err, out = _refuse(monkeypatch, capsys, tmp_path)
    assert code == 2 and not out.exists()
    assert len(err) == 1 and err[0].startswith("inkopt: error: ") and "--height-mm" in err[0], err
    height = float(re.search(r"largest --height-mm that fits is ([0-9.]+)", err[0]).group(1))
    dpi = float(re.search(r"or --dpi ([0-9]+) at this size", err[0]).group(1))
    assert 5.0 < height < 40.0 and 0 < dpi < 300
    shape = mesh_shape(load_spec_mesh(MeshSpec(str(SPOT), 40.0)))
    limit = 0.8 * 2.0**30

    def at(h, d=300.0):
        return mesh_footprint(shape.scaled(h / shape.height_mm), d, None, 5)

    assert at(height).peak_bytes() <= limit < at(height * 1.02).peak_bytes()  # it fits, and it is the largest
    assert mesh_footprint(shape, dpi, None, 5).peak_bytes() <= limit


def test_the_memory_limit_flag_and_variable_decide(monkeypatch, capsys, tmp_path):
    code, err, _ = _refuse(monkeypatch, capsys, tmp_path, ["--memory-gb", "0.5"])
    assert code == 2 and "0.5 GiB it may use (--memory-gb)" in err[0]
    monkeypatch.setenv(footprint.MEMORY_ENV, "0.25")
    assert footprint.memory_limit().bytes == 0.25 * 2**30
    assert footprint.memory_limit(2.0).bytes == 2 * 2**30


def test_dry_run_answers_from_the_mesh_without_voxelizing(monkeypatch, capsys, tmp_path):
    import inkopt.scenes.mesh.scene as mesh_scene

    def no_voxelize(*a, **k):
        raise AssertionError("voxelize called")

    monkeypatch.setattr(mesh_scene, "voxelize", no_voxelize)
    monkeypatch.setattr(footprint, "available_bytes", lambda: 64.0 * 2**30)
    out = tmp_path / "run"
    assert main(["optimize", str(SPOT), "--height-mm", "200", "--dry-run", "--out", str(out), "--iterations", "9"]) == 2
    printed = capsys.readouterr()
    line = printed.out.strip()
    assert line.startswith("estimate from the mesh's size") and "up to 9 iterations" in line and "GiB" in line
    err = printed.err.strip().splitlines()  # 200 mm needs ~280 GiB: refused in one line, after the estimate
    assert len(err) == 1 and "largest --height-mm that fits is" in err[0]
    assert main(["optimize", str(SPOT), "--height-mm", "20", "--dry-run", "--out", str(out), "--iterations", "9"]) == 0
    assert "96 k texels" in capsys.readouterr().out  # 96 002 voxelized
    assert not out.exists()


def test_a_run_without_time_budget_or_iterations_gets_a_time_plan(monkeypatch, tmp_path):
    cfg, logged = _run_args(monkeypatch, tmp_path, [])
    fp, _ = spec_footprint(MeshSpec(str(SPOT), height_mm=6.0), 5)
    assert cfg.time_budget == default_time_budget(fp.seconds_per_iteration()) >= PLAN_MIN_SECONDS
    assert np.isfinite(cfg.time_budget)
    assert logged[0].startswith("time plan: ") and "no --time-budget or --iterations given" in logged[0]
    assert logged[1].startswith("deadline: coarse to fine from the extrusion baseline")  # the plan of a mesh
    assert logged[2] == "the run's own first line"


def test_the_flags_decide_when_given(monkeypatch, tmp_path):
    cfg, logged = _run_args(monkeypatch, tmp_path, ["--iterations", "7"])
    assert cfg.iterations == 7 and cfg.time_budget is None
    assert not any(m.startswith("time plan") for m in logged)
    cfg, logged = _run_args(monkeypatch, tmp_path, ["--time-budget", "10m"])
    assert cfg.time_budget == 600 and cfg.iterations == 300
    assert not any(m.startswith("time plan") for m in logged)


def test_the_plan_rule():
    assert default_time_budget(0.5) == PLAN_MIN_SECONDS
    assert default_time_budget(60.0) == PLAN_ITERATIONS * 60.0
    assert default_time_budget(876.0) == PLAN_MAX_SECONDS  # Spot 100 mm: within 3 hours, not 40 x 876 s
    assert default_time_budget(PLAN_MAX_SECONDS / PLAN_ITERATIONS) == PLAN_MAX_SECONDS
    with pytest.raises(ValueError):
        default_time_budget(float("inf"))


def _run_args(monkeypatch, tmp_path, extra):
    """The settings ``optimize`` of Spot 6 mm hands to the run driver (patched: it records them) with ``extra``
    options, and the lines it logged."""
    import inkopt.coarse
    import inkopt.run
    from inkopt.cli import runargs

    seen = {}

    def record(*args):
        seen["cfg"] = next(a for a in args if hasattr(a, "time_budget"))
        args[-1].log("the run's own first line")  # the RunOptions' log
        return "REPORT"

    monkeypatch.setattr(inkopt.run, "run_optimisation", record)
    monkeypatch.setattr(inkopt.coarse, "run_coarse_to_fine", record)
    monkeypatch.setattr(inkopt.scenes, "build_scene", lambda spec, inks: None)
    logged = []
    monkeypatch.setattr(runargs, "stderr_log", logged.append)
    from inkopt.cli import build_parser

    args = build_parser().parse_args(["optimize", str(SPOT), "--height-mm", "6", "--out", str(tmp_path / "r"), *extra])
    rep, budget = runargs.run_from_args(args, runargs.mesh_spec_from_args(args, args.mesh))
    assert rep == "REPORT" and budget == seen["cfg"].time_budget
    return seen["cfg"], logged


def test_a_slab_beyond_the_memory_is_refused_naming_the_size_that_fits(monkeypatch, capsys, tmp_path):
    from PIL import Image

    from inkopt.footprint import slab_footprint

    Image.new("RGB", (40, 40), (200, 50, 50)).save(tmp_path / "p.png")
    monkeypatch.setattr(footprint, "available_bytes", lambda: 2.0**30)
    monkeypatch.delenv(footprint.MEMORY_ENV, raising=False)
    out = tmp_path / "run"
    assert main(["slab", str(tmp_path / "p.png"), "--size-mm", "100x100x10", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and not out.exists(), err
    side = float(re.search(r"largest --size-mm that fits is ([0-9.]+)x", err[0]).group(1))
    limit = 0.8 * 2.0**30
    assert slab_footprint((side, side, 10.0), 300.0, 1, 5).peak_bytes() <= limit
    assert slab_footprint((side * 1.05, side * 1.05, 10.0), 300.0, 1, 5).peak_bytes() > limit


def test_the_band_estimate_agrees_with_measured_band_runs():
    """Spot with a 1 mm shell: the band's estimated stages within 15 % of what was measured: the scene's and the
    figures' in whole runs at 40 and 60 mm (bench/results/footprint_spot.json, fit_shell_s69: each stage's own
    peak, bench/run_stages.py), a step's through an iteration at 100 mm (bench/results/mesh_100mm_shell1_mem69.json,
    bench/bench_mesh.py, to which it is fitted) and at 40 mm (bench/results/step_memory_spot.json,
    40mm_shell1_mem_after_trim, bench/bench_step_memory.py); and the scene's stage below the others."""
    import json
    from pathlib import Path

    results = Path(__file__).resolve().parents[1] / "bench" / "results"
    rows = json.loads((results / "footprint_spot.json").read_text())["entries"]["fit_shell_s69"]["rows"]
    for height in (40.0, 60.0):
        measured = rows[f"run_{height:g}mm_shell1_s69"]["measured_gib"]
        fp, _ = spec_footprint(MeshSpec(str(SPOT), height_mm=height, shell_mm=1.0), len(INKS))
        stages = {k: v / 2**30 for k, v in fp.stage_bytes().items()}
        for stage in ("voxelize", "figures"):
            assert stages[stage] == pytest.approx(measured[stage], rel=0.15), (height, stage)
        assert stages["voxelize"] < min(stages["step"], stages["figures"])
    step40 = json.loads((results / "step_memory_spot.json").read_text())["results"]["40mm_shell1_mem_after_trim"]
    run100 = json.loads((results / "mesh_100mm_shell1_mem69.json").read_text())
    for height, gib in ((40.0, step40["iterations"][0]["peak_gib"]), (100.0, run100["peak_rss_gb"])):
        fp, _ = spec_footprint(MeshSpec(str(SPOT), height_mm=height, shell_mm=1.0), len(INKS))
        assert fp.stage_bytes()["step"] / 2**30 == pytest.approx(gib, rel=0.15), height


def test_what_quantize_writes_follows_the_surface():
    """The dry run's "+ ... after inkopt quantize" against what `inkopt quantize` wrote (quantized_labels.layers plus
    quantized.npz) for 1-iteration Spot runs with a 1 mm shell: 16.86 MB at 40 mm and 166.98 MB at 100 mm
    (docs/performance.md, "The last mile"), within 10 %; a byte per printer voxel, what it said before, is 35 times
    too much at 100 mm."""
    for height, written in ((40.0, 16.86e6), (100.0, 166.98e6)):
        fp, _ = spec_footprint(MeshSpec(str(SPOT), height_mm=height, shell_mm=1.0), len(INKS))
        assert fp.quantized_bytes() == pytest.approx(written, rel=0.10), height
        assert fp.quantized_bytes() < 0.1 * 6.27 * fp.grid_voxels


def test_the_plan_of_a_large_object_is_at_most_its_cap_and_says_so():
    from inkopt.cli.jobplan import _time_plan

    fp, _ = spec_footprint(MeshSpec(str(SPOT), height_mm=100.0, shell_mm=1.0), 5)
    assert PLAN_ITERATIONS * fp.seconds_per_iteration() > PLAN_MAX_SECONDS  # 40 iterations: ~10 hours
    budget, line = _time_plan(fp)
    assert budget == PLAN_MAX_SECONDS and line.startswith("time plan: 2 h 45 min (")
    assert "at most 2 h 45 min, mesh to printer package within 3 hours" in line


def test_a_coarse_to_fine_dry_run_counts_the_coarse_stage_and_its_start_on_disk(capsys, tmp_path):
    """Its disk: the fine run's folder, plus the coarse run's (its footprint at the coarse DPI) and the start (8 + 4N
    bytes per free voxel); a run that does not go coarse to fine adds nothing."""
    from inkopt.footprint import mesh_footprint

    out, args = tmp_path / "run", ["optimize", str(SPOT), "--height-mm", "20", "--dry-run", "--shell-mm", "1"]
    assert main([*args, "--out", str(out), "--iterations", "9"]) == 0
    assert "coarse stage" not in capsys.readouterr().out
    assert main([*args, "--out", str(out), "--iterations", "9", "--coarse-dpi", "150"]) == 0
    line = capsys.readouterr().out
    fp, shape = spec_footprint(MeshSpec(str(SPOT), height_mm=20.0, shell_mm=1.0), 5)
    coarse = mesh_footprint(shape, 150.0, 1.0, 5, footprint.mesh_band(25.4 / 150, 1.0))
    extra = coarse.disk_bytes(9) + 28 * fp.free_voxels
    assert f"disk ~{(fp.disk_bytes(9) + extra) / 1e9:.2f} GB (of which {extra / 1e6:.1f} MB the coarse stage" in line
    assert not out.exists()
