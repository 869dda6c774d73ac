"""Compact fixed ink shares (``model.FixedShares``) against the dense array they stand for."""
import hashlib

import numpy as np
import pytest

from inkopt.model import FixedShares, InkTable
from inkopt.optim import Parameterization
from inkopt.rundir import Translucency, white_fixed_share, white_fixed_shares

INKS = InkTable.parse("vero-cmykwt")


def _scene(rng):
    free = rng.random((4, 5, 6)) < 0.6
    tr_index = np.sort(rng.choice(free.size, 25, replace=False))
    tr = Translucency("transparent", free.shape, tr_index, rng.uniform(0.2, 1.0, 25).astype(np.float32))
    return free, tr


def test_compact_shares_are_the_dense_array():
    """Rows, layers, the dense form, its hash and the translucency constraint agree with the dense array."""
    rng = np.random.default_rng(3)
    free, tr = _scene(rng)
    want = tr.apply(white_fixed_share(free, INKS), INKS)
    fs = tr.applied(white_fixed_shares(free, INKS), INKS)
    assert fs.shape == want.shape and fs.free is free  # the mask is kept by reference
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
    again = tr.applied(fs, INKS)  # idempotent, as apply is
    np.testing.assert_array_equal(again.dense(), want)
    with pytest.raises(ValueError, match="strictly increasing"):
        FixedShares(free, fs.held, [3, 3], np.zeros((2, len(INKS))))


@pytest.mark.parametrize("kind", ["softmax", "sigmoid"])
def test_parameterisation_of_compact_shares_matches_the_dense_one(kind):
    """Free voxels, free shares, fixed rows and mixtures are bit-identical from either form; bad shares are
    refused in one line."""
    rng = np.random.default_rng(4)
    free, tr = _scene(rng)
    dense = Parameterization(kind, tr.apply(white_fixed_share(free, INKS), INKS))
    fs = tr.applied(white_fixed_shares(free, INKS), INKS)
    compact = Parameterization(kind, fs)
    np.testing.assert_array_equal(compact.free_index, dense.free_index)
    np.testing.assert_array_equal(compact.share_f, dense.share_f)
    np.testing.assert_array_equal(compact.fixed_f, dense.fixed_f)
    assert compact.shape == free.shape and compact.fixed_share is fs
    x = rng.normal(size=(compact.n_free, len(INKS))).astype(np.float32)
    np.testing.assert_array_equal(compact.mixture(x), dense.mixture(x))
    for p in (compact, dense):  # the result written in slabs of layers: the same, bit for bit
        np.testing.assert_array_equal(np.concatenate(list(p.mixture_slabs(x, voxels=37))), dense.mixture(x))
    plain = Parameterization(kind, white_fixed_shares(free, INKS))  # no constraint: every free voxel, no fixed rows
    assert plain.fixed_f is None and np.array_equal(plain.free_index, np.flatnonzero(free))
    with pytest.raises(ValueError, match="sum to at most 1"):
        Parameterization(kind, FixedShares(free, np.full(len(INKS), 0.5, np.float32)))
