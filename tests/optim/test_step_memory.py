"""The step's memory: the in-place update (the same bits as a step on copies; Ctrl-C during it finishes the step),
the smoothing a column at a time, the smoother's guide made in chunks, the step scale's held voxels, and the band
voxels a renderer is given fixed shares for."""

import signal

import numpy as np
import pytest
from helpers import SPOT, fuzz, small_chart_scene
from helpers import small_run as run
from hypothesis import given
from hypothesis import strategies as st

from inkopt.optim import optimizers
from inkopt.optim.optimizers import OPTIMIZER_CLASSES


@pytest.mark.parametrize("kind", sorted(OPTIMIZER_CLASSES))
@pytest.mark.parametrize("into_g", [False, True])
def test_update_in_place_is_the_copying_step_bit_for_bit(kind, into_g, monkeypatch):
    """Over several steps (the warm-up's and later ones) and blocks of rows: ``update`` leaves in x (or, with
    ``into_g``, in g as x' - x) exactly what ``step`` returns, with the same state."""
    monkeypatch.setattr(optimizers, "ROWS", 7)  # several blocks, the last one short
    rng = np.random.default_rng(5)
    shape = (50, 5)
    a, b = OPTIMIZER_CLASSES[kind](0.5, shape, threads=2), OPTIMIZER_CLASSES[kind](0.5, shape, threads=1)
    x_a = rng.normal(size=shape).astype(np.float32)
    x_b = x_a.copy()
    for _ in range(8):
        g = (rng.normal(size=shape) * rng.uniform(0.1, 10)).astype(np.float32)
        old_m = a.m
        x_new = a.step(x_a, g)
        assert a.m is not old_m  # the copying step replaces its state
        g_b = g.copy()
        b.update(x_b, g_b, into_g=into_g)
        if into_g:
            np.testing.assert_array_equal(g_b, x_new - x_b)
            x_b += g_b
        np.testing.assert_array_equal(x_b, x_new)
        np.testing.assert_array_equal(a.m, b.m)
        np.testing.assert_array_equal(a.v, b.v)
        x_a = x_new


@pytest.mark.parametrize("smooth", [0.0, 1.5])
def test_ctrl_c_during_the_update_finishes_the_step(tmp_path, smooth):
    """SIGINT while the step changes x in place is held back until the step is done: the run stops after that step,
    its checkpoint holds it, and the resumed run ends bit-identically to an uninterrupted one. Python's own Ctrl-C
    handler is set for the test: a pytest started in the background from a non-interactive shell inherits SIGINT
    as ignored, and an ignored signal would never interrupt the run."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        _interrupt_a_run(tmp_path, smooth)
    finally:
        signal.signal(signal.SIGINT, before)


def _interrupt_a_run(tmp_path, smooth):
    scene = small_chart_scene(12, 8, 0.3)
    a = run(scene, iterations=5, smooth=smooth)
    a.run()
    b = run(scene, iterations=5, smooth=smooth)
    real, calls = b.opt.update, {"n": 0}

    def interrupted(x, g, into_g=False):
        calls["n"] += 1
        if calls["n"] == 3:
            signal.raise_signal(signal.SIGINT)  # Ctrl-C as the update starts
        real(x, g, into_g)

    b.opt.update = interrupted
    with pytest.raises(KeyboardInterrupt):
        b.run(tmp_path / "ck.npz")
    assert b.iteration == 3
    c = run(scene, iterations=5, smooth=smooth)
    c.load_checkpoint(tmp_path / "ck.npz")
    assert c.iteration == 3 and len(c.history.loss) == 3
    c.run()
    np.testing.assert_array_equal(a.x, c.x)
    assert a.history.loss == c.history.loss


@pytest.mark.parametrize("zeros", [0, 1, 37, 400, 5000])
def test_abs_percentile_with_zeros_is_numpys(zeros):
    """The percentile of |g| with ``zeros`` more entries of 0 is numpy's of the padded array, bit for bit."""
    rng = np.random.default_rng(zeros)
    g = (rng.normal(size=(230, 5)) * rng.uniform(0.1, 3.0, size=(230, 1))).astype(np.float32)
    for q in (99.0, 50.0, 0.0, 100.0):
        padded = np.concatenate([np.abs(g).ravel(), np.zeros(zeros, np.float32)])
        assert optimizers.abs_percentile(g, q, 2, zeros) == float(np.percentile(padded, q))


def test_a_shell_runs_step_scale_counts_its_core():
    """A shell run's exponentiated gradient counts the inside voxels that are not free as zero gradients of its step
    scale's percentile; a run with every inside voxel free counts none (its step scale is unchanged)."""
    from inkopt.model import InkTable
    from inkopt.scenes import build_scene
    from inkopt.scenes.spec import MeshSpec

    inks = InkTable.parse("vero-cmykw")
    for shell in (None, 0.3):
        scene = build_scene(MeshSpec(str(SPOT), height_mm=4.0, shell_mm=shell), inks)
        r = run(scene, iterations=1)
        inside = scene.volume.inside.count
        assert r.opt.held_rows == inside - r.param.n_free
        assert (r.opt.held_rows > 0.2 * inside) if shell else (r.opt.held_rows == 0)


@pytest.mark.parametrize("guided", [False, True])
def test_smoothing_the_set_in_place_is_the_gathered_sets_bit_for_bit(guided):
    """``GradientSmoother.apply`` diffuses the set's rows of g in place through their row numbers; the kernel on the
    gathered rows and their voxels gives the same bits, and the other rows are unchanged."""
    from inkopt import _core
    from inkopt.optim.smooth import ALPHA, GradientSmoother

    rng = np.random.default_rng(2)
    shape = (6, 9, 11)
    index = np.flatnonzero(rng.random(int(np.prod(shape))) < 0.7)
    rows = np.flatnonzero(rng.random(len(index)) < 0.8)
    guide = rng.normal(size=(len(rows), 4)).astype(np.float32) if guided else None
    sm = GradientSmoother(shape, index, 2.0, guide, 1.5 if guided else 0.0, rows, threads=2)
    g = rng.normal(size=(len(index), 5)).astype(np.float32)
    whole = g.copy()
    tau = 1.5 if guided else 1.0
    sub = np.ascontiguousarray(g[rows])
    _core.smooth_rows(shape, index[rows], sub, sm.steps, ALPHA, guide, tau, 2)
    whole[rows] = sub
    assert not np.array_equal(sub, g[rows])
    np.testing.assert_array_equal(sm(g), whole)
    np.testing.assert_array_equal(sm.apply(g), whole)


def test_the_smoothers_guide_made_in_chunks_is_the_whole_arrays(monkeypatch):
    """The loop's smoother keeps the rows and guide of the free voxels under flat texels found a chunk of voxels at
    a time: the same as from the whole (F,) nearest-texel arrays."""
    from functools import partial

    from inkopt.optim import smooth
    from inkopt.optim.smooth import MAX_DEPTH, nearest_texel_chunks, nearest_texels, texel_guide

    monkeypatch.setattr(smooth, "nearest_texel_chunks", partial(nearest_texel_chunks, chunk=37))
    scene = small_chart_scene(48, 32, 0.3)
    r = run(scene, iterations=1, smooth=1.0)
    monkeypatch.undo()  # the whole arrays below, from the module's own chunking
    p = r.param
    assert p.n_free > 10 * 37
    nearest, dist = nearest_texels(p.shape, p.free_index, scene.texels.pos_vox, MAX_DEPTH)
    rows = np.flatnonzero((nearest >= 0) & r.loss.flat[nearest])
    assert 0 < len(rows) < p.n_free
    np.testing.assert_array_equal(r.smoother.rows, rows)
    want = texel_guide(r.loss.target_lab, nearest[rows], dist[rows])
    assert r.smoother.rows.dtype == np.uint32 and r.smoother.guide.key.dtype == np.uint32
    np.testing.assert_array_equal(r.smoother.guide.key, want.key)
    np.testing.assert_array_equal(r.smoother.guide.extra, want.extra)
    np.testing.assert_array_equal(r.smoother.guide.dense(), want.dense())


@fuzz(40)
@given(st.lists(st.integers(0, 300), unique=True), st.lists(st.integers(0, 300), unique=True), st.integers(1, 7))
def test_held_band_voxels_are_numpys_set_difference(a, b, chunk):
    """The band voxels a renderer is given fixed shares for (``held_index``: the band less the free voxels) are
    ``np.setdiff1d``'s, found a chunk at a time by binary search, for any pair of increasing indices."""
    from inkopt.optim.param import _sorted_difference

    a, b = (np.array(sorted(v), np.int64) for v in (a, b))
    want = np.setdiff1d(a, b, assume_unique=True)
    got = _sorted_difference(a, b, chunk)
    assert got.dtype == np.int64 and np.array_equal(got, want)
    assert len(_sorted_difference(a, a)) == 0  # a band that is the free voxels holds none


def test_a_band_runs_renderer_holds_no_band_voxel_fixed():
    """A band run whose free voxels are its band (one index array for both) gives its renderer no held voxels."""
    from inkopt.model import InkTable
    from inkopt.scenes import build_scene
    from inkopt.scenes.spec import MeshSpec

    scene = build_scene(MeshSpec(str(SPOT), height_mm=4.0, shell_mm=0.3), InkTable.parse("vero-cmykw"))
    r = run(scene, iterations=1)
    assert r.param.free_index is scene.volume.band.index
    assert len(r.param.held_index(scene.volume)) == 0
