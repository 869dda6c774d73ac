"""Tests of ``inkopt select-inks`` (inkopt.inksets): outputs and their keys, halving vs brute force, resume,
serial / process pool / Ray giving identical results, meshes, one-line errors before any work.

A 2 x 1.33 x 0.5 mm colour-chart slab (24 x 16 x 6 voxels, 384 texels) at 2 + 4 spp: a run of a few iterations
takes a fraction of a second. Results are deterministic (seeded, bit-identical for any thread count).
"""

import json

import numpy as np
import pytest
import trimesh
from helpers import FAST_RUN

from inkopt import charts
from inkopt.cli import main
from inkopt.inksets import Pool, Selection, Serial, load_selection, run_selection
from inkopt.inksets.search import extrapolate_loss
from inkopt.optim import OptimizeConfig
from inkopt.rundir import RunDir
from inkopt.scenes.spec import MeshSpec, SlabSpec

pytest.importorskip("inkopt._core")

CANDIDATE_KEYS = {"inks", "iterations", "loss", "delta_e76_mean", "delta_e2000_mean", "ssim", "texel_samples"}


@pytest.fixture(scope="module")
def chart(tmp_path_factory):
    return charts.save(charts.colour_chart(24, 16), tmp_path_factory.mktemp("chart") / "chart.png")


def selection(chart, strategy="halving", candidates="cyan,magenta,yellow", choose=2, iterations=4, **kw):
    # decay 0.5: the step decays in the last 2 of 4 iterations, so a rung of 2 that planned its own decay would
    # differ from the full run (test_halving_final_run_equals_brute_force)
    cfg = OptimizeConfig(iterations=iterations, spp=2, forward_spp=4, checkpoint_every=2, decay=0.5)
    return Selection(
        SlabSpec(str(chart), (2.0, 4 / 3, 0.5)),
        candidates,
        choose,
        ["black", "white"],
        cfg,
        strategy,
        eval_spp=16,
        rung_eval_spp=8,
        **kw,
    )


@pytest.fixture(scope="module")
def halving(chart, tmp_path_factory):
    out = tmp_path_factory.mktemp("halving")
    return out, run_selection(selection(chart), out, Serial(2), log=lambda m: None)


def test_outputs_keys_and_work(halving):
    out, res = halving
    assert json.loads((out / "selection.json").read_text()) == res == load_selection(out)
    assert set(res) == {"strategy", "candidates", "winner", "texel_samples", "format_version"}
    assert res["strategy"] == "halving" and res["format_version"] == 1
    assert len(res["candidates"]) == 3
    for c in res["candidates"]:
        assert set(c) == CANDIDATE_KEYS and c["inks"][-2:] == ["black", "white"]
    # 3 sets: rungs of 2 and 4 iterations; the first two continue, the third stops at 2
    assert [c["iterations"] for c in res["candidates"]] == [4, 4, 2]
    assert res["winner"] == {"inks": res["candidates"][0]["inks"], "loss": res["candidates"][0]["loss"]}
    assert res["candidates"][0]["loss"] <= res["candidates"][1]["loss"]
    texels = 24 * 16
    # work: iterations x (2 + 4) spp + the evaluation renders: the start and the result on the first rung (8 spp),
    # the result only on the last (16 spp; the resumed run keeps its start's figures)
    assert res["candidates"][2]["texel_samples"] == texels * (2 * 6 + 2 * 8)
    assert res["candidates"][0]["texel_samples"] == texels * (4 * 6 + 2 * 8 + 16)
    assert res["texel_samples"] == sum(c["texel_samples"] for c in res["candidates"])
    assert (out / "selection.png").stat().st_size > 1000


def test_selection_json_versions(halving, tmp_path):
    """selection.json written before files carried a version (0) loads as version 1; a newer one is refused."""
    from inkopt.io import FormatError

    _, res = halving
    old = {k: v for k, v in res.items() if k != "format_version"}
    (tmp_path / "selection.json").write_text(json.dumps(old))
    assert load_selection(tmp_path) == res
    (tmp_path / "selection.json").write_text(json.dumps({**old, "format_version": 2}))
    with pytest.raises(FormatError, match="format version 2"):
        load_selection(tmp_path)


def test_winner_is_a_run_directory(halving, capsys):
    out, res = halving
    rep = RunDir(out / "winner").read_report()
    assert rep["inks"] == res["winner"]["inks"] and rep["loss"] == res["winner"]["loss"]
    assert main(["quantize", str(out / "winner")]) == 0


def test_halving_final_run_equals_brute_force(chart, halving, tmp_path):
    """The resumed runs continue exactly: the winner's figures equal brute force's run of the same set."""
    _, res = halving
    brute = run_selection(selection(chart, "brute"), tmp_path, log=lambda m: None)
    assert all(c["iterations"] == 4 for c in brute["candidates"])
    by_inks = {tuple(c["inks"]): c for c in brute["candidates"]}
    for c in res["candidates"][:2]:
        b = by_inks[tuple(c["inks"])]
        assert {k: c[k] for k in ("loss", "delta_e76_mean", "ssim")} == {
            k: b[k] for k in ("loss", "delta_e76_mean", "ssim")
        }
    assert brute["texel_samples"] == 3 * 24 * 16 * (4 * 6 + 2 * 16)


def test_extrapolate_loss():
    """The rung ranking's learning-curve extrapolation: exact on a power law (fitted on the second half), never
    below a rising history's mean, the last value for fewer than 3 points."""
    t = np.arange(1, 21)
    assert extrapolate_loss(0.1 + 0.5 * t**-0.7, 80) == pytest.approx(0.1 + 0.5 * 80**-0.7, rel=1e-6)
    rising = 0.2 + 0.001 * t
    assert extrapolate_loss(rising, 80) == pytest.approx(rising[10:].mean())
    assert extrapolate_loss([0.3, 0.2], 80) == 0.2
    assert extrapolate_loss([0.5, 0.4, 0.33, 0.29, 0.27, 0.26], 80) < 0.26


def test_budgets_paper_setup():
    """15 sets: rungs of 1/4, 1/2 and the full budget keeping 4 then 2 sets; work (iterations, evaluation renders at
    16 and 256 spp: the start's only on a fresh run) at most 40 % of brute force's."""
    sel = Selection(
        None, "cyan,cyan2,magenta,magenta2,yellow,yellow2", 4, ["black", "white"], OptimizeConfig(iterations=80)
    )
    assert sel.plan() == [(20, 4), (40, 2), (80, 1)] and sel.budgets() == [20, 40, 80]
    assert Selection(None, "cyan,magenta,yellow", 2, [], OptimizeConfig(iterations=4)).budgets() == [2, 4]
    per_it = sel.cfg.spp + sel.cfg.forward_spp
    work = 15 * (20 * per_it + 2 * 16) + 4 * (20 * per_it + 16) + 2 * (40 * per_it + 256)
    assert work / (15 * (80 * per_it + 2 * 256)) <= 0.40


class Interrupted(Serial):
    """Serial execution that is killed (Ctrl-C) before its ``runs``+1-th run."""

    def __init__(self, runs):
        super().__init__(2)
        self.left = runs

    def map(self, fn, tasks):
        for t in tasks:
            if self.left == 0:
                raise KeyboardInterrupt
            self.left -= 1
            yield fn(t)


def test_resume_after_interruption(chart, halving, tmp_path):
    """A selection killed in its second rung (one run of it done, the other still at its first-rung checkpoint)
    finishes with the same result, continuing that run from its checkpoint."""
    _, res = halving
    with pytest.raises(KeyboardInterrupt):
        run_selection(selection(chart), tmp_path / "sel", Interrupted(4), log=lambda m: None)
    state = json.loads((tmp_path / "sel" / "selection_state.json").read_text())
    assert [len(r["results"]) for r in state["rungs"]] == [3, 1]
    again = run_selection(selection(chart), tmp_path / "sel", resume=True, log=lambda m: None)
    assert again == res
    with pytest.raises(ValueError, match="different settings"):
        run_selection(selection(chart, iterations=6), tmp_path / "sel", resume=True, log=lambda m: None)


def test_resume_key_holds_the_scene_kinds_settings(chart):
    """The key holds the settings as the target's kind resolves them: a picture search of the unset defaults has
    the key of explicit 0.8 and 1.5 (searches started before these were left to the kind resume); a mesh target's
    unset defaults are 0.5 and 3, so an old mesh search does not."""
    from dataclasses import replace

    def key(sel, **cfg):
        sel.cfg = replace(sel.cfg, **cfg)
        return json.loads(sel.key())["cfg"]

    assert key(selection(chart)) == key(selection(chart), adjoint_ema=0.8, smooth=1.5)
    mesh = selection(chart)
    mesh.target = MeshSpec(str(chart), height_mm=1.0)
    assert (key(mesh)["adjoint_ema"], key(mesh)["smooth"]) == (0.5, 3.0)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--candidates", "cyan", "--choose", "2"], "needs at least 2 candidates"),
        (["--candidates", "cyan,teal", "--choose", "1"], "unknown ink(s) teal"),
        (["--candidates", "cyan,white", "--choose", "1"], "in both --candidates and --always"),
        (["--candidates", "cyan,cyan2,magenta,magenta2,yellow", "--choose", "5"], "holds 6 materials"),
        (["--candidates", "cyan,magenta", "--choose", "1", "--ray", "auto", "--inks", "vero-cmykw"], "not --inks"),
        (["--candidates", "cyan,magenta", "--choose", "1", "--workers", "0"], "--workers must be at least 1"),
        (["--candidates", "cyan,magenta", "--choose", "1", "--shell-mm", "0.2"], "--shell-mm is for a mesh target"),
        (["--candidates", "cyan,magenta", "--choose", "1", "--scale", "1"], "exactly one of --size-mm"),
    ],
)
def test_bad_input_one_line_before_work(chart, tmp_path, capsys, argv, message):
    out = tmp_path / "sel"
    assert main(["select-inks", str(chart), "--size-mm", "2x1.333x0.5", "--out", str(out), *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("inkopt: error:") and message in err and "\n" not in err
    assert not out.exists()


def test_ray_missing_says_how_to_install(chart, tmp_path, capsys, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    argv = [
        "select-inks",
        str(chart),
        "--size-mm",
        "2x1.333x0.5",
        "--out",
        str(tmp_path / "s"),
        "--candidates",
        "cyan,magenta",
        "--choose",
        "1",
        "--ray",
        "auto",
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pip install 'inkopt[ray]'" in err


def test_cli_mesh_target(tmp_path, capsys, monkeypatch):
    """A mesh target: a tiny vertex-coloured icosphere (1 mm), two candidates choose 1, two iterations."""
    monkeypatch.setattr("inkopt.scenes.mesh.scene.VIEW_SIZE", 32)
    sph = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    col = np.where(sph.vertices[:, 2:3] > 0, [[0, 200, 230, 255]], [[230, 0, 160, 255]]).astype(np.uint8)
    mesh = tmp_path / "ball.ply"
    trimesh.Trimesh(sph.vertices, sph.faces, vertex_colors=col, process=False).export(mesh)
    out = tmp_path / "sel"
    assert (
        main(
            [
                "select-inks",
                str(mesh),
                "--height-mm",
                "1",
                "--up",
                "z",
                "--candidates",
                "cyan,magenta",
                "--choose",
                "1",
                "--out",
                str(out),
                *FAST_RUN,
            ]
        )
        == 0
    )
    res = json.loads((out / "selection.json").read_text())
    assert len(res["candidates"]) == 2 and RunDir(out / "winner").load_scene().kind == "mesh"
    assert "winner (lowest loss)" in capsys.readouterr().out


@pytest.mark.slow
def test_pool_equals_serial(chart, halving, tmp_path):
    _, res = halving
    pool = Pool(2)
    try:
        assert run_selection(selection(chart), tmp_path, pool, log=lambda m: None) == res
    finally:
        pool.close()


@pytest.mark.slow
def test_halving_fifteen_sets_pool_equals_serial(chart, tmp_path):
    """The paper's 15 sets by halving (24 iterations: rungs of 6, 12, 24): 15, 4 then 2 sets, ranked between rungs
    by the training loss; a pool of 2 gives the same selection.json as serial execution."""
    sel = lambda: selection(chart, candidates="cyan,cyan2,magenta,magenta2,yellow,yellow2", choose=4, iterations=24)  # noqa: E731
    res = run_selection(sel(), tmp_path / "serial", Serial(2), log=lambda m: None)
    state = json.loads((tmp_path / "serial" / "selection_state.json").read_text())
    assert [(r["iterations"], len(r["results"])) for r in state["rungs"]] == [(6, 15), (12, 4), (24, 2)]
    for k in (0, 1):
        ranked = sorted(state["rungs"][k]["results"].items(), key=lambda kv: (kv[1]["train_loss"], kv[0]))
        assert {n for n, _ in ranked[: len(state["rungs"][k + 1]["results"])]} == set(state["rungs"][k + 1]["results"])
    assert [c["iterations"] for c in res["candidates"]] == [24] * 2 + [12] * 2 + [6] * 11
    pool = Pool(2)
    try:
        assert run_selection(sel(), tmp_path / "pool", pool, log=lambda m: None) == res
    finally:
        pool.close()


@pytest.fixture(scope="module")
def local_ray():
    """A local Ray instance of 2 CPUs for this module's Ray tests."""
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


def test_ray_equals_serial(chart, halving, local_ray, tmp_path):
    from inkopt.inksets import Ray

    _, res = halving
    backend = Ray("auto")
    assert backend.cpus == 2
    assert run_selection(selection(chart), tmp_path, backend, log=lambda m: None) == res


@pytest.mark.slow
def test_cli_ray_pool_serial_identical_brute_six_candidates(chart, local_ray, tmp_path):
    """The paper's 15 sets (brute force, 3 iterations) through the command line: serial, a pool of 2 and Ray
    (the local 2-CPU instance) write the same selection.json."""
    out = {}
    for how, extra in (("serial", []), ("pool", ["--workers", "2"]), ("ray", ["--ray", "auto"])):
        argv = [
            "select-inks",
            str(chart),
            "--size-mm",
            "2x1.333x0.5",
            "--candidates",
            "cyan,cyan2,magenta,magenta2,yellow,yellow2",
            "--choose",
            "4",
            "--out",
            str(tmp_path / how),
            "--strategy",
            "brute",
            "--iterations",
            "3",
            "--spp",
            "2",
            "--forward-spp",
            "4",
            "--eval-spp",
            "16",
            *extra,
        ]
        assert main(argv) == 0
        out[how] = json.loads((tmp_path / how / "selection.json").read_text())
    assert len(out["serial"]["candidates"]) == 15
    assert out["serial"] == out["pool"] == out["ray"]


@pytest.mark.parametrize("option", [["--dry-run"], ["--log-every", "5"], ["--eval-max-spp", "64"]])
def test_select_inks_does_not_take_single_run_options(tmp_path, capsys, option):
    """The options of one run's estimate, progress lines and evaluation budget are not offered by select-inks (which
    runs many): argparse refuses them in one line, nothing is written."""
    from inkopt.cli import main

    argv = ["select-inks", "x.png", "--size-mm", "3x2x1", "--candidates", "cyan,magenta", "--choose", "1"]
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--out", str(tmp_path / "s"), *option])
    assert exc.value.code == 2 and option[0] in capsys.readouterr().err
    assert not (tmp_path / "s").exists()
