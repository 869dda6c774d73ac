"""Tests of quantize_mix(method="error-diffusion"): 3D vector error diffusion on the printer grid (Rust core in
crates/core/src/kernels/diffuse.rs, which has its own unit tests)."""

import hashlib
import os
import subprocess
import sys

import numpy as np
import pytest
from numpy.lib.stride_tricks import sliding_window_view
from printing.test_quantize import V300, lowpass_error, quantize_mix, smooth_mixture

from inkopt import _core

ED = "error-diffusion"
ISO = dict(dpi=(300, 300, 300))  # printer grid = optimisation grid (V300 voxels): windows in known voxels
# The documented filter (diffuse.rs), 128ths: (dx along the sweep, dy, w) in the layer; (dx, dy, w) one layer down.
IN_LAYER = [(1, 0, 49), (-1, 1, 21), (0, 1, 35), (1, 1, 7)]
NEXT_LAYER = [(0, 0, 8), (-1, 0, 2), (1, 0, 2), (0, -1, 2), (0, 1, 2)]


def crossing_weight(k: int, z0: int, y0: int, x0: int) -> float:
    """Total filter weight of the links u -> v with exactly one end in the k^3 window at (z0, y0, x0), for a
    window whose neighbourhood lies inside the grid (no renormalisation). Rows sweep +x when y + z is even."""

    def inside(z, y, x):
        return z0 <= z < z0 + k and y0 <= y < y0 + k and x0 <= x < x0 + k

    tot = 0.0
    for z, y, x in np.ndindex(k + 2, k + 2, k + 2):
        z, y, x = z + z0 - 1, y + y0 - 1, x + x0 - 1
        d = 1 if (y + z) % 2 == 0 else -1
        links = [(z, y + dy, x + dx * d, w) for dx, dy, w in IN_LAYER]
        links += [(z + 1, y + dy, x + dx, w) for dx, dy, w in NEXT_LAYER]
        tot += sum(w for zz, yy, xx, w in links if inside(z, y, x) != inside(zz, yy, xx)) / 128
    return tot


def window_deviation(lab, p0: float, k: int, margin: int = 2) -> np.ndarray:
    """|count of ink 0 - k^3 p0| over every k^3 window at least ``margin`` voxels from the grid's faces."""
    c = sliding_window_view((lab == 0).astype(float), (k, k, k)).sum((-1, -2, -3))
    n = lab.shape
    c = c[margin : n[0] - k - margin + 1, margin : n[1] - k - margin + 1, margin : n[2] - k - margin + 1]
    return np.abs(c - k**3 * p0)


@pytest.mark.parametrize("p0", [0.3, 0.137])
def test_window_counts_sure_bound_and_spread(p0):
    """Let r_u = u_u - onehot_u be the residual of voxel u and w(u -> v) the filter. Since q = m + e - r with
    e_v = sum_u w(u -> v) r_u, the ink count of a window B differs from its summed mixture by
    sum_B (q - m) = sum_{u not in B} r_u w(u -> B) - sum_{u in B} r_u (1 - w(u -> B)): only residuals that cross
    B's boundary count (weights are >= 0 and sum to 1, so error is conserved). With two inks every residual is in
    [-1/2, 1/2] (u_0 in [-1/2, 3/2] by induction, and the nearer of 0 and 1 is within 1/2), so
    |count - k^3 p| <= W_cross / 2, W_cross = the filter weight crossing B's faces, ~1.2 k^2 (4.6, 10.7, 19.4, 44.4
    for k = 2, 3, 4, 6): a sure bound for every window, O(k^2). Random draws have no bound at all. The sure bound
    is loose; measured, the spread of the counts is ~0.35-0.65x that of random draws (binomial, sqrt(k^3 p q))
    and shrinks relative to it as k grows."""
    n = 20
    p = np.array([p0, 1 - p0], np.float32)
    mix = np.broadcast_to(p, (n, n, n, 2))
    lab, _ = quantize_mix(mix, (V300,) * 3, method=ED, **ISO)
    lab_r, _ = quantize_mix(mix, (V300,) * 3, method="random", seed=0, **ISO)
    assert lab.shape == (n, n, n)
    for k in (2, 3, 4, 6):
        bound = 0.5 * min(crossing_weight(k, 4, 4, 4), crossing_weight(k, 4, 5, 4))  # both sweep parities
        assert 1.0 * k * k < bound < 1.4 * k * k
        dev, dev_r = window_deviation(lab, p0, k), window_deviation(lab_r, p0, k)
        assert dev.max() <= bound + 1e-3, (k, dev.max(), bound)
        rms, rms_r = np.sqrt(np.mean(dev**2)), np.sqrt(np.mean(dev_r**2))
        assert rms < (0.7 if k < 4 else 0.5) * rms_r, (k, rms, rms_r)
        assert dev.max() < dev_r.max(), (k, dev.max(), dev_r.max())
    # the total over the whole box: only the very last voxel's residual is dropped
    assert abs(np.count_nonzero(lab == 0) - p0 * lab.size) <= 0.5 + 1e-2


def test_four_inks_beat_random_and_blue_noise_low_pass():
    """Multi-ink fields: per-voxel fractions and the 0.1 mm low-pass error (what scattering sees, as
    test_blue_noise_beats_random) are below blue noise's (measured 0.0033 vs 0.0048, 0.133 vs 0.139) and far
    below random draws' (0.0199)."""
    shape, n = (12, 40, 40), 4
    mix = smooth_mixture(shape, n)
    vo = (V300,) * 3
    err = {}
    for method in ("random", "blue-noise", ED):
        lab, vp = quantize_mix(mix, vo, method=method, seed=0)
        err[method] = lowpass_error(lab, mix, vo, vp)
    assert err[ED] < 0.8 * err["blue-noise"] < 0.3 * err["random"], err


def labels_hash(mix, **kw) -> str:
    return hashlib.sha256(quantize_mix(mix, (V300,) * 3, method=ED, **kw)[0].tobytes()).hexdigest()


def test_deterministic_seed_free_and_thread_independent():
    mix = np.random.default_rng(2).dirichlet(np.ones(4), size=(6, 9, 10)).astype(np.float32)
    a = labels_hash(mix, seed=1)
    assert a == labels_hash(mix, seed=1) == labels_hash(mix, seed=99)
    code = (
        "import sys, numpy as np; sys.path[:0] = sys.argv[1:]; from printing.test_diffuse import labels_hash; "
        "print(labels_hash(np.random.default_rng(2).dirichlet(np.ones(4), size=(6, 9, 10)).astype(np.float32)))"
    )
    env = {**os.environ, "RAYON_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    got = subprocess.run(
        [sys.executable, "-c", code, os.path.dirname(os.path.dirname(__file__))],
        env=env,
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    assert got == a


@pytest.mark.parametrize("upsample", ["nearest", "linear"])
def test_outside_is_empty_and_isolated(upsample):
    """Two blocks separated by a one-voxel gap of outside voxels: each block's labels do not depend on the other
    block (outside voxels neither take nor pass error), and outside voxels are EMPTY whatever their mixture."""
    rng = np.random.default_rng(3)
    shape = (6, 8, 11)
    mix = rng.dirichlet(np.ones(3), size=shape).astype(np.float32)
    inside = np.ones(shape, bool)
    inside[:, :, 5] = False
    a, vp = quantize_mix(mix, (V300,) * 3, method=ED, inside=inside, upsample=upsample, **ISO)
    assert np.all(a[:, :, 5] == 255) and np.all(a[:, :, :5] != 255) and np.all(a[:, :, 6:] != 255)
    mix2 = mix.copy()
    mix2[:, :, 6:] = rng.dirichlet(np.ones(3), size=(6, 8, 5))  # other right block, other outside rows
    mix2[:, :, 5] = [1.0, 0.0, 0.0]
    b, _ = quantize_mix(mix2, (V300,) * 3, method=ED, inside=inside, upsample=upsample, **ISO)
    if upsample == "nearest":  # linear upsampling blends the right block into the gap's neighbours: skip them
        np.testing.assert_array_equal(a[:, :, :5], b[:, :, :5])
    inside3 = inside.copy()
    inside3[:, :, 6:] = False
    c, _ = quantize_mix(mix, (V300,) * 3, method=ED, inside=inside3, upsample=upsample, **ISO)
    np.testing.assert_array_equal(a[:, :, :5], c[:, :, :5])
    assert np.all(c[:, :, 5:] == 255)


@pytest.mark.parametrize("upsample", ["nearest", "linear"])
def test_one_ink_everywhere(upsample):
    mix = np.zeros((4, 5, 6, 4), np.float32)
    mix[..., 2] = 1.0
    lab, _ = quantize_mix(mix, (V300,) * 3, method=ED, upsample=upsample)
    assert np.all(lab == 2)


def test_linear_upsampling_follows_the_ramp():
    """Ink-0 weight ramps along x; with linear upsampling the ink-0 fraction of each optimisation voxel's pair of
    printer columns (Z * Y * 2 = 2400 voxels) follows the interpolated mixture: measured within 0.035 (error
    diffusion trails a ramp by about a printer column along its sweep, so single columns are off by up to 0.1),
    and the whole slab's fraction within 1e-3."""
    nx = 8
    ramp = np.linspace(0.0, 1.0, nx)
    mix = np.zeros((20, 20, nx, 2), np.float32)
    mix[..., 0], mix[..., 1] = ramp, 1 - ramp
    lab, vp = quantize_mix(mix, (V300,) * 3, method=ED, upsample="linear")
    frac0 = (lab == 0).mean(axis=(0, 1))
    xc = np.clip((np.arange(lab.shape[2]) + 0.5) * vp[0] / V300 - 0.5, 0, nx - 1)
    expect = np.interp(xc, np.arange(nx), ramp)
    assert np.abs(frac0.reshape(-1, 2).mean(1) - expect.reshape(-1, 2).mean(1)).max() < 0.05
    assert abs(frac0.mean() - expect.mean()) < 1e-3


def test_speed():
    """The reference slab's printer grid (94 x 118 x 354 = 3.9 M voxels, 5 inks): measured ~0.3 s; generous
    bound for a shared machine."""
    import time

    mix = np.random.default_rng(6).dirichlet(np.ones(5), size=(30, 118, 177)).astype(np.float32)
    t = time.perf_counter()
    lab, _ = quantize_mix(mix, (V300,) * 3, method=ED)
    assert lab.shape == (94, 118, 354)
    assert time.perf_counter() - t < 15.0


def test_binding_checks_shapes():
    mix = np.full((2, 3, 4), 0.5, np.float32)
    ins = np.ones((3, 4), np.uint8)
    err = np.zeros((2, 3, 4, 2), np.float32)
    out = np.zeros((3, 4), np.uint8)
    _core.diffuse_layer(mix, ins, ins, err, 0, out)
    assert set(np.unique(out).tolist()) <= {0, 1}
    with pytest.raises(ValueError, match="error"):
        _core.diffuse_layer(mix, ins, ins, np.zeros((2, 3, 4, 3), np.float32), 0, out)
    with pytest.raises(ValueError, match="inside"):
        _core.diffuse_layer(mix, np.ones((4, 3), np.uint8), ins, err, 0, out)
    with pytest.raises(ValueError, match="contiguous"):
        _core.diffuse_layer(mix, ins, ins, np.asfortranarray(err), 0, out)
