"""The result's finishing smoothing decided by the run (``inkopt.evaluation.finish``, ``finish_smooth`` auto): the
pass stays where the paired render says it lowers the loss or cannot tell, goes where it raises it beyond the noise;
report.json and the log say which; ``finish_smooth`` N forces N passes; a resume returns the same result.

The scenes are 16 x 12-voxel slabs, 0.5 mm (6 voxels) deep, CMYKW, whose target is one colour at every texel (every
texel flat, so the smoothing reaches every voxel): the mean of a 256-spp render of 40 % cyan and 60 % white. The
softmax's variables are the shares' logarithms (up to a constant per voxel), so a pass averages log shares and moves
each voxel towards the ink most of its neighbourhood holds. Two iterates whose outcome is certain beyond the noise:
"speckled", the target's mixture with 15 % of the voxels pure black (the pass removes the isolated black voxels: the
loss falls by ~15 standard errors at 64 spp), and "noisy", each voxel pure cyan (40 %) or pure white (the same mean
mixture, which the render averages; the pass turns each neighbourhood into its majority ink: the loss rises by
~15 standard errors at 16 spp)."""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from inkopt import runfigures
from inkopt.evaluation import finish
from inkopt.model import InkTable, Volume
from inkopt.optim import Optimization, OptimizeConfig
from inkopt.optim.config import FINISH_AUTO
from inkopt.proof import write_proof
from inkopt.run import RunOptions, run_optimisation
from inkopt.rundir import RunDir
from inkopt.scenes.slab import build_slab

pytest.importorskip("inkopt._core")

INKS = InkTable.parse("vero-cmykw")  # cyan, magenta, yellow, black, white
NX, NY, VOX = 16, 12, 25.4 / 300
SPP = 16  # the decision's samples per texel (the figures' first pass: --eval-spp)


def _cfg(**kw) -> OptimizeConfig:
    return OptimizeConfig(**{"iterations": 0, "spp": 4, "forward_spp": 16, "smooth": 1.5, **kw})


def _flat_scene():
    top = np.full((NY * 4, NX * 4, 3), 0.5, np.float32)
    return build_slab(top, None, (NX * VOX, NY * VOX, 0.5), INKS)


def _free_mixture(run: Optimization, case: str) -> np.ndarray:
    """(F, 5) float32 free-voxel mixtures: "uniform" (40 % cyan, 60 % white), "speckled" (that with 15 % of the voxels
    pure black) or "noisy" (each voxel pure cyan with probability 0.4, else pure white); seeded."""
    n, rng = run.param.n_free, np.random.default_rng(5)
    p = np.full((n, 5), 1e-6, np.float32)
    if case == "noisy":
        cyan = rng.random(n) < 0.4
        p[cyan, 0], p[~cyan, 4] = 1.0, 1.0
        return p
    p[:, 0], p[:, 4] = 0.4, 0.6
    if case == "speckled":
        black = rng.random(n) < 0.15
        p[black] = 1e-6
        p[black, 3] = 1.0
    return p


def _scene_of(iterate: str):
    """The slab whose target is the mean colour of a 256-spp render of the "uniform" mixture at every texel, and a run
    of it set to mixture ``iterate``."""
    scene = _flat_scene()
    cfg = _cfg(finish_smooth=FINISH_AUTO).for_scene("slab")
    run = Optimization(scene, cfg, threads=2)
    run.x = run.param.variables_for(_free_mixture(run, "uniform"))
    rgb = run.renderer().render(scene.texels, 256, 12345, True).rgb
    scene = replace(scene, target_rgb=np.broadcast_to(rgb.mean(0), rgb.shape).astype(np.float32))
    run = Optimization(scene, cfg, threads=2)
    run.x = run.param.variables_for(_free_mixture(run, iterate))
    return scene, run


def _render(run):
    def render(n, s):
        r = run.renderer().render(run.texels, n, s, True)
        return r.rgb, r.var_mean, n

    return render


@pytest.fixture(scope="module")
def noisy():
    return _scene_of("noisy")


def test_the_pass_is_dropped_where_it_raises_the_loss(noisy):
    _, run = noisy
    x0 = run.x.copy()
    choice, replay = finish.choose_finish(run, _render(run), SPP, 77)
    assert choice.decision == "dropped" and not choice.smoothed and choice.passes == 0
    assert choice.difference < -10 * choice.stderr, choice  # by far: each neighbourhood turned into its majority ink
    assert choice.loss_unsmoothed - choice.loss_smoothed == pytest.approx(choice.difference)
    np.testing.assert_array_equal(run.x, x0)  # the iterate itself, bit for bit
    plain = _render(run)(SPP, 77)
    assert (replay.spp, replay.seed) == (SPP, 77)
    np.testing.assert_array_equal(replay.result[0], plain[0])  # the chosen candidate's render, for the figures
    assert choice.texels == len(run.texels) and choice.seconds > 0


def test_the_pass_is_kept_where_it_lowers_the_loss():
    _, run = _scene_of("speckled")
    x0 = run.x.copy()
    choice, replay = finish.choose_finish(run, _render(run), 64, 77)
    assert choice.decision == "kept" and choice.smoothed and choice.passes == 1
    assert choice.difference > 10 * choice.stderr, choice  # the black voxels cost far more than the error
    run.x, smoothed = x0, run.x.copy()
    run.finish(1)
    np.testing.assert_array_equal(smoothed, run.x)  # the iterate after one pass
    np.testing.assert_array_equal(replay.result[0], _render(run)(64, 77)[0])


def test_the_rule_keeps_the_pass_unless_dropping_it_wins_by_two_standard_errors():
    assert finish.decide(-2.1, 1.0) is False
    assert finish.decide(-1.9, 1.0) is True and finish.decide(0.0, 1.0) is True and finish.decide(5.0, 1.0) is True
    assert finish.paired(np.array([1.0, 2.0, 3.0]), np.array([1.5, 2.5, 3.5])) == pytest.approx((0.5, 0.0))


def test_the_per_texel_loss_removes_the_noise_excess():
    """Renders of one mixture at 4 and at 256 spp: the corrected mean ΔE76² agree within their error, the raw one
    at 4 spp lies far above."""
    scene, run = _scene_of("uniform")
    low = _render(run)(4, 3)
    high = _render(run)(256, 4)
    raw = finish.texel_loss(run.loss, low[0], np.zeros_like(low[1]))
    lo, hi = finish.texel_loss(run.loss, *low[:2]), finish.texel_loss(run.loss, *high[:2])
    se = np.hypot(lo.std() / np.sqrt(len(lo)), hi.std() / np.sqrt(len(hi)))
    assert abs(lo.mean() - hi.mean()) < 4 * se
    assert raw.mean() - lo.mean() > 10 * se


def _run(scene, out, lines=None, passes=FINISH_AUTO, **kw):
    """A run of ``scene`` from the "noisy" mixture (a volume file), no iterations, its figures at ``SPP``."""
    start = out.parent / "noisy.npz"
    if not start.is_file():
        run = Optimization(scene, _cfg().for_scene("slab"), threads=2)
        scene.volume.with_mixture(run.param.mixture(run.param.variables_for(_free_mixture(run, "noisy")))).save(start)
    log = lines.append if lines is not None else lambda m: None
    options = RunOptions(threads=2, eval_spp=SPP, log=log, baseline_guard=False, **kw)
    return run_optimisation(scene, out, _cfg(init=str(start), finish_smooth=passes), options)


@pytest.fixture
def passes(monkeypatch):
    """The figures' render passes of the runs in the test (``RunFigures._pass`` calls)."""
    calls, real = [], runfigures.RunFigures._pass

    def counted(self, renderer, n, s, texels=None):
        calls.append((n, s) if texels is None else (n, s, len(texels)))
        return real(self, renderer, n, s, texels)

    monkeypatch.setattr(runfigures.RunFigures, "_pass", counted)
    return calls


def test_a_run_reports_its_choice_and_writes_the_chosen_result(noisy, tmp_path, passes):
    scene, _ = noisy
    lines = []
    rep = _run(scene, tmp_path / "auto", lines)
    n_auto = len(passes)
    on_disk = json.loads((tmp_path / "auto" / "report.json").read_text())
    f = on_disk["finish"]
    assert f["setting"] == "auto" and f["decision"] == "dropped" and f["passes"] == 0 and not f["smoothed"]
    assert on_disk["finish_smooth"] == 0 and rep.finish == f
    for key in ("loss_smoothed", "loss_unsmoothed", "difference", "stderr", "spp", "texels", "seconds"):
        assert f[key] is not None, key
    assert f["spp"] == SPP and f["difference"] < -2 * f["stderr"]
    said = [m for m in lines if m.startswith("finishing smoothing")]
    assert len(said) == 1 and "dropped" in said[0], lines
    # the result is the last iterate (the checkpoint's), and its figures what a run without the pass measures
    plain = _run(scene, tmp_path / "none", passes=0)
    assert len(passes) - n_auto == n_auto - 1  # the choice costs one render: the chosen one is the figures' pass
    assert plain.finish is None and plain.finish_smooth == 0
    a, b = Volume.load(tmp_path / "auto" / "volume.npz"), Volume.load(tmp_path / "none" / "volume.npz")
    np.testing.assert_array_equal(a.mixture, b.mixture)
    assert rep.metrics.delta_e76_mean_corrected == plain.metrics.delta_e76_mean_corrected
    assert rep.eval_spp == plain.eval_spp == SPP


def test_a_run_measured_on_a_texel_sample_chooses_on_its_points(noisy, tmp_path, passes):
    """A run whose figures are of a texel sample renders the two candidates on the sample's points alone, the chosen
    one then the points' first pass of the result's figures; every texel is rendered once, for the pictures."""
    scene, _ = noisy
    lines = []
    rep = _run(scene, tmp_path / "r", lines, figure_texel_sample=100)
    f = rep.finish
    assert f["decision"] == "dropped" and f["texels"] == 100 and f["difference"] < -2 * f["stderr"], f
    assert rep.texel_sample["sample"]["texels"] == 100 and rep.pictures_spp == rep.eval_spp == SPP
    windows = rep.texel_sample["sample"]["window_texels"]
    # the start: points and windows; the choice: the points twice; the result: its windows (the points replayed)
    # and every texel for the pictures
    want = [100, windows, 100, 100, windows, len(scene.texels)]
    assert [c[2] if len(c) == 3 else len(scene.texels) for c in passes] == want, passes
    predictions = RunDir(tmp_path / "r").load_predictions()
    assert predictions.rgb["continuous"].shape == (len(scene.texels), 3) and predictions.texels is None
    assert predictions.spp["continuous"] == SPP
    page = Path(write_proof(tmp_path / "r").path).read_text()  # the soft proof says where its figures come from
    assert f"on a random sample of 100 of its {len(scene.texels)} texels" in page


def test_finish_smooth_1_forces_the_pass_without_a_choice(noisy, tmp_path, passes):
    scene, _ = noisy
    lines = []
    rep = _run(scene, tmp_path / "one", lines, passes=1)
    assert rep.finish is None and rep.finish_smooth == 1
    assert not [m for m in lines if m.startswith("finishing smoothing")]
    assert len(passes) == 2  # the start's and the result's figures, one pass each: nothing rendered for a choice
    plain = Volume.load(tmp_path / "one" / "volume.npz").mixture
    run = Optimization(scene, _cfg(finish_smooth=1).for_scene("slab"), threads=2)
    run.x = run.param.variables_for(_free_mixture(run, "noisy"))
    run.finish()
    np.testing.assert_allclose(plain, run.mixture(), atol=1e-5)  # the iterate smoothed once


def test_a_resumed_run_makes_the_same_choice(noisy, tmp_path):
    scene, _ = noisy
    first = _run(scene, tmp_path / "r")
    volume = Volume.load(tmp_path / "r" / "volume.npz").mixture
    x = np.load(tmp_path / "r" / "checkpoint.npz")["x"]
    again = _run(scene, tmp_path / "r", resume=True)
    assert again.finish == {**first.finish, "seconds": again.finish["seconds"]}
    np.testing.assert_array_equal(np.load(tmp_path / "r" / "checkpoint.npz")["x"], x)  # the iterate, unsmoothed
    np.testing.assert_array_equal(Volume.load(tmp_path / "r" / "volume.npz").mixture, volume)


def test_a_run_whose_pass_changes_nothing_renders_nothing_for_it(noisy, tmp_path, passes):
    scene, _ = noisy
    lines = []
    rep = run_optimisation(
        scene,
        tmp_path / "r",
        _cfg(smooth=0.0, finish_smooth=FINISH_AUTO),
        RunOptions(threads=2, eval_spp=SPP, log=lines.append, baseline_guard=False),
    )
    assert rep.finish["decision"] == "unchanged" and rep.finish["loss_smoothed"] is None
    assert len(passes) == 2  # the start's and the result's
    assert [m for m in lines if "changes nothing" in m], lines


def test_the_option_takes_a_number_of_passes_or_auto():
    import argparse

    from inkopt.cli.runargs import finish_passes

    assert finish_passes("auto") == FINISH_AUTO and finish_passes("AUTO") == FINISH_AUTO
    assert finish_passes("0") == 0 and finish_passes("2") == 2
    for bad in ("-1", "x", "1.5"):
        with pytest.raises(argparse.ArgumentTypeError):
            finish_passes(bad)
    assert OptimizeConfig(finish_smooth=1).for_scene("mesh").finish_smooth == 1  # the mesh default is one pass
    assert OptimizeConfig().for_scene("mesh").finish_smooth == 1
