"""The optimiser: parameterisations, chain rule to the mixture, convergence on a chart, exact resume."""

import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from helpers import central_differences as _fd
from helpers import small_chart_scene, with_fixed_shares
from helpers import small_run as run

from inkopt.color import srgb_to_linear
from inkopt.evaluation.metrics import prediction_metrics
from inkopt.model import FixedShares, InkTable, mix, mix_grad
from inkopt.optim import (
    AdaGrad,
    Adam,
    ExponentiatedGradient,
    GradientSmoother,
    Optimization,
    OptimizeConfig,
    Parameterization,
    initial_free_mixture,
    make_optimizer,
)
from inkopt.optim.optimizers import abs_percentile
from inkopt.render import Renderer
from inkopt.scenes.slab import build_slab

INKS = InkTable.parse("vero-cmykw")


def test_mix_grad_is_the_chain_rule():
    rng = np.random.default_rng(0)
    rho = rng.dirichlet(np.ones(5), size=(2, 3)).astype(np.float64)
    ws, wa = rng.normal(size=(2, 3, 3)), rng.normal(size=(2, 3, 3))
    f = lambda r: float(np.sum(mix(r, INKS)[0] * ws) + np.sum(mix(r, INKS)[1] * wa))
    np.testing.assert_allclose(mix_grad(ws, wa, INKS), _fd(f, rho), rtol=2e-3, atol=1e-2)


@pytest.mark.parametrize("kind", ["sigmoid", "softmax"])
def test_parameterisation_gradient_and_fixed_shares(kind):
    rng = np.random.default_rng(1)
    fixed = np.zeros((2, 2, 3, 4), np.float32)
    fixed[0, 0, 0] = [0, 0, 0, 1]  # a fully fixed voxel: not a variable
    fixed[1, 1, 1] = [0.8, 0, 0, 0]  # 80 % of ink 0 fixed, 20 % free (a translucency-style constraint)
    p = Parameterization(kind, FixedShares.from_dense(fixed))
    assert p.n_free == 11
    x = rng.normal(size=(p.n_free, 4))
    rho = p.mixture(x)
    np.testing.assert_allclose(rho.sum(-1), 1.0, atol=1e-5)
    np.testing.assert_array_equal(rho[0, 0, 0], [0, 0, 0, 1])
    assert rho[1, 1, 1, 0] >= 0.8 - 1e-6
    w = rng.normal(size=fixed.shape)
    f = lambda x: float(np.sum(p.mixture(x) * w))
    np.testing.assert_allclose(p.backward(x, w), _fd(f, x), rtol=1e-3, atol=1e-4)
    # The sparse (F, N) form of dE/drho gives the same as the dense one.
    np.testing.assert_allclose(p.backward(x, w.reshape(-1, 4)[p.free_index]), p.backward(x, w), rtol=1e-6)


def test_exponentiated_gradient_direction():
    """The natural direction is g - <g, p>: a small EG step multiplies rho by exp(-eta (g - <g,p>)) (renormalised)."""
    rng = np.random.default_rng(2)
    p = Parameterization("softmax", FixedShares.none((1, 1, 2), 3))
    x = rng.normal(size=(2, 3))
    g = rng.normal(size=(1, 1, 2, 3))
    eta = 1e-2
    new = p.mixture(x - eta * p.backward(x, g, natural=True)).reshape(2, 3)
    eg = p.mixture(x).reshape(2, 3) * np.exp(-eta * g.reshape(2, 3))
    np.testing.assert_allclose(new, eg / eg.sum(1, keepdims=True), rtol=1e-5)


def test_softmax_in_the_core_matches_numpy():
    """The Rust core's softmax and backward map (``inkopt_core::simplex``) against the numpy expressions they
    replaced, on more rows than two of its parallel blocks, with a non-contiguous float64 input and on no rows."""
    rng = np.random.default_rng(5)
    fixed = np.zeros((3, 40, 100, 5), np.float32)  # 12 000 free voxels
    fixed[:, :, 0] = [0.5, 0, 0, 0, 0]  # a free share of 0.5 on a column
    p = Parameterization("softmax", FixedShares.from_dense(fixed))
    x = (rng.normal(size=(p.n_free, 10)) * 4)[:, ::2]  # strided float64
    g = rng.normal(size=(p.n_free, 5)).astype(np.float32)
    e = np.exp(x.astype(np.float32) - x.astype(np.float32).max(1, keepdims=True))
    want_p = e / e.sum(1, keepdims=True)
    # float32 rounding of exp (numpy's vectorised exp and Rust's differ by an ulp): entries of at most 1
    np.testing.assert_allclose(p.free_rows(x), p.fixed_f + p.share_f[:, None] * want_p, rtol=0, atol=1e-6)
    gs = g * p.share_f[:, None]
    centred = gs - np.sum(gs * want_p, axis=1, keepdims=True)
    np.testing.assert_allclose(p.backward(x, g, natural=True), centred, rtol=0, atol=4e-6)
    np.testing.assert_allclose(p.backward(x, g), want_p * centred, rtol=0, atol=4e-6)
    assert p.backward(x, g).dtype == np.float32
    empty = Parameterization("softmax", FixedShares.from_dense(np.ones((1, 2, 2, 1), np.float32)))
    assert empty.n_free == 0 and empty.backward(np.zeros((0, 1), np.float32), np.zeros((1, 2, 2, 1))).shape == (0, 1)


def _pool_threads(n: int, want: int | None = None, wait_s: float = 10.0) -> int:
    """How many threads of the bindings' kept pool of ``n`` (named ``inkopt-p{n}-{i}``) the process has.

    A new thread takes its name once it first runs, which on a busy machine can be after the pool's first jobs
    have returned; with ``want`` given, count again until that many are seen or ``wait_s`` has passed."""
    deadline = time.monotonic() + wait_s
    while True:
        count = 0
        for t in Path("/proc/self/task").iterdir():
            try:
                count += (t / "comm").read_text().startswith(f"inkopt-p{n}-")
            except OSError:  # a thread that ended meanwhile
                pass
        if want is None or count >= want or time.monotonic() > deadline:
            return count
        time.sleep(0.01)


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="reads the process's thread names in /proc")
def test_core_array_functions_keep_to_the_callers_threads():
    """``threads`` of the softmax, its backward map and the step smoothing: the same bits as on all cores, run
    in a pool of that many threads, made once and kept (not rayon's global pool of all cores), so that an ink-set
    search's per-run share of the cores holds for them too."""
    from inkopt import _core

    rng = np.random.default_rng(2)
    x = rng.normal(size=(5000, 4)).astype(np.float32)
    g = rng.normal(size=(5000, 4)).astype(np.float32)
    scale = np.ones(5000, np.float32)
    index, shape = np.arange(5000), (5, 10, 100)
    want = (_core.softmax_rows(x), _core.softmax_backward(x, g, scale, True), GradientSmoother(shape, index, 1.5)(g))
    for _ in range(2):  # the second round reuses the pool
        got = (
            _core.softmax_rows(x, 7),
            _core.softmax_backward(x, g, scale, True, 7),
            GradientSmoother(shape, index, 1.5, threads=7)(g),
        )
        assert _pool_threads(7, want=7) == 7
        for a, b in zip(got, want):
            np.testing.assert_array_equal(a, b)
    assert _pool_threads(3) == 0  # no pool of a count nobody asked for


def test_optimisation_lowers_delta_e_far_below_white_start():
    """30 iterations on a small colour chart, colour term only: the mean dE76 (at 64 spp, noise < 1 dE)
    drops far below the all-white start, and the training loss goes down."""
    scene = small_chart_scene()
    r = run(scene, gamma=(1.0, 0.0, 0.0))
    start = prediction_metrics(r.loss, Renderer(r.volume()).render(scene.texels, 64, 99).rgb)
    r.run()
    end = prediction_metrics(r.loss, Renderer(r.volume()).render(scene.texels, 64, 99).rgb)
    assert end.delta_e76_mean < 0.75 * start.delta_e76_mean, (start, end)
    h = np.array(r.history.loss)
    assert h[-5:].mean() < 0.7 * h[:5].mean()


@pytest.mark.parametrize("gamma", [(1.0, 0.0, 0.0), (1.0, 1.0, 0.0)])
def test_only_steps_that_read_the_loss_operators_hold_them(gamma):
    """The set-up and the figures hold none of the loss's sparse operators (they are found a block of rows at a
    time); the steps build and hold them only when they read them (γ2 > 0 or γ3 > 0)."""
    scene = small_chart_scene()
    r = run(scene, gamma=gamma, iterations=2)
    assert not r.loss._ops.held
    prediction_metrics(r.loss, Renderer(r.volume()).render(scene.texels, 4, 99).rgb)  # as the start's figures
    assert not r.loss._ops.held
    r.run()
    assert r.loss._ops.held == (gamma[1] > 0)


def test_without_forward_renders(monkeypatch):
    """forward_spp 0: only the first iteration renders forward (START_FORWARD_SPP); the loss is taken on the running
    average of the gradient passes' estimates, and 30 iterations still lower dE76 far below the white start."""
    from inkopt.optim import loop

    scene = small_chart_scene()
    r = run(scene, gamma=(1.0, 0.0, 0.0), forward_spp=0, adjoint_ema=0.9)
    calls = []
    orig = Renderer.render
    monkeypatch.setattr(Renderer, "render", lambda self, *a, **k: calls.append(a[1]) or orig(self, *a, **k))
    start = prediction_metrics(r.loss, Renderer(r.volume()).render(scene.texels, 64, 99).rgb)
    calls.clear()
    r.run()
    assert calls == [loop.START_FORWARD_SPP]
    end = prediction_metrics(r.loss, Renderer(r.volume()).render(scene.texels, 64, 99).rgb)
    assert end.delta_e76_mean < 0.75 * start.delta_e76_mean, (start, end)
    # the average's weight tends to spp / (1 - adjoint_ema): 4 / 0.1 = 40 samples per texel
    assert abs(r.c_weight - 40.0) < 2.0, r.c_weight
    with pytest.raises(ValueError, match="forward_spp"):
        OptimizeConfig(forward_spp=-1).validate()


@pytest.mark.parametrize("forward_spp,smooth", [(16, 0.0), (0, 0.0), (16, 1.0)])
def test_resume_continues_exactly(tmp_path, forward_spp, smooth):
    """6 iterations in one go and 3 + 3 through a checkpoint give bit-identical variables."""
    scene = small_chart_scene(12, 8, 0.3)
    a = run(scene, iterations=6, forward_spp=forward_spp, smooth=smooth, decay=0.5)  # steps 3-5 decayed
    a.run()
    b = run(scene, iterations=6, forward_spp=forward_spp, smooth=smooth, decay=0.5)
    for _ in range(3):  # a run of 6 stopped after 3
        b.step()
    b.save_checkpoint(tmp_path / "ck.npz")
    c = run(scene, iterations=6, forward_spp=forward_spp, smooth=smooth, decay=0.5)
    c.load_checkpoint(tmp_path / "ck.npz")
    assert c.iteration == 3
    c.run(tmp_path / "ck.npz")
    np.testing.assert_array_equal(a.x, c.x)
    assert a.history.loss == c.history.loss
    # A checkpoint made with other settings is refused.
    d = run(scene, iterations=6, lr=0.3)
    with pytest.raises(ValueError, match="different settings"):
        d.load_checkpoint(tmp_path / "ck.npz")
    # the smoothing width and the step decay are part of the key
    e = run(scene, iterations=6, forward_spp=forward_spp, smooth=0.5 if smooth else 1.0, decay=0.5)
    with pytest.raises(ValueError, match="different settings"):
        e.load_checkpoint(tmp_path / "ck.npz")
    f = run(scene, iterations=6, forward_spp=forward_spp, smooth=smooth, decay=0.25)
    with pytest.raises(ValueError, match=r"different settings \(decay 0.5 -> 0.25\)"):  # names what changed
        f.load_checkpoint(tmp_path / "ck.npz")
    # the run's wall time carries over: the resumed run's count starts at the checkpoint's
    assert c.wall_seconds() >= float(np.load(tmp_path / "ck.npz")["wall_seconds"]) > 0


@pytest.mark.parametrize("kind", ["surface", "extrusion"])
def test_start_from_a_baseline(kind, monkeypatch):
    """--init surface|extrusion starts from that baseline's mixture (fixed shares kept, zeros lifted to 1e-6 by
    the softmax), and the start is reproducible (what a resumed run reports)."""
    from inkopt.evaluation import baselines

    inks = InkTable.from_names(["cyan", "white"])
    table = baselines.colour_table(inks, patch_mm=1.0, step=8, max_stderr=0.4)  # small table, cached after once
    monkeypatch.setattr(baselines, "colour_table", lambda *a, **k: table)
    img = np.full((6, 8, 3), 255, np.uint8)
    img[:, :4] = (0, 160, 220)  # cyan half
    vox = 25.4 / 300
    scene = build_slab(srgb_to_linear(img / 255.0).astype(np.float32), None, (8 * vox, 6 * vox, 4 * vox), inks)
    fixed = np.zeros(scene.volume.shape + (2,), np.float32)
    fixed[0, ..., 1] = 1.0  # bottom layer fixed white
    start = lambda k: baselines.baseline_mixture(k, scene.volume, scene.texels, scene.target_rgb, fixed, table=table)
    r = Optimization(
        with_fixed_shares(scene, FixedShares.from_dense(fixed)),
        OptimizeConfig(init=kind, iterations=1).for_scene(scene.kind),
        baseline=start,
    )
    make = baselines.surface_baseline if kind == "surface" else baselines.extrusion_baseline
    want = make(scene.volume, scene.texels, scene.target_rgb, fixed, table)
    got = r.initial_volume().mixture
    np.testing.assert_allclose(got, want, atol=2e-6)
    np.testing.assert_allclose(r.volume().mixture, got)
    assert want[-1, 0, 0, 0] > want[-1, 0, -1, 0] + 0.1  # the cyan half has cyan ink, the white half less
    with pytest.raises(ValueError, match="needs the run's texels"):
        initial_free_mixture(inks, r.param, kind, 0)


@pytest.mark.parametrize("opt", ["eg", "adagrad"])
def test_ctrl_c_inside_a_step_resumes_exactly(tmp_path, opt):
    """Ctrl-C during a gradient pass: the checkpoint holds the state before that step (running average, optimiser
    moments, history), so the resumed run ends bit-identically to an uninterrupted one."""
    scene = small_chart_scene(12, 8, 0.3)
    a = run(scene, iterations=5, optimizer=opt)
    a.run()
    b = run(scene, iterations=5, optimizer=opt)
    calls = {"n": 0}
    b.renderer()  # build it so its gradient can be wrapped
    real = b._renderer.gradient

    def interrupted(*args, **kw):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return real(*args, **kw)

    b._renderer.gradient = interrupted
    with pytest.raises(KeyboardInterrupt):
        b.run(tmp_path / "ck.npz")
    c = run(scene, iterations=5, optimizer=opt)
    c.load_checkpoint(tmp_path / "ck.npz")
    assert c.iteration == 2 and len(c.history.loss) == 2
    c.run()
    np.testing.assert_array_equal(a.x, c.x)
    assert a.history.loss == c.history.loss


def test_exponentiated_gradient_step_scale_is_frozen_after_warmup():
    """EG's step scale is the mean of the 99th percentile of |g| over the first ``warmup`` steps, then fixed: the
    most influential coordinates move by about lr per step whatever the gradient's later size."""
    rng = np.random.default_rng(3)
    opt = ExponentiatedGradient(lr=1.0, shape=(200, 3), beta=0.0, warmup=3)
    x = np.zeros((200, 3), np.float32)
    scales = []
    for t in range(6):
        g = rng.normal(size=(200, 3)) * (10.0**t)
        if t < 3:
            scales.append(np.percentile(np.abs(g), 99))
        x_new = opt.step(x, g)
        if t < 3:
            np.testing.assert_allclose(opt.v[0], np.mean(scales), rtol=1e-5)
        np.testing.assert_allclose(x_new - x, -g / np.mean(scales), rtol=1e-4)  # beta = 0: m = g
        x = x_new


def test_exponentiated_gradient_step_is_numpys_expression_bit_for_bit():
    """The Rust step equals the numpy expression it replaces, in float32, bit for bit (over several warm-up and
    later steps, for 1 and 2 threads): m' = beta m + (1 - beta) g, x' = x - lr (m' / bias) / s, s the running mean
    of np.percentile(|g|, 99) over the warm-up."""
    rng = np.random.default_rng(11)
    shape = (70_001, 5)
    x = (rng.normal(size=shape) * 3).astype(np.float32)
    opts = [ExponentiatedGradient(lr=0.7, shape=shape, threads=k) for k in (1, 2)]
    m, v = np.zeros(shape, np.float32), np.zeros(1, np.float32)
    for t in range(1, 8):
        g = (rng.normal(size=shape) * np.exp(rng.normal(size=shape))).astype(np.float32)
        if t <= 5:
            v = v.copy()
            v[0] += (float(np.percentile(np.abs(g), 99.0)) - v[0]) / t
        m = 0.8 * m + (1 - 0.8) * g
        x_ref = x - 0.7 * (m / (1 - 0.8**t)) / (v[0] + 1e-30)
        outs = [o.step(x, g) for o in opts]
        for o, out in zip(opts, outs):
            assert out.dtype == np.float32 and o.m.dtype == np.float32
            np.testing.assert_array_equal(out, x_ref)
            np.testing.assert_array_equal(o.m, m)
            np.testing.assert_array_equal(o.v, v)
        x = x_ref


@pytest.mark.parametrize("n", [1, 2, 3, 5, 100, 101, 4999, 100_000])
def test_abs_percentile_is_numpys(n):
    """The step scale's percentile from two exact order statistics equals numpy's (linear method) bit for bit, ties,
    zeros and signs included, for several percentiles."""
    rng = np.random.default_rng(n)
    g = (rng.normal(size=n) * np.exp(2 * rng.normal(size=n))).astype(np.float32)
    g[rng.random(n) < 0.2] = 0.0
    g[rng.random(n) < 0.2] = -1.5
    g = g.reshape(-1, 1)
    for q in (0.0, 1.0, 50.0, 99.0, 99.9, 100.0):
        assert abs_percentile(g, q) == float(np.percentile(np.abs(g), q)), q


@pytest.mark.parametrize("n,q", [(17_858_959, 99.0), (34_001, 99.9), (78_397_510, 99.0)])
def test_abs_percentile_weight_is_numpys_at_large_sizes(n, q):
    """The interpolation weight between the two order statistics is numpy's to the bit at sizes where an
    algebraically equal index formula, n q + (1 - q) - 1, rounds differently from numpy's (n - 1) q (the first two;
    the last is Spot 40 mm's 15.7 M voxels x 5 inks): |g| is 0 up to the lower rank and 1 above, so the percentile
    is the weight itself."""
    lo = int(np.floor((n - 1) * (q / 100)))
    g = np.zeros((n, 1), np.float32)
    g[lo + 1 :] = -1.0
    assert abs_percentile(g, q) == float(np.percentile(np.abs(g), q))


@pytest.mark.parametrize("kind,cls", [("eg", ExponentiatedGradient), ("adagrad", AdaGrad), ("adam", Adam)])
def test_optimizer_state_round_trips(kind, cls):
    """state() / load() restore an optimiser exactly (what resume relies on), under the same checkpoint keys; a step
    returns a new array that neither its input nor the optimiser's state shares (the loop changes it in place)."""
    rng = np.random.default_rng(4)
    a, b = make_optimizer(kind, 0.5, (7, 4)), make_optimizer(kind, 0.5, (7, 4))
    assert isinstance(a, cls) and a.natural == (kind == "eg")
    x = rng.normal(size=(7, 4)).astype(np.float32)
    for _ in range(3):
        x_new = a.step(x, g := rng.normal(size=(7, 4)).astype(np.float32))
        assert not any(np.shares_memory(x_new, y) for y in (x, g, a.m, a.v))
        x = x_new
    assert set(a.state()) == {"opt_m", "opt_v", "opt_t"}
    b.load(a.state())
    g = rng.normal(size=(7, 4)).astype(np.float32)
    np.testing.assert_array_equal(a.step(x, g), b.step(x, g))


def test_one_renderer_per_run():
    """The loop builds its renderer once and swaps the medium each iteration (no per-iteration set-up)."""
    scene = small_chart_scene(8, 6, 0.2)
    r = run(scene, iterations=2)
    r.run()
    first = r._renderer
    r.step()
    assert r._renderer is first


@pytest.mark.slow
def test_ssim_term_raises_ssim():
    """gamma2 > 0 raises SSIM against the target compared with gamma2 = 0 (same seeds, 80 iterations)."""
    scene = small_chart_scene(32, 24, 1.0, bottom=True)
    out = {}
    for g2 in (0.0, 3.0):
        r = run(scene, iterations=80, gamma=(1.0, g2, 0.0))  # measured: SSIM 0.555 (g2=0) vs 0.593 (g2=3)
        r.run()
        out[g2] = prediction_metrics(r.loss, Renderer(r.volume()).render(scene.texels, 256, 7).rgb).ssim
    assert out[3.0] > out[0.0] + 0.01, out


def test_the_loop_smooths_the_optimisers_step():
    """One iteration with smoothing moves the variables by exactly the smoothed step of the same iteration
    without it (same seeds, same start): the smoother acts on the step, after the optimiser."""
    from inkopt.optim.smooth import MAX_DEPTH, GradientSmoother, nearest_texels, texel_guide

    scene = small_chart_scene(48, 32, 0.3)  # big enough for flat texels (patch interiors): 61 of 1536
    runs = {}
    for smooth in (0.0, 1.0):
        cfg = OptimizeConfig(iterations=1, spp=4, forward_spp=16, smooth=smooth)
        r = Optimization(scene, cfg.for_scene(scene.kind), threads=2)
        x0 = r.x.copy()
        r.run()
        runs[smooth] = (x0, r)
    x0, plain = runs[0.0]
    _, smoothed = runs[1.0]
    p = plain.param
    nearest, dist = nearest_texels(p.shape, p.free_index, scene.texels.pos_vox, MAX_DEPTH)
    rows = np.flatnonzero((nearest >= 0) & plain.loss.flat[nearest])  # the free voxels under flat texels
    assert 0 < len(rows) < p.n_free
    sm = GradientSmoother(
        p.shape, p.free_index, 1.0, texel_guide(plain.loss.target_lab, nearest[rows], dist[rows]), 4.0, rows
    )
    expect = x0 + sm(plain.x - x0)
    np.testing.assert_allclose(smoothed.x, expect, atol=1e-5)
    others = np.setdiff1d(np.arange(p.n_free), rows)
    np.testing.assert_allclose(smoothed.x[others], plain.x[others], atol=1e-6)  # the others take the plain step
    assert np.abs(smoothed.x - plain.x).max() > 1e-3


@pytest.mark.parametrize("opt", ["eg", "adam", "adagrad"])
def test_steps_in_blocks_of_rows_are_bit_identical(opt, monkeypatch):
    """A big object's per-voxel arithmetic (mixtures to the renderer, the chain rule, the optimiser's update)
    runs in blocks of rows to bound its temporaries: with blocks of a few rows, 4 iterations give the same
    variables and optimiser state, bit for bit, as with one block."""
    from inkopt.optim import optimizers

    scene = small_chart_scene(bottom=True)
    whole = run(scene, iterations=4, optimizer=opt, lr=0.5)
    whole.run()
    monkeypatch.setattr(optimizers, "ROWS", 37)
    orig = Parameterization.chunks
    monkeypatch.setattr(Parameterization, "chunks", lambda self, rows=0: orig(self, 101))
    blocks = run(scene, iterations=4, optimizer=opt, lr=0.5)
    assert len(blocks.param.chunks()) > 10
    blocks.run()
    np.testing.assert_array_equal(blocks.x, whole.x)
    for k, v in whole.opt.state().items():
        np.testing.assert_array_equal(blocks.opt.state()[k], v)


def test_a_warm_start_takes_half_the_default_step():
    """A start other than white or random steps at WARM_LR_FACTOR of the default, written out in the checkpoint key
    (so a checkpoint made when the warm start took the full step is not resumed as if it were the same run); an
    explicit lr is kept."""
    from inkopt.optim.config import WARM_LR_FACTOR

    assert OptimizeConfig(init="white").step_size == 2.0 and OptimizeConfig(init="random").step_size == 2.0
    assert OptimizeConfig(init="extrusion").step_size == 2.0 * WARM_LR_FACTOR
    assert OptimizeConfig(init="run/volume.npz", lr=1.5).step_size == 1.5
    assert OptimizeConfig(init="surface", optimizer="adam").step_size == 0.1 * WARM_LR_FACTOR


def test_step_decay_schedule():
    """The full step until the run's last `decay` fraction, then DECAY_HALVINGS halvings in equal stages."""
    from inkopt.optim.optimizers import DECAY_HALVINGS, step_factor

    assert DECAY_HALVINGS == 3
    f = [step_factor(t, 8, 0.5) for t in range(8)]
    assert f == [1, 1, 1, 1, 0.5, 0.5, 0.25, 0.125]
    f = [step_factor(t, 200, 0.25) for t in range(200)]
    assert f[149] == 1 and f[150] == 0.5 and f[166] == 0.5 and f[167] == 0.25 and f[184] == 0.125 == min(f)
    assert sorted(set(f)) == [0.125, 0.25, 0.5, 1] and all(a >= b for a, b in zip(f, f[1:]))
    assert all(step_factor(t, 200, 0.0) == 1 for t in range(200))
    for bad in (-0.1, 1.0):
        with pytest.raises(ValueError, match="decay"):
            OptimizeConfig(decay=bad).validate()


@pytest.mark.parametrize("decay", [0.5, 0.0])
def test_the_loop_steps_with_the_decayed_step_size(decay):
    """Each step is taken with the configured step size times the schedule's factor for that iteration."""
    from inkopt.optim.optimizers import step_factor

    r = run(small_chart_scene(12, 8, 0.3), iterations=6, decay=decay)
    used, update = [], r.opt.update
    r.opt.update = lambda x, g, into_g=False: used.append(r.opt.lr) or update(x, g, into_g)
    r.run()
    base = r.cfg.step_size
    assert used == [base * step_factor(t, 6, decay) for t in range(6)]
    assert (used[-1] == base / 8) if decay else (used == [base] * 6)


def test_settings_left_to_the_scene_kind():
    """adjoint_ema and smooth unset: the scene kind's values (slabs 0.8 and 1.5, meshes 0.5 and 3; a set value is
    kept). The run's cfg is the resolved one, so checkpoints of the two do not mix, and the running average's weight
    follows its recursion w <- ema * w + forward_spp + spp (tending to 20 / (1 - ema) samples per texel)."""
    from inkopt.optim import SCENE_DEFAULTS
    from inkopt.optim.config import FINISH_AUTO
    from inkopt.optim.smooth import diffusion_steps

    assert diffusion_steps(1.5) != diffusion_steps(3.0)
    assert SCENE_DEFAULTS == {
        "slab": {"adjoint_ema": 0.8, "smooth": 1.5, "init": "white", "finish_smooth": 0, "colour_term": "squared"},
        "mesh": {"adjoint_ema": 0.5, "smooth": 3.0, "init": "white", "finish_smooth": 1, "colour_term": "linear"},
    }
    assert OptimizeConfig(finish_smooth=2).for_scene("slab").finish_smooth == 2
    assert OptimizeConfig(finish_smooth=FINISH_AUTO).for_scene("mesh").finish_smooth == FINISH_AUTO
    assert OptimizeConfig().adjoint_ema is None and OptimizeConfig().smooth is None and OptimizeConfig().init is None
    mesh = OptimizeConfig().for_scene("mesh")
    assert (mesh.adjoint_ema, mesh.smooth, mesh.init) == (0.5, 3.0, SCENE_DEFAULTS["mesh"]["init"])
    kept = OptimizeConfig(adjoint_ema=0.3, smooth=0.0).for_scene("mesh")
    assert (kept.adjoint_ema, kept.smooth) == (0.3, 0.0)
    with pytest.raises(ValueError, match="scene kind"):
        OptimizeConfig().for_scene("torus")
    scene = small_chart_scene(12, 8, 0.3)
    cfg = OptimizeConfig(iterations=8, spp=4, forward_spp=16)
    runs = {kind: Optimization(scene, cfg.for_scene(kind), threads=2) for kind in ("slab", "mesh")}
    assert runs["slab"].config_key() != runs["mesh"].config_key()
    # checkpoints made when 0.8 and 1.5 were every scene's defaults still resume on slabs; an integer spelling of a
    # setting (``--set smooth=3``) gives the default's key
    old = Optimization(scene, replace(cfg, adjoint_ema=0.8, smooth=1.5).for_scene("slab"), threads=2)
    assert old.config_key() == runs["slab"].config_key()
    spelled = Optimization(scene, replace(cfg, smooth=3, adjoint_ema=0.5).for_scene("mesh"), threads=2)
    with pytest.raises(ValueError, match="resolved"):  # one configuration: the run reads the settings it is given
        Optimization(scene, cfg, threads=2)
    assert spelled.config_key() == runs["mesh"].config_key()
    for kind, r in runs.items():
        ema, smooth = SCENE_DEFAULTS[kind]["adjoint_ema"], SCENE_DEFAULTS[kind]["smooth"]
        assert (r.cfg.adjoint_ema, r.cfg.smooth, r.smoother.steps) == (ema, smooth, diffusion_steps(smooth))
        r.run()
        assert r.c_weight == pytest.approx(sum(20 * ema**k for k in range(8)), rel=1e-6)


def test_finish_smooths_the_result_not_the_checkpoint(tmp_path):
    """``finish`` applies ``finish_smooth`` passes of the step's smoothing operator to x: only the smoothed set's
    rows change, each column's sum over them is kept (the diffusion moves mass, it makes none), their
    voxel-to-voxel variation falls, and every pass is the operator once more. The checkpoint written at the run's
    end keeps the unsmoothed iterate, and the number of passes is not part of the checkpoint key (it does not
    change a step). 0 passes, or no smoothing, leave x alone."""
    top = np.zeros((48, 64, 3), np.float32)  # two flat halves (a smoothed set) and an edge between them (not)
    top[:, :32] = srgb_to_linear(np.array([0.8, 0.3, 0.2]))
    top[:, 32:] = srgb_to_linear(np.array([0.2, 0.5, 0.8]))
    vox = 25.4 / 300
    scene = build_slab(top, None, (16 * vox, 12 * vox, 0.4), InkTable.parse("vero-cmykw"))
    r = run(scene, iterations=6, smooth=1.5, finish_smooth=2)
    ck = tmp_path / "checkpoint.npz"
    r.run(ck)
    before = r.x.copy()
    rows = r.smoother.rows
    assert rows is not None and 0 < len(rows) < r.param.n_free
    once = r.smoother.apply(before.copy())
    r.finish()
    assert np.array_equal(r.x, r.smoother.apply(once.copy()))
    outside = np.setdiff1d(np.arange(r.param.n_free), rows)
    assert np.array_equal(r.x[outside], before[outside])
    np.testing.assert_allclose(r.x[rows].sum(0), before[rows].sum(0), rtol=1e-4)
    assert r.x[rows].var(0).sum() < before[rows].var(0).sum()

    resumed = run(scene, iterations=6, smooth=1.5, finish_smooth=0)
    assert resumed.config_key() == r.config_key()
    assert resumed.resume(ck, log=lambda s: None)
    assert np.array_equal(resumed.x, before)
    resumed.finish()
    assert np.array_equal(resumed.x, before)
    plain = run(scene, iterations=1, smooth=0.0, finish_smooth=3)
    plain.run()
    x = plain.x.copy()
    plain.finish()
    assert plain.smoother is None and np.array_equal(plain.x, x)
    with pytest.raises(ValueError, match="finish_smooth"):
        OptimizeConfig(finish_smooth=9).validate()


def test_the_colour_term_is_the_scene_kinds_unless_given():
    """No ``--colour-term``: the config leaves it to the scene kind, the mean dE76 on meshes and the mean dE76^2 on
    slabs (``SCENE_DEFAULTS``); given, it is kept on either."""
    from inkopt.cli import build_parser
    from inkopt.cli.runargs import config_from_args

    cfg = config_from_args(build_parser().parse_args(["slab", "top.png", "--size-mm", "6x4x1", "--out", "run"]))
    assert cfg.colour_term is None
    assert cfg.for_scene("mesh").colour_term == "linear" and cfg.for_scene("slab").colour_term == "squared"
    assert replace(cfg, colour_term="squared").for_scene("mesh").colour_term == "squared"
    assert replace(cfg, colour_term="linear").for_scene("slab").colour_term == "linear"
    assert not cfg.resolved and cfg.for_scene("mesh").resolved


def test_the_linear_colour_term_optimises_and_is_an_option():
    """``--colour-term linear`` reaches the run's loss (``OptimizeConfig.colour_term``), whose 30 iterations lower the
    chart's dE76 far below the white start, as the squared term's do."""
    from inkopt.cli import build_parser
    from inkopt.cli.runargs import config_from_args

    args = build_parser().parse_args(
        ["slab", "top.png", "--size-mm", "6x4x1", "--out", "run", "--colour-term", "linear"]
    )
    assert config_from_args(args).colour_term == "linear"
    scene = small_chart_scene()
    r = run(scene, gamma=(1.0, 0.0, 0.0), colour_term="linear")
    assert r.loss.colour_term == "linear"
    start = prediction_metrics(r.loss, Renderer(r.volume()).render(scene.texels, 64, 99).rgb)
    r.run()
    end = prediction_metrics(r.loss, Renderer(r.volume()).render(scene.texels, 64, 99).rgb)
    assert end.delta_e76_mean < 0.75 * start.delta_e76_mean, (start, end)
