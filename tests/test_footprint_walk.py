"""The footprint's time model (``inkopt.footprint.walk``): events per path from the object's thickness, every voxel
free or a band over a white core; an iteration's seconds in proportion to texels x events; the set-up's to the
texels; its inputs taken from the mesh's counts; its constants the fit recorded in bench/results."""

import json
import math
from pathlib import Path

import pytest
from helpers import SPOT

from inkopt.footprint import mesh_footprint, mesh_shape, walk
from inkopt.scenes.mesh import load_spec_mesh
from inkopt.scenes.spec import MeshSpec

RESULTS = Path(__file__).resolve().parents[1] / "bench" / "results"
THICKNESSES = [0.5, 1.0, 2.2, 4.5, 9.0, 13.4, 22.3, 44.7, 100.0]


def test_events_grow_with_the_thickness_and_a_white_core_walks_longer():
    """Both forms grow with r; every voxel free levels off below its limit; a band over a white core never walks
    less than every voxel free and grows on (its core's walks lengthen with the core)."""
    free = [walk.events_per_path(r, band=False) for r in THICKNESSES]
    band = [walk.events_per_path(r, band=True) for r in THICKNESSES]
    assert all(a <= b for a, b in zip(free, free[1:])) and all(a <= b for a, b in zip(band, band[1:]))
    assert all(b >= f >= 1.0 for f, b in zip(free, band))
    assert free[-1] < walk.FREE_EVENTS_LIMIT and band[-1] > 2 * free[-1]
    assert walk.events_per_path(walk.BAND_R_REF_MM, band=True) == pytest.approx(walk.BAND_EVENTS_REF)


def test_an_iteration_costs_texels_times_events_plus_the_step():
    base = walk.iteration_seconds(1e5, 80.0, 1e6)
    assert walk.iteration_seconds(2e5, 80.0, 1e6) > base and walk.iteration_seconds(1e5, 160.0, 1e6) > base
    assert walk.iteration_seconds(1e5, 80.0, 2e6) > base
    passes = walk.iteration_seconds(2e5, 160.0, 0.0)
    assert passes == pytest.approx(4 * walk.iteration_seconds(1e5, 80.0, 0.0), rel=1e-12)
    assert passes == pytest.approx(walk.iteration_cpu_seconds(2e5, 160.0) / walk.BUSY_CORES, rel=1e-12)
    assert walk.setup_seconds(1e5) > 0 and walk.setup_seconds(2e5) == pytest.approx(2 * walk.setup_seconds(1e5))


def test_the_footprint_takes_its_walk_from_the_mesh(capsys, tmp_path):
    """A mesh's footprint: its events from its own thickness (3 V / A), the band's when a shell leaves a core below
    it, every voxel free's when the shell takes the whole object; seconds and set-up grow with the size, a band's
    iteration costs more than every voxel free at the same size (its longer walk over the same texels)."""
    shape = mesh_shape(load_spec_mesh(MeshSpec(str(SPOT), height_mm=20.0)))
    r = walk.thickness_mm(shape.volume_mm3, shape.area_mm2)
    assert r == pytest.approx(3 * shape.volume_mm3 / shape.area_mm2)
    free, band = (mesh_footprint(shape, 300.0, d, 5, band=14.0 if d else 3.0) for d in (None, 1.0))
    assert free.events == walk.events_per_path(r, band=False) and band.events == walk.events_per_path(r, band=True)
    assert band.seconds_per_iteration() > free.seconds_per_iteration()
    whole = mesh_footprint(shape, 300.0, 100.0, 5, band=14.0)
    assert whole.free_voxels == whole.inside_voxels and whole.events == free.events
    sizes = [mesh_footprint(shape.scaled(k), 300.0, 1.0, 5, band=14.0) for k in (1.0, 2.0, 5.0)]
    for a, b in zip(sizes, sizes[1:]):
        assert b.events > a.events and b.setup_seconds() > a.setup_seconds()
        assert b.seconds_per_iteration() / a.seconds_per_iteration() > b.texels / a.texels
    from inkopt.cli import main

    dry = ["optimize", str(SPOT), "--height-mm", "20", "--shell-mm", "1", "--dry-run", "--out", str(tmp_path / "r")]
    assert main([*dry, "--iterations", "10", "--memory-gb", "64"]) == 0
    line = capsys.readouterr().out
    each = band.seconds_per_iteration()
    assert "set-up ~" in line and f"{band.events:.0f} events per path" in line and f"x {each:.0f} s" in line


def test_the_constants_are_the_recorded_fit():
    """``python bench/bench_footprint.py walk`` fitted the constants to the runs it names (footprint_spot.json,
    ``fit_walk``): the code holds them to their printed digits, and reproduces each fitted run's events per path
    within 1 %."""
    fit = json.loads((RESULTS / "footprint_spot.json").read_text())["entries"]["fit_walk"]
    for name, value in fit["fitted"].items():
        assert getattr(walk, name) == pytest.approx(value, rel=2e-3), name
    for name, rec in fit["events_per_path"].items():
        model = walk.events_per_path(rec["r_mm"], band=name in fit["runs"]["band"])
        assert model == pytest.approx(rec["measured"], rel=0.01), name
        assert math.isfinite(model)
