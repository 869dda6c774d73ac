"""Tests of the counts' dither (``printing.counts.CountDiffusion``): each optimisation voxel's whole ink counts by
vector error diffusion between optimisation voxels (``inkopt_core::kernels::counts``), placed by blue noise."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from inkopt.errors import ParameterError
from inkopt.model import EMPTY, InkTable, Quantization
from inkopt.printing.counts import DITHER_CLASS, AdaptiveCounts, CountDiffusion
from inkopt.printing.dithers import DITHERS, band_order
from inkopt.printing.grid import Nearest, PrinterGrid
from inkopt.printing.layers import CumulativeLayers
from inkopt.printing.quantize import MixtureLayers, check_quantization, ink_fractions, quantize

V300 = 25.4 / 300
VO = (V300, V300, 0.108)  # 2 x 1 x 4 printer voxels per optimisation voxel: blocks of 8
GREY = np.array([0.05, 0.1, 0.1, 0.15, 0.6], np.float32)


def sharp_mixture(shape=(8, 14, 12), n=4, seed=0, inside=False):
    """A mixture that changes sharply from voxel to voxel (Dirichlet(0.3) rows), optionally with a random inside
    mask (rows zero outside)."""
    rng = np.random.default_rng(seed)
    mix = rng.dirichlet(np.full(n, 0.3), size=shape).astype(np.float32)
    mask = rng.random(shape) < 0.75 if inside else None
    if mask is not None:
        mix[~mask] = 0.0
    return mix, mask


def run(mix, inside=None, seed=0, vo=VO):
    """The counts' dither driven as ``quantize`` drives it (index order): labels (Z, Y, X), the grid and the dither
    (its ``max_residual``)."""
    q = Quantization("count-diffusion", seed, ink_order="index")
    src = MixtureLayers(mix, vo, inside, None)
    grid = PrinterGrid.of(src.shape[:3], src.voxel_mm, q, inside=src.inside)
    dither = CountDiffusion(q, grid, src.shape[3], None)
    layers = CumulativeLayers(src, Nearest(grid), None)
    labels = np.stack([dither.layer(k, *layers.printer_layer(k)) for k in range(grid.shape[0])])
    return labels, grid, dither


def counts_and_targets(labels, grid, mix):
    """Per optimisation voxel: the ink counts (z, y, x, N) from the labels, the block sizes (z, y, x) and the
    targets block x share (z, y, x, N)."""
    frac, tot = ink_fractions(labels, mix.shape[3], mix.shape[:3], grid.source_voxel_mm, grid.voxel_mm)
    rows = mix / np.maximum(mix.sum(-1, keepdims=True), 1e-30)
    return np.rint(frac * tot[..., None]), tot, rows * tot[..., None]


def test_registered_ordered_and_nearest_only():
    assert DITHERS["count-diffusion"] is CountDiffusion and CountDiffusion.ordered and CountDiffusion.nearest_only
    inks = InkTable.parse("vero-cmykw")
    q = Quantization("count-diffusion")
    np.testing.assert_array_equal(band_order(q, inks, 0.4, 1.5), band_order(Quantization(), inks, 0.4, 1.5))
    with pytest.raises(ParameterError, match="nearest"):
        check_quantization(Quantization("count-diffusion", upsample="linear"))


def test_blocks_sum_to_their_inside_voxels_and_outside_is_empty():
    mix, inside = sharp_mixture(inside=True)
    labels, grid, _ = run(mix, inside)
    expect, _ = quantize(MixtureLayers(mix, VO, inside, None), Quantization("count-diffusion", 0, ink_order="index"))
    np.testing.assert_array_equal(labels, expect)  # ``run`` is what ``quantize`` does
    counts, tot, _ = counts_and_targets(labels, grid, mix)
    iz, iy, ix = grid.enclosing
    block = np.bincount(iz, minlength=8)[:, None, None] * np.outer(np.bincount(iy), np.bincount(ix))[None]
    np.testing.assert_array_equal(tot, np.where(inside, block, 0))
    np.testing.assert_array_equal(counts.sum(-1), tot)
    np.testing.assert_array_equal(labels == EMPTY, ~inside[iz][:, iy][:, :, ix])


def test_layer_counts_within_one_residual_without_carrying_down(monkeypatch):
    """With nothing carried down (``down`` 0) every optimisation layer is a 2D diffusion of its own: error is conserved
    in it except the last visited voxel's residual, so each layer's count of each ink is within ``max_residual`` of its
    summed targets, and the layer's first y rows within ``max_residual`` x (voxels of row y1 - 1 passing on)."""
    monkeypatch.setattr(CountDiffusion, "down", 0.0)
    mix, _ = sharp_mixture()
    labels, grid, d = run(mix)
    counts, _, target = counts_and_targets(labels, grid, mix)
    rho = d.max_residual
    assert 0.4 < rho < 1.5, rho
    gap = np.abs(counts.sum((1, 2)) - target.sum((1, 2)))  # (z, N)
    assert gap.max() <= rho + 1e-9, (gap.max(), rho)
    for y1 in (3, 7):
        gap = np.abs(counts[:, :y1].sum((1, 2)) - target[:, :y1].sum((1, 2)))
        assert gap.max() <= rho * mix.shape[2] + 1e-9


def test_windows_within_the_residuals_crossing_them():
    """With the default fraction ``down`` carried to the next layer, the first z1 whole layers lose only what layer
    z1 - 1 passes down: at most ``down`` x ``max_residual`` from each voxel whose neighbours all exist, at most
    ``max_residual`` from each on the layer's border (weights renormalised there). And on 2 x 2 x 2 windows the
    counts' error is far below blue noise's, which rounds each block on its own."""
    mix, _ = sharp_mixture()
    labels, grid, d = run(mix)
    counts, _, target = counts_and_targets(labels, grid, mix)
    rho, (nz, ny, nx) = d.max_residual, mix.shape[:3]
    border = ny * nx - (ny - 2) * (nx - 2)
    for z1 in range(1, nz):
        gap = np.abs(counts[:z1].sum((0, 1, 2)) - target[:z1].sum((0, 1, 2)))
        assert gap.max() <= rho * (CountDiffusion.down * (ny * nx - border) + border) + 1e-9
    blue, vp = quantize(MixtureLayers(mix, VO, None, None), Quantization("blue-noise", 0, ink_order="index"))
    frac, tot = ink_fractions(blue, mix.shape[3], mix.shape[:3], VO, vp)

    def window_rms(c):
        e = (c - target).reshape(nz // 2, 2, ny // 2, 2, nx // 2, 2, -1).sum((1, 3, 5))
        return np.sqrt(np.mean(e**2))

    ours, theirs = window_rms(counts), window_rms(frac * tot[..., None])
    assert ours < 0.5 * theirs, (ours, theirs)


def grey_error(method: str, seed: int = 0) -> float:
    """RMS of each ink's share low-passed by a 0.1 mm Gaussian minus the constant grey, on 24 x 64 x 32 voxels."""
    mix = np.broadcast_to(GREY, (24, 64, 32, 5))
    lab, vp = quantize(MixtureLayers(mix, VO, None, None), Quantization(method, seed, ink_order="index"))
    sigma = 0.1 / vp[::-1]
    err = [gaussian_filter((lab == k).astype(np.float64), sigma, mode="wrap") - GREY[k] for k in range(5)]
    return float(np.sqrt(np.mean(np.square(err))))


def test_constant_mixture_keeps_blue_noise_statistics():
    """On a constant grey the placement is blue noise's ranks within each block, but which blocks get the extra voxel
    of an ink is the diffusion's choice at the optimisation voxels' scale, not the 3D array's: the low-passed error
    is of blue noise's order (measured 0.0041 against blue noise's 0.0024) and far below random draws' (0.016)."""
    ours, blue, white = grey_error("count-diffusion"), grey_error("blue-noise"), grey_error("random")
    assert ours < 2.0 * blue and ours < 0.35 * white, (ours, blue, white)


def test_seed_moves_the_pattern_and_repeats():
    mix, inside = sharp_mixture(inside=True)
    a, _, _ = run(mix, inside, seed=7)
    b, _, _ = run(mix, inside, seed=7)
    c, _, _ = run(mix, inside, seed=8)
    np.testing.assert_array_equal(a, b)
    assert np.mean(a != c) > 0.1


def window_error(labels, vp, mix, inside=None):
    """RMS over 2 x 2 x 2 windows of optimisation voxels of the ink counts minus block x share."""
    frac, tot = ink_fractions(labels, mix.shape[3], mix.shape[:3], VO, vp)
    rows = mix / np.maximum(mix.sum(-1, keepdims=True), 1e-30)
    e = (frac - rows) * tot[..., None]
    nz, ny, nx = (s // 2 * 2 for s in mix.shape[:3])
    e = e[:nz, :ny, :nx].reshape(nz // 2, 2, ny // 2, 2, nx // 2, 2, -1).sum((1, 3, 5))
    return float(np.sqrt(np.mean(e**2)))


def test_adaptive_is_blue_noise_where_smooth_and_counts_where_sharp():
    """``count-adaptive``: on a mixture half constant grey, half changing sharply from voxel to voxel, the smooth
    half's printer voxels are blue noise's (but along the seam, where a voxel's neighbours differ), and the sharp
    half keeps its 2 x 2 x 2 windows' counts as the counts' dither does, far closer than blue noise."""
    assert DITHERS["count-adaptive"] is AdaptiveCounts and AdaptiveCounts.nearest_only
    sharp, _ = sharp_mixture(shape=(8, 14, 24), n=5)
    mix = sharp.copy()
    mix[:, :, :12] = GREY
    q = {m: Quantization(m, 3, ink_order="index") for m in ("blue-noise", "count-diffusion", "count-adaptive")}
    out = {m: quantize(MixtureLayers(mix, VO, None, None), qm) for m, qm in q.items()}
    (ours, vp), (blue, _) = out["count-adaptive"], out["blue-noise"]
    ix = PrinterGrid.of(mix.shape[:3], VO, q["blue-noise"]).enclosing[2]
    seam, start = np.searchsorted(ix, 11), np.searchsorted(ix, 12)  # x = 11 has a sharp neighbour
    np.testing.assert_array_equal(ours[..., :seam], blue[..., :seam])
    assert np.mean(ours[..., start:] != blue[..., start:]) > 0.05
    errs = {m: window_error(out[m][0][..., start:], vp, mix[:, :, 12:]) for m in out}
    assert errs["count-adaptive"] < 0.5 * errs["blue-noise"], errs
    assert errs["count-adaptive"] < 1.5 * errs["count-diffusion"], errs


def test_adaptive_shares_blue_noise_compensation():
    """The compensation's flat patches are constant mixtures, where count-adaptive is blue noise: the two share one
    measured (and shipped) compensation."""
    from inkopt.printing.compensate import compensation_key

    inks = InkTable.parse("vero-cmykw")
    key = compensation_key(inks, Quantization("count-adaptive"), 0.4, 1.5)
    assert key == compensation_key(inks, Quantization("blue-noise"), 0.4, 1.5)
    assert key != compensation_key(inks, Quantization("count-diffusion"), 0.4, 1.5)


def _smooth_reference(share, inside, below, below_inside, smooth):
    """The smooth voxels by whole-plane numpy arithmetic: each inside voxel's RMS share distance to its inside
    neighbours (4 in the layer, 1 below) below ``smooth``."""
    ny, nx = inside.shape
    sq, cnt = np.zeros(inside.shape), np.zeros(inside.shape)
    for dy, dx in ((1, 0), (0, 1)):
        a, b = np.s_[: ny - dy, : nx - dx], np.s_[dy:, dx:]
        both = inside[a] & inside[b]
        d = np.where(both, np.sum((share[:, a[0], a[1]] - share[:, b[0], b[1]]) ** 2, axis=0), 0.0)
        sq[a] += d
        sq[b] += d
        cnt[a] += both
        cnt[b] += both
    if below is not None:
        both = inside & below_inside
        sq += np.where(both, np.sum((share - below) ** 2, axis=0), 0.0)
        cnt += both
    return inside & (np.sqrt(sq / np.maximum(cnt, 1)) < smooth)


def test_smooth_voxels_are_the_whole_plane_arithmetic_bit_for_bit():
    """``_core.mark_smooth`` marks exactly the voxels numpy's whole-plane arithmetic finds smooth, also at
    distances near the threshold, with and without a layer below, and leaves the other classes as they were."""
    from inkopt import _core

    rng = np.random.default_rng(3)
    for trial in range(6):
        n, ny, nx = (4, 8)[trial % 2], 23, 31  # numpy sums a C-contiguous share's (N, y, x) planes in turn
        patches = rng.integers(0, 64, (n, 3, 4))  # 8 x 8 patches of one mixture, some voxels moved by 1/64 steps
        raw = np.repeat(np.repeat(patches, 8, 1), 8, 2)[:, :ny, :nx]
        raw = raw + (rng.random((n, ny, nx)) < 0.1) * rng.integers(-2, 3, (n, ny, nx))
        share = np.maximum(raw, 0) / np.maximum(np.maximum(raw, 0).sum(0), 1)
        inside = rng.random((ny, nx)) < 0.8
        classes = np.where(inside, rng.integers(1, 4, (ny, nx)), 0).astype(np.uint8)
        below = rng.permutation(share.reshape(n, -1).T).T.reshape(share.shape) if trial > 2 else None
        below_inside = (rng.random((ny, nx)) < 0.7) if trial > 2 else None
        smooth = [0.05, 1 / 64, 0.2][trial % 3]
        want = _smooth_reference(share, inside, below, below_inside, smooth)
        got = classes.copy()
        extra = (
            {}
            if below is None
            else {"below": np.ascontiguousarray(below), "below_inside": below_inside.astype(np.uint8)}
        )
        _core.mark_smooth(np.ascontiguousarray(share), got, smooth, **extra)
        np.testing.assert_array_equal(got == DITHER_CLASS, want)
        np.testing.assert_array_equal(got[~want], classes[~want])
        assert 0 < want.sum() < inside.sum()  # both kinds of voxel present
