"""Evaluation outputs: views pictures of a mesh evaluation, earlier evaluations kept with --out, the start's figures
measured once per run (a resume does not render the start again), and the sample cap."""

import json

import numpy as np
import pytest
import trimesh
from PIL import Image

from inkopt import charts
from inkopt.cli import main


@pytest.fixture(scope="module")
def mesh_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("meshrun")
    sph = trimesh.creation.icosphere(subdivisions=3, radius=0.6)
    col = np.where(sph.vertices[:, 2:3] > 0, [[0, 200, 230, 255]], [[230, 0, 160, 255]]).astype(np.uint8)
    trimesh.Trimesh(sph.vertices, sph.faces, vertex_colors=col, process=False).export(d / "ball.ply")
    argv = ["optimize", str(d / "ball.ply"), "--scale", "1", "--up", "z", "--out", str(d / "run")]
    assert main(argv + ["--iterations", "1", "--spp", "1", "--eval-spp", "2", "--threads", "2"]) == 0
    return d / "run"


def test_mesh_evaluation_writes_views_and_out_keeps_the_earlier(mesh_run, monkeypatch, capsys):
    monkeypatch.setattr("inkopt.scenes.mesh.views.EVALUATION_VIEW_SIZE", 32)
    base = ["evaluate", str(mesh_run), "--spp", "2", "--no-baselines", "--threads", "2"]
    assert main(base) == 0
    ev = json.loads((mesh_run / "evaluation.json").read_text())
    assert ev["pictures"] == ["evaluation_views.png"]
    with Image.open(mesh_run / "evaluation_views.png") as im:
        assert im.size == (4 * 32, 3 * 32)  # target, optimized, quantized rows; four sides
    first = (mesh_run / "evaluation.json").read_bytes()
    assert main(base + ["--seed", "1", "--out", str(mesh_run / "seed1.json")]) == 0
    assert (mesh_run / "evaluation.json").read_bytes() == first  # the earlier evaluation is kept
    ev1 = json.loads((mesh_run / "seed1.json").read_text())
    assert ev1["seed"] == 1 and ev1["pictures"] == ["seed1_views.png"] and (mesh_run / "seed1_views.png").is_file()
    capsys.readouterr()
    assert main(base + ["--out", str(mesh_run / "x.txt")]) == 2
    assert "--out must name a .json file" in capsys.readouterr().err


def test_evaluate_sample_cap(mesh_run, capsys):
    assert main(["evaluate", str(mesh_run), "--no-baselines", "--max-spp", "8", "--out", str(mesh_run / "c.json")]) == 0
    ev = json.loads((mesh_run / "c.json").read_text())
    assert ev["continuous"]["spp"] <= 8 and ev["quantized"]["spp"] <= 8
    capsys.readouterr()
    assert main(["evaluate", str(mesh_run), "--max-spp", "0"]) == 2
    assert "--max-spp must be at least 1" in capsys.readouterr().err


def test_the_start_is_rendered_once_per_run(tmp_path, monkeypatch, capsys):
    import inkopt.runfigures

    calls = []
    real = inkopt.runfigures.adaptive_render

    def counting(*a, **k):
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(inkopt.runfigures, "adaptive_render", counting)
    chart = charts.save(charts.colour_chart(24, 16), tmp_path / "chart.png")
    argv = ["slab", str(chart), "--size-mm", "2x1.333x0.5", "--out", str(tmp_path / "r"), "--spp", "1"]
    argv += ["--forward-spp", "1", "--eval-spp", "2", "--threads", "1"]
    assert main(argv + ["--iterations", "2"]) == 0
    assert len(calls) == 3  # the start, the extrusion baseline (evaluation.guard), then the result
    rep1 = json.loads((tmp_path / "r" / "report.json").read_text())
    assert main(argv + ["--iterations", "4", "--resume"]) == 0
    assert len(calls) == 4  # the resumed run renders only its result: the start's (and baseline's) figures come
    # from the checkpoint
    rep2 = json.loads((tmp_path / "r" / "report.json").read_text())
    for k in ("initial_delta_e76_mean", "initial_ssim", "initial_eval_spp"):
        assert rep2[k] == rep1[k]
    assert (
        rep2["baseline"]["extrusion"]["delta_e76_mean_corrected"]
        == rep1["baseline"]["extrusion"]["delta_e76_mean_corrected"]
    )
