"""experiments/core_depth.py's cores (the ``--core`` value of a cell, the "deep" mixture from the results file)
and bench/bench_mesh.py's ``--core``, which passes a core to the scene."""

import json

import numpy as np
import pytest
from helpers import REPO, SPOT, load_file_module

from inkopt.model import InkTable
from inkopt.model.fixed import core_shares

DEEP = {
    "1": {
        "voxels": 10,
        "mixture": {"cyan": 0.00026, "magenta": 0.007388, "yellow": 0.007987, "black": 0.001348, "white": 0.983017},
    }
}


def _study():
    return load_file_module(REPO / "experiments" / "core_depth.py", "core_depth_study")


def test_the_deep_core_is_the_rounded_mixture_renormalised_onto_white():
    study = _study()
    arg = study.core_arg("deep", DEEP, 1.0)
    shares = core_shares(arg, InkTable.parse("vero-cmykw"))
    assert abs(float(shares.sum()) - 1) < 1e-6
    names = list(InkTable.parse("vero-cmykw").names)
    for ink, share in DEEP["1"]["mixture"].items():  # 4 decimals each; white takes the rounding
        assert abs(shares[names.index(ink)] - share) <= (5e-4 if ink == "white" else 5e-5 + 1e-7)
    with pytest.raises(SystemExit, match="'free' cell first"):
        study.core_arg("deep", None, 1.0)


def test_named_and_explicit_cores_pass_through():
    study = _study()
    assert study.core_arg("grey", None, 1.0) == study.GREY
    assert study.core_arg("white", None, 1.0) == "white"
    assert study.core_arg("white=0.9+black=0.1", None, 1.0) == "white=0.9,black=0.1"


def test_the_deep_mixture_is_read_from_the_results_file(tmp_path, monkeypatch):
    study = _study()
    import common

    monkeypatch.setattr(common, "STUDY_RESULTS", tmp_path)
    a = type("Args", (), {"height_mm": 20.0, "dpi": 150.0, "iterations": 60})()
    assert study.stored_deep_mixture(a) is None  # no results file
    entry = {"deep_mixture": DEEP}
    (tmp_path / study.RESULT).write_text(json.dumps({"results": {"spot20mm_150dpi_60it/free": entry}}))
    assert study.stored_deep_mixture(a) == DEEP
    a.iterations = 30  # another setting's free cell is not this one's
    assert study.stored_deep_mixture(a) is None


def test_bench_mesh_passes_its_core_to_the_scene(tmp_path, monkeypatch):
    bench = load_file_module(REPO / "bench" / "bench_mesh.py", "bench_mesh_core")
    seen = []
    import inkopt.scenes.mesh as mesh  # main imports build_mesh_scene from here when it runs

    original = mesh.build_mesh_scene

    def spy(spec, inks):
        scene = original(spec, inks)
        seen.append(scene.volume.band.core.copy())
        return scene

    monkeypatch.setattr(mesh, "build_mesh_scene", spy)
    out = tmp_path / "mesh.json"
    args = ["4", "--mesh", str(SPOT), "--dpi", "60", "--shell-mm", "0.5", "--core", "white=0.9,black=0.1"]
    args += ["--iterations", "1"]
    result = bench.main([*args, "--spp", "1", "--threads", "1", "--out", str(out)])
    names = list(InkTable.parse("vero-cmykw").names)
    expect = np.zeros(len(names), np.float32)
    expect[names.index("white")], expect[names.index("black")] = 0.9, 0.1
    np.testing.assert_allclose(seen[0], expect, atol=1e-6)
    assert result["core"] == "white=0.9,black=0.1" and json.loads(out.read_text())["core"] == result["core"]
    assert result["free_voxels"] < result["inside_voxels"]
