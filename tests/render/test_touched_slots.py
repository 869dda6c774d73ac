"""The touched-slot encoding of a shard's fixed-point gradient sums (``distributed.TouchedSlots``): exact round trip,
shards adding up to the whole pass's sums in wrapping int64, and a size that follows the touched slots."""

import numpy as np
import pytest
from helpers import fuzz
from hypothesis import example, given
from hypothesis import strategies as st

from inkopt.distributed import TouchedSlots, payload_bytes

I64 = np.iinfo(np.int64)


@st.composite
def sums(draw):
    """Raw sums (F, 3) int64 x 2: each slot untouched, touched in some of its 6 sums, with magnitudes from 1 to the
    int64 extremes (so every narrow dtype and int64 itself are drawn)."""
    n = draw(st.integers(0, 300))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    share = draw(st.sampled_from([0.0, 0.003, 0.3, 0.97, 1.0]))
    bits = draw(st.sampled_from([7, 15, 31, 40, 63]))
    touched = rng.random(n) < share
    out = []
    for _ in range(2):
        v = rng.integers(-(2 ** (bits - 1)), 2 ** (bits - 1), size=(n, 3), dtype=np.int64, endpoint=True)
        v[~touched] = 0
        if draw(st.booleans()) and n:
            v.reshape(-1)[rng.integers(0, v.size)] = draw(st.sampled_from([I64.min, I64.max, -1, 1]))
        out.append(v)
    return out


@fuzz(200)
@given(sums())
@example([np.zeros((0, 3), np.int64)] * 2)  # an empty shard's gradient: no slots
@example([np.zeros((50, 3), np.int64)] * 2)  # a shard whose paths touched nothing
@example([np.full((40, 3), I64.max), np.full((40, 3), I64.min)])  # every slot touched, int64 extremes
def test_round_trip_is_exact(arrays):
    s, a = arrays
    t = TouchedSlots.of(s, a)
    back_s, back_a = t.dense()
    np.testing.assert_array_equal(back_s, s)
    np.testing.assert_array_equal(back_a, a)
    touched = np.flatnonzero((s != 0).any(1) | (a != 0).any(1))
    np.testing.assert_array_equal(t.indices(), touched)
    assert t.count == len(touched)
    # never larger than the indices as int64 plus the sums as int64, and a touched slot's bytes, not a free voxel's
    assert payload_bytes(t.where) <= 8 * max(len(touched) - 1, 0) or t.bitmap
    assert len(t.sums) <= 48 * len(touched) + 64  # zlib's stored blocks add a few bytes to incompressible data
    assert [c.dtype.str for c in t.columns()] == list(t.dtypes)


@fuzz(100)
@given(sums(), st.integers(1, 5), st.integers(0, 2**32 - 1))
def test_shards_add_up_wrapping(arrays, parts, seed):
    """A pass's sums split into ``parts`` shards (any integers, wrapping): adding each shard's encoding into zeros
    gives the wrapped int64 total, as adding the raw arrays does."""
    s, a = arrays
    rng = np.random.default_rng(seed)
    pieces = [(rng.integers(I64.min, I64.max, s.shape, np.int64), rng.integers(I64.min, I64.max, a.shape, np.int64))]
    pieces = [(s, a)] + [tuple(np.where(x != 0, p, 0) for x, p in zip((s, a), pc)) for pc in pieces * (parts - 1)]
    with np.errstate(over="ignore"):
        want_s, want_a = sum(p[0] for p in pieces), sum(p[1] for p in pieces)
    got_s, got_a = np.zeros_like(s), np.zeros_like(a)
    for p in pieces:
        TouchedSlots.of(*p).add_to(got_s, got_a)
    np.testing.assert_array_equal(got_s, want_s)
    np.testing.assert_array_equal(got_a, want_a)


def test_grid_shaped_sums_and_size():
    """Sums shaped (z, y, x, 3) (a renderer without a gradient index) round-trip; a compact run of touched slots
    with 21-bit sums costs a bitmap bit and at most 6 x 4 bytes per touched slot, not 48 bytes per slot."""
    s = np.zeros((4, 50, 60, 3), np.int64)
    a = np.zeros_like(s)
    rng = np.random.default_rng(0)
    s[1:3, 10:40] = rng.integers(-(2**20), 2**20, (2, 30, 60, 3))
    a[1:3, 10:40] = rng.integers(-(2**20), 2**20, (2, 30, 60, 3))
    t = TouchedSlots.of(s, a)
    assert t.shape == s.shape and t.bitmap
    np.testing.assert_array_equal(t.dense()[0], s)
    np.testing.assert_array_equal(t.dense()[1], a)
    touched = 2 * 30 * 60
    assert all(c.dtype == np.int32 for c in t.columns())
    assert payload_bytes(t) <= 24 * touched + (touched + 2 * 20 * 60) // 8 + 64
    assert payload_bytes(t) < 0.6 * 48 * s[..., 0].size / 2  # well under the raw arrays' bytes of this shard


@pytest.mark.parametrize("gap", [1, 200, 70_000])
def test_gaps_use_the_narrowest_dtype(gap):
    """Sparse touched slots are coded as gaps in the narrowest unsigned dtype that holds the largest gap."""
    s = np.zeros((gap * 5 + 1, 3), np.int64)
    s[::gap, 0] = 7
    t = TouchedSlots.of(s, np.zeros_like(s))
    if gap == 1:
        assert t.bitmap
    else:
        assert not t.bitmap and t.where.dtype == (np.uint8 if gap < 256 else np.uint32)
    np.testing.assert_array_equal(t.dense()[0], s)
