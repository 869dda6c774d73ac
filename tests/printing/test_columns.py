"""Tests of the columns' dither (``printing.thresholds.BlueNoiseColumns``): golden-ratio shifts of a shipped 2D
blue-noise mask along depth."""

import numpy as np
from scipy.ndimage import gaussian_filter

from inkopt.model import InkTable, Quantization, Volume
from inkopt.printing.dither import COLUMN_MASK_SHAPE, GOLDEN, blue_noise_path, load_blue_noise, void_and_cluster
from inkopt.printing.dithers import DITHERS, band_order
from inkopt.printing.grid import PrinterGrid
from inkopt.printing.quantize import MixtureLayers, quantize, quantize_volume
from inkopt.printing.thresholds import BlueNoiseColumns

V300 = 25.4 / 300
#: shares of cyan, magenta, yellow, black, white: a grey with every ink present
GREY = np.array([0.05, 0.1, 0.1, 0.15, 0.6], np.float32)


def quantize_grey(method: str, shape=(24, 64, 32), seed: int = 0, ink_order: str = "index"):
    """Labels (Z, Y, X) of the constant mixture ``GREY`` on ``shape`` (z, y, x) optimisation voxels of 85 x 85 x 108
    µm (a printer grid of 4 layers, 1 row and 2 columns per voxel), and the printer voxel size (x, y, z) mm."""
    mix = np.broadcast_to(GREY, tuple(shape) + (5,))
    inks = InkTable.parse("vero-cmykw")
    return quantize(
        MixtureLayers(mix, (V300, V300, 0.108), None, inks), Quantization(method, seed, ink_order=ink_order)
    )


def column_count_error(lab: np.ndarray, depth: int) -> np.ndarray:
    """Per ink, column and start layer: the count of the ink over ``depth`` consecutive layers minus depth x its
    share; float64 (5, Z - depth, Y, X)."""
    one_hot = np.stack([(lab == k) for k in range(5)]).astype(np.float64)
    cum = np.cumsum(one_hot, axis=1)
    return cum[:, depth:] - cum[:, :-depth] - depth * GREY[:, None, None, None]


def test_registered_and_ordered():
    assert DITHERS["blue-noise-columns"] is BlueNoiseColumns and BlueNoiseColumns.ordered
    inks = InkTable.parse("vero-cmykw")
    for name in ("lightness", "tint-first"):
        q = Quantization("blue-noise-columns", ink_order=name)
        np.testing.assert_array_equal(
            band_order(q, inks, 0.4, 1.5), band_order(Quantization(ink_order=name), inks, 0.4, 1.5)
        )
    vol = Volume.from_mixture((V300,) * 3, np.broadcast_to(GREY, (2, 3, 4, 5)).copy(), inks)
    assert quantize_volume(vol, Quantization("blue-noise-columns")).quantization.ink_order == "lightness"


def test_thresholds_are_golden_ratio_shifts_of_the_mask():
    """Layer k's thresholds are the mask, tiled at a toroidal offset, plus (k + oz) x GOLDEN, modulo 1, in [0, 1)."""
    grid = PrinterGrid.of((3, 40, 40), (V300, V300, V300), Quantization())
    d = BlueNoiseColumns(Quantization("blue-noise-columns", seed=5), grid, 5, None)
    mask = load_blue_noise(COLUMN_MASK_SHAPE)
    _, Y, X = grid.shape
    assert (Y, X) == (40, 80)
    oy, ox = (int(v[0]) for v in np.nonzero(mask == d.mask[0, 0]))
    np.testing.assert_array_equal(d.mask, np.roll(mask, (-oy, -ox), (0, 1))[np.arange(Y) % 64][:, np.arange(X) % 64])
    for k in (0, 1, 7, 1000):
        t = d.thresholds(k)
        assert t.dtype == np.float32 and t.shape == (Y, X) and t.min() >= 0.0 and t.max() < 1.0
        expect = np.mod(d.mask.astype(np.float64) + (k + d.oz) * GOLDEN, 1.0)
        gap = np.abs(t - expect)
        np.testing.assert_allclose(np.minimum(gap, 1 - gap), 0, atol=2e-7)


def test_seed_moves_the_pattern_and_repeats():
    a, _ = quantize_grey("blue-noise-columns", seed=7)
    b, _ = quantize_grey("blue-noise-columns", seed=7)
    c, _ = quantize_grey("blue-noise-columns", seed=8)
    np.testing.assert_array_equal(a, b)
    assert np.mean(a != c) > 0.1


def test_every_column_is_even_in_depth():
    """Along a column the thresholds are a Kronecker sequence of step GOLDEN: every ink's count over any 3 to 12
    consecutive layers is within 2 of its share's (measured at most 1.6; the 3D blue-noise array's columns reach
    6.2 over 12 layers, asserted > 3), and each layer holds the whole mask's thresholds, so on whole tiles each
    ink's fraction is exact to 2 / 4096 per layer."""
    lab, vp = quantize_grey("blue-noise-columns")
    assert lab.shape == (96, 64, 64)
    for depth in (3, 6, 12):
        assert np.abs(column_count_error(lab, depth)).max() < 2.0, depth
    per_layer = np.stack([np.bincount(layer.ravel(), minlength=5) / layer.size for layer in lab])
    assert np.abs(per_layer - GREY).max() <= 2 / 4096
    lab3d, _ = quantize_grey("blue-noise")
    assert np.abs(column_count_error(lab3d, 12)).max() > 3.0


def test_depth_weighted_sums_closer_than_the_3d_array():
    """What a texel sees, roughly: each ink's share low-passed laterally (0.04 mm Gaussian) and summed over depth
    with weights exp(-z / 0.08 mm). Its RMS error against the mixture is measured 0.0370 for the columns against
    0.0435 for the 3D blue-noise array and 0.0647 for random draws; asserted < 0.93x the 3D array's."""
    rms = {}
    for method in ("blue-noise-columns", "blue-noise"):
        lab, vp = quantize_grey(method)
        one_hot = np.stack([(lab == k) for k in range(5)]).astype(np.float64)
        lateral = gaussian_filter(one_hot, (0, 0, 0.04 / vp[1], 0.04 / vp[0]), mode="wrap")
        w = np.exp(-(np.arange(15) + 0.5) * vp[2] / 0.08)
        w /= w.sum()
        sums = np.stack([np.tensordot(w, lateral[:, s : s + 15], axes=([0], [1])) for s in range(lab.shape[0] - 15)])
        rms[method] = np.sqrt(np.mean((sums - GREY[None, :, None, None]) ** 2))
    assert rms["blue-noise-columns"] < 0.93 * rms["blue-noise"], rms


def spectrum_ratio(pattern, fmax=0.15):
    """Mean power at 0 < |f| <= fmax (cycles/voxel) relative to white noise of the same density."""
    p = pattern.mean()
    power = np.abs(np.fft.fftn(pattern - p)) ** 2 / (pattern.size * p * (1 - p))
    f = np.sqrt(sum(np.meshgrid(*[np.fft.fftfreq(s) ** 2 for s in pattern.shape], indexing="ij")))
    return power[(f > 0) & (f <= fmax)].mean()


def test_shipped_mask_is_blue_and_regenerates():
    """The shipped 64 x 64 mask is void_and_cluster's (deterministic). A layer's ink takes a band of its ranks:
    prefixes and suffixes are blue (low-frequency power measured 0.02-0.08 of white noise's), other bands less so
    (0.06-0.13), and all far bluer in the layer's plane than a layer of the 3D array (0.37-0.60), whose blue noise is
    spread over three dimensions."""
    ranks = np.load(blue_noise_path(COLUMN_MASK_SHAPE), allow_pickle=False)
    assert ranks.shape == COLUMN_MASK_SHAPE and ranks.dtype == np.uint16
    np.testing.assert_array_equal(ranks, void_and_cluster(COLUMN_MASK_SHAPE))
    layer3d = np.load(blue_noise_path(), allow_pickle=False)[5]
    n = ranks.size
    for lo, hi in ((0.0, 0.1), (0.0, 0.5), (0.3, 0.4), (0.45, 0.75), (0.9, 1.0)):
        band = ((ranks >= lo * n) & (ranks < hi * n)).astype(float)
        assert spectrum_ratio(band) < (0.1 if lo == 0 or hi == 1 else 0.2), (lo, hi)
        band3d = ((layer3d >= lo * 32**3) & (layer3d < hi * 32**3)).astype(float)
        assert spectrum_ratio(band3d) > 0.3, (lo, hi)
    white = (np.random.default_rng(0).random(COLUMN_MASK_SHAPE) < 0.1).astype(float)
    assert spectrum_ratio(white) > 0.5
