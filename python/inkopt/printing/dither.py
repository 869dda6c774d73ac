"""Blue-noise dither arrays (void-and-cluster) for ordered dithering of ink mixtures (``quantize``), and the order of
the inks in it (``lightness_order``).

The default 32 x 32 x 32 array and the 64 x 64 mask of the columns' dither ship with the package (``inkopt/data``);
other shapes are generated once and cached there when it is writable.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ..io import atomic_write_bytes

#: Luminance Y of linear sRGB (Rec. 709 primaries, D65)
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
BLUE_NOISE_SHAPE = (32, 32, 32)
BLUE_NOISE_SIGMA = 1.5
#: the 2D mask of ``thresholds.BlueNoiseColumns`` (y, x), shipped like the 3D array
COLUMN_MASK_SHAPE = (64, 64)
#: the golden ratio's conjugate, (sqrt(5) - 1) / 2: the step of the columns' thresholds from layer to layer
GOLDEN = (5.0**0.5 - 1.0) / 2.0
DATA_DIR = Path(__file__).resolve().parent.parent / "data"


def void_and_cluster(
    shape=BLUE_NOISE_SHAPE, sigma=BLUE_NOISE_SIGMA, seed: int = 0, initial_fraction: float = 0.1
) -> np.ndarray:
    """Blue-noise dither array by Ulichney's void-and-cluster algorithm on a periodic grid of any dimension.

    Energy of a pattern = periodic convolution of its "on" points with a Gaussian (``sigma`` in voxels, one number
    or one per axis, truncated at 3 sigma). Phase 0 relaxes a random initial pattern (``initial_fraction`` on,
    ``default_rng(seed)``) by moving the tightest cluster into the largest void until stable; phase 1 ranks its
    points by repeatedly removing the tightest cluster; phase 2 ranks the rest by repeatedly filling the largest
    void (the
    "tightest cluster of zeros" of Ulichney's phase 3 is the same voxel, since the energies of the ones and the
    zeros add up to a constant). Deterministic for a given (shape, sigma, seed); ties go to the lowest index.
    Returns the ranks, int64 array of ``shape``, a permutation of 0..n-1; every prefix ``rank < k`` is a
    blue-noise pattern. O(n * (n + (6 sigma)^d)); 32^3 takes a few seconds.
    """
    shape = tuple(int(s) for s in shape)
    if not shape or min(shape) < 2:
        raise ValueError(f"blue-noise shape must have sizes >= 2, got {shape}")
    n, d = int(np.prod(shape)), len(shape)
    shp = np.array(shape)
    sig = np.broadcast_to(np.asarray(sigma, np.float64), (d,))  # one sigma per axis (an anisotropic energy)
    r = [int(np.ceil(3 * v)) for v in sig]
    axes = [np.arange(-min(ri, (s - 1) // 2), min(ri, (s - 1) // 2) + 1) for ri, s in zip(r, shape)]
    offs = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, d)
    if np.ndim(sigma) == 0:
        kern = np.exp(-np.sum(offs.astype(np.float64) ** 2, 1) / (2.0 * float(sigma) ** 2))
    else:
        kern = np.exp(-np.sum((offs / sig) ** 2, 1) / 2.0)
    strides = np.array([int(np.prod(shape[i + 1 :])) for i in range(d)])

    rng = np.random.default_rng(seed)
    m = max(1, int(round(initial_fraction * n)))
    ones = np.zeros(n, bool)
    ones[rng.choice(n, m, replace=False)] = True
    k_full = np.zeros(shape)
    k_full[tuple((offs % shp).T)] = kern
    energy = np.real(np.fft.ifftn(np.fft.fftn(ones.reshape(shape).astype(np.float64)) * np.fft.fftn(k_full)))
    energy = energy.ravel()
    on = np.where(ones, energy, -np.inf)  # energy of "on" points, -inf elsewhere (argmax: tightest cluster)
    off = np.where(ones, np.inf, energy)  # energy of "off" points, +inf elsewhere (argmin: largest void)

    def flip(p: int, to_on: bool) -> None:
        idx = ((np.array(np.unravel_index(p, shape)) + offs) % shp) @ strides
        step = kern if to_on else -kern
        on[idx] += step
        off[idx] += step
        if to_on:
            on[p], off[p] = off[p], np.inf
        else:
            off[p], on[p] = on[p], -np.inf

    for _ in range(n):  # phase 0
        c = int(np.argmax(on))
        flip(c, False)
        v = int(np.argmin(off))
        flip(v, True)
        if v == c:
            break
    rank = np.empty(n, np.int64)
    on0, off0 = on.copy(), off.copy()
    for cnt in range(m - 1, -1, -1):  # phase 1
        c = int(np.argmax(on))
        flip(c, False)
        rank[c] = cnt
    on[:], off[:] = on0, off0
    for cnt in range(m, n):  # phase 2 (+3)
        v = int(np.argmin(off))
        flip(v, True)
        rank[v] = cnt
    return rank.reshape(shape)


def blue_noise_path(shape=BLUE_NOISE_SHAPE) -> Path:
    return DATA_DIR / ("blue_noise_" + "x".join(str(int(s)) for s in shape) + ".npy")


def load_blue_noise(shape=BLUE_NOISE_SHAPE) -> np.ndarray:
    """Blue-noise thresholds, float32 array of ``shape`` ((z, y, x), or (y, x) for a 2D mask) with values
    (rank + 0.5) / n in (0, 1).

    Loads the shipped ranks (``inkopt/data/blue_noise_<shape>.npy``, uint16, ``void_and_cluster(shape)`` with
    the default sigma and seed); other shapes are generated and cached there (atomically) when writable.
    """
    shape = tuple(int(s) for s in shape)
    path = blue_noise_path(shape)
    ranks = None
    if path.is_file():
        ranks = np.load(path, allow_pickle=False)
        if ranks.shape != shape:
            ranks = None
    if ranks is None:
        ranks = void_and_cluster(shape)
        try:
            buf = io.BytesIO()
            np.save(buf, ranks.astype(np.uint16 if ranks.size <= 65536 else np.uint32))
            atomic_write_bytes(path, buf.getvalue())
            path.chmod(0o644)
        except OSError:
            pass  # read-only install: use the generated array without caching
    return ((ranks.astype(np.float64) + 0.5) / ranks.size).astype(np.float32)


def thick_layer_reflectance(inks, g: float, ior: float) -> np.ndarray:
    """(N, 3) linear RGB: the total diffuse reflectance of a semi-infinite layer of each ink, in the dipole
    approximation (Jensen et al. 2001): R = a'/2 (1 + exp(-4/3 A s)) exp(-s), s = sqrt(3 (1 - a')), with the reduced
    albedo a' = sigma_s (1 - g) / (sigma_s (1 - g) + sigma_a) per channel and A = (1 + F_dr) / (1 - F_dr) from the
    boundary's relative index ``ior`` (F_dr by Egan and Hilgeman's fit); an ink that neither scatters nor absorbs
    (clear) counts as R = 1."""
    ss = np.asarray(inks.sigma_s, np.float64) * (1.0 - float(g))
    ext = ss + np.asarray(inks.sigma_a, np.float64)
    a = np.divide(ss, ext, out=np.ones_like(ext), where=ext > 0)
    eta = float(ior)
    f_dr = -1.440 / eta**2 + 0.710 / eta + 0.668 + 0.0636 * eta
    big_a = (1.0 + f_dr) / (1.0 - f_dr)
    s = np.sqrt(3.0 * (1.0 - a))
    return a / 2.0 * (1.0 + np.exp(-4.0 / 3.0 * big_a * s)) * np.exp(-s)


def lightness_order(inks, g: float, ior: float) -> np.ndarray:
    """The ink indices (N,) int64 ordered by the luminance of a thick layer of each ink (``thick_layer_reflectance``),
    lightest first: the order of the inks in the cumulative mixture that ordered dithering compares with the
    thresholds (``quantize``). Ties keep index order.

    Why: ink k takes the printer voxels whose threshold falls in its band of the cumulative mixture. The first and the
    last band are a prefix and a suffix of the thresholds' order, each a blue-noise pattern of its own; the bands
    between are differences of two such patterns, less evenly spread. Lightest first puts the two inks that contrast
    most (white and black) at the two ends, each evenly dispersed, and makes the printed lightness a monotone function
    of the threshold, so the halftone's lightness error keeps the dither array's blue-noise spectrum. In index order
    (cyan, magenta, yellow, black, white) black takes a middle band. Measured in docs/quality.md ("The inks' order in
    the dither"). For the paper's inks: white, yellow, magenta, cyan, black, as the colour table's rendered patches
    have them.
    """
    return np.argsort(-(thick_layer_reflectance(inks, g, ior) @ LUMINANCE), kind="stable")
