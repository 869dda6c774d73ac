"""Fixed ink shares (``model.FixedShares``) against the dense array they stand for, and the constraints that
build them (``model.constraints``)."""

import hashlib

import numpy as np
import pytest

from inkopt.model import FixedShares, InkTable, Translucency, scene_fixed_shares, white_fixed_shares
from inkopt.optim import Parameterization

INKS = InkTable.parse("vero-cmykwt")
T, W = INKS.index("transparent"), INKS.index("white")


def _scene(rng):
    free = rng.random((4, 5, 6)) < 0.6
    tr_index = np.sort(rng.choice(free.size, 25, replace=False))
    tr = Translucency("transparent", free.shape, tr_index, rng.uniform(0.2, 1.0, 25).astype(np.float32))
    return free, tr


def _dense(free, tr):
    """The dense shares the constraints stand for, written out voxel by voxel."""
    want = np.zeros(free.shape + (len(INKS),), np.float32)
    want[~free, W] = 1.0
    for i, s in zip(tr.index, tr.share):
        row = want.reshape(-1, len(INKS))[i]
        row[W] = min(row[W], np.float32(1.0) - s)
        row[T] = s
    return want


def test_compact_shares_are_the_dense_array():
    """Rows, layers, the dense form, its hash and the translucency constraint agree with the dense array."""
    rng = np.random.default_rng(3)
    free, tr = _scene(rng)
    want = _dense(free, tr)
    fs = tr.applied(white_fixed_shares(free, INKS), INKS)
    assert fs.shape == want.shape and np.array_equal(fs.free, free)  # the mask, kept as bits
    np.testing.assert_array_equal(fs.dense(), want)
    np.testing.assert_array_equal(np.asarray(fs), want)
    ix = rng.permutation(free.size)[:50]
    np.testing.assert_array_equal(fs.at(ix), want.reshape(-1, len(INKS))[ix])
    for z in range(free.shape[0]):
        np.testing.assert_array_equal(fs.plane(z), want[z])
    h1, h2 = hashlib.sha256(), hashlib.sha256()
    fs.digest(h1)
    h2.update(want.data)
    assert h1.hexdigest() == h2.hexdigest()
    again = tr.applied(fs, INKS)  # idempotent
    np.testing.assert_array_equal(again.dense(), want)
    np.testing.assert_array_equal(scene_fixed_shares(INKS, free, tr).dense(), want)
    only_tr = scene_fixed_shares(INKS, None, tr).dense()  # no white core: the transparent shares alone
    np.testing.assert_array_equal(only_tr[..., T], tr.grid())
    assert scene_fixed_shares(INKS) is None
    with pytest.raises(ValueError, match="strictly increasing"):
        FixedShares(free, fs.held, [3, 3], np.zeros((2, len(INKS))))
    with pytest.raises(ValueError, match="no 'white'"):
        white_fixed_shares(free, InkTable.from_names(["cyan", "magenta"]))


def test_from_dense_round_trips():
    """Any dense array, also one whose fixed rows all differ, comes back bit for bit."""
    rng = np.random.default_rng(5)
    free, tr = _scene(rng)
    for dense in (
        _dense(free, tr),
        rng.uniform(0, 0.2, (3, 4, 5, len(INKS))).astype(np.float32),
        np.zeros((2, 3, 4, len(INKS)), np.float32),
    ):
        fs = FixedShares.from_dense(dense)
        np.testing.assert_array_equal(fs.dense(), dense)
        np.testing.assert_array_equal(fs.free, ~dense.any(-1))
    np.testing.assert_array_equal(FixedShares.none((2, 3, 4), 6).dense(), np.zeros((2, 3, 4, 6), np.float32))
    with pytest.raises(ValueError, match="shape"):
        FixedShares.from_dense(np.zeros((3, 4, 5)))


@pytest.mark.parametrize("kind", ["softmax", "sigmoid"])
def test_parameterisation_of_fixed_shares(kind):
    """Free voxels, free shares and fixed rows are those of the dense array; the mixture holds the fixed shares
    plus the free share of p(x), whole or in slabs of layers, bit for bit; bad shares are refused in one line."""
    rng = np.random.default_rng(4)
    free, tr = _scene(rng)
    dense = _dense(free, tr)
    fs = tr.applied(white_fixed_shares(free, INKS), INKS)
    p = Parameterization(kind, fs)
    flat = dense.reshape(-1, len(INKS))
    share = np.clip(1.0 - flat.sum(-1), 0.0, 1.0)
    np.testing.assert_array_equal(p.free_index, np.flatnonzero(share > 1e-6))
    np.testing.assert_array_equal(p.share_f, share[p.free_index])
    np.testing.assert_array_equal(p.fixed_f, flat[p.free_index])
    assert p.shape == free.shape and p.fixed_share is fs
    x = rng.normal(size=(p.n_free, len(INKS))).astype(np.float32)
    mix = p.mixture(x)
    np.testing.assert_array_equal(mix.reshape(-1, len(INKS))[p.free_index], p.free_rows(x))
    held = np.setdiff1d(np.arange(free.size), p.free_index)
    np.testing.assert_array_equal(mix.reshape(-1, len(INKS))[held], flat[held])
    np.testing.assert_array_equal(np.concatenate(list(p.mixture_slabs(x, voxels=37))), mix)
    same = Parameterization(kind, FixedShares.from_dense(dense))  # the same shares in another compact layout
    np.testing.assert_array_equal(same.mixture(x), mix)
    plain = Parameterization(kind, white_fixed_shares(free, INKS))  # no constraint: every free voxel, no fixed rows
    assert plain.fixed_f is None and np.array_equal(plain.free_index, np.flatnonzero(free))
    with pytest.raises(ValueError, match="sum to at most 1"):
        Parameterization(kind, FixedShares(free, np.full(len(INKS), 0.5, np.float32)))


def test_core_shares():
    """The named cores and explicit shares as (N,) rows over the ink set (renormalised within 1e-3), and their
    one-line errors naming `core`."""
    from inkopt.errors import ParameterError
    from inkopt.model.fixed import START_WHITE, core_shares

    np.testing.assert_array_equal(core_shares("white", INKS), np.eye(len(INKS), dtype=np.float32)[W])
    start = core_shares("start", INKS)
    assert start[W] == np.float32(START_WHITE) and abs(start.sum() - 1) < 1e-6
    np.testing.assert_allclose(np.delete(start, W), (1 - START_WHITE) / (len(INKS) - 1), rtol=1e-6)
    row = core_shares("white = 0.7, black=0.3004", INKS)
    assert row.dtype == np.float32 and abs(row.sum() - 1) < 1e-6 and row[INKS.index("black")] > 0.3
    assert np.count_nonzero(row) == 2
    for bad in ("grey", "white=0.5,white=0.5", "cyan", "white=x", "white=0.5,black=0.4", "white=1,nope=0"):
        with pytest.raises(ParameterError, match="core") as err:
            core_shares(bad, INKS)
        assert err.value.parameters == ("core",) and "\n" not in str(err.value)


def test_a_core_mixture_is_what_scene_records_rebuild():
    """A scene record without the dense fixed shares rebuilds them from the free mask and the core's row."""
    from inkopt.model.fixed import core_shares

    free = np.random.default_rng(3).random((4, 5, 6)) < 0.5
    core = core_shares("start", INKS)
    fixed = scene_fixed_shares(INKS, free, None, core)
    np.testing.assert_array_equal(fixed.dense()[~free], np.broadcast_to(core, (int((~free).sum()), len(INKS))))
    assert not fixed.dense()[free].any()
    np.testing.assert_array_equal(scene_fixed_shares(INKS, free).dense(), white_fixed_shares(free, INKS).dense())


@pytest.mark.parametrize("step", [8, 16, 1 << 24])  # slabs smaller than the mask, and one slab
def test_packed_mask_reads_back_the_mask(monkeypatch, step):
    from inkopt.model.fixed import PackedMask

    monkeypatch.setattr(PackedMask, "STEP", step)
    rng = np.random.default_rng(3)
    mask = rng.random((3, 5, 7)) < 0.4  # 105 voxels: not a multiple of 8
    pm = PackedMask(mask)
    assert pm.shape == mask.shape and pm.size == mask.size and pm.count == int(mask.sum())
    assert pm.bits.nbytes == 14 and not pm.all() and PackedMask(np.ones((2, 3, 5), bool)).all()
    np.testing.assert_array_equal(pm.dense(), mask)
    np.testing.assert_array_equal(pm.nonzero(), np.flatnonzero(mask))
    idx = rng.integers(0, mask.size, 50)
    np.testing.assert_array_equal(pm.at(idx), mask.reshape(-1)[idx])
    np.testing.assert_array_equal(pm.range(96, 200), mask.reshape(-1)[96:])
