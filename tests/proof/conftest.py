"""Fixtures of the soft-proof tests: a small evaluated mesh run (a two-coloured ball) and a small evaluated slab
run, each made once per test session through the command line, with their pages."""

import numpy as np
import pytest
import trimesh

from inkopt import charts, cli
from inkopt.evaluation.colour_table import colour_table
from inkopt.evaluation.evaluate import evaluate_run
from inkopt.evaluation.options import EvaluateOptions
from inkopt.model import InkTable

INKS = "cyan,magenta,white"  # three inks: the baselines' colour table is small


def _run(*argv):
    assert cli.main([str(a) for a in argv]) == 0


@pytest.fixture(scope="session")
def mesh_run(tmp_path_factory):
    """A 2 mm ball, cyan above its equator and magenta below, optimised briefly, evaluated (baselines included,
    from a 6-patch colour table) and reported."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("INKOPT_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))
        mp.setattr("inkopt.scenes.mesh.scene.VIEW_SIZE", 64)
        root = tmp_path_factory.mktemp("proofmesh")
        sph = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
        col = np.where(sph.vertices[:, 2:3] > 0, [[0, 200, 230, 255]], [[230, 0, 160, 255]]).astype(np.uint8)
        mesh = root / "ball.ply"
        trimesh.Trimesh(sph.vertices, sph.faces, vertex_colors=col, process=False).export(mesh)
        run = root / "run"
        _run(
            "optimize",
            mesh,
            "--scale",
            1,
            "--up",
            "z",
            "--out",
            run,
            "--iterations",
            3,
            "--spp",
            2,
            "--eval-spp",
            8,
            "--inks",
            INKS,
        )
        table = colour_table(InkTable.parse(INKS), patch_mm=1.0, step=2, max_stderr=0.5)  # 6 patches
        evaluate_run(run, EvaluateOptions(spp=8, table=table))
        _run("report", run)
    return run


@pytest.fixture(scope="session")
def slab_run(tmp_path_factory):
    """A 2 x 1.333 x 0.5 mm slab with a colour chart on top, optimised briefly and reported before and after
    evaluation (``report_optimised.html``: the optimisation's prediction only)."""
    root = tmp_path_factory.mktemp("proofslab")
    chart = charts.save(charts.colour_chart(48, 32), root / "chart.png")
    run = root / "run"
    _run("slab", chart, "--size-mm", "2x1.333x0.5", "--out", run, "--iterations", 3, "--spp", 2, "--eval-spp", 8)
    _run("report", run, "--out", run / "report_optimised.html")
    _run("evaluate", run, "--spp", 8, "--no-baselines")
    _run("report", run)
    return run
