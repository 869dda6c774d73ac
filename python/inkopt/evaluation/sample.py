"""Figures of an evaluation from a random sample of scene texels, with their sampling standard errors.

Every figure of ``metrics.Metrics`` is a mean over the scene's I texels of a per-texel value (ΔE76, ΔE2000, the
noise terms), a quantile of one (the ΔE76 95th percentile), or a mean of a per-texel value that depends on the
texel's Gaussian window (SSIM, the edge term e3, the mottle; ``loss.gaussian_window``: every texel within
Chebyshev distance ``radius`` = int(3.5 sigma + 0.5) voxels). A simple random sample estimates each one, and the
spread of the sampled values gives its standard error, so a large object need not be rendered whole.

**The sample** (``TexelSample.draw``, numpy's generator seeded with the evaluation seed): n scene texels (the
user's ``texel_sample``, or as many as ``evaluation.choice`` asks for a given accuracy) drawn without
replacement (the *points*); the first m of them in draw order (a simple random sample too) are window *centres*,
each rendered with every texel of its window (the *window texels*, their union). The two groups are
rendered apart, each adaptively (``evaluate``): the points as every texel would be (the noise adds at most
``noise.TARGET_NOISE_DE76`` to the mean ΔE76 and SSIM's noise ratio is at most ``noise.SSIM_NOISE_RATIO``), so that
their render noise biases the figures it is not corrected out of (ΔE2000, the 95th percentile) and leaves in the
corrected mean ΔE76 the same residual as rendering every texel; the window texels until SSIM's noise ratio is at
most ``SAMPLE_SSIM_NOISE_RATIO``. The loss is built on the window texels only; a centre's window lies inside them, so
its SSIM, e3 and mottle terms equal the full evaluation's for the same colours (the other window texels' own
window values are not used).

**Estimates** (``sampled_figures``): the mean of the points' values (ΔE76, ΔE2000, noise terms, e1) or of the
centres' (SSIM, e3; mottle over the flat centres), with standard error s / sqrt(k) · sqrt(1 - k / I) (s the
sample standard deviation of the k values, finite-population corrected); the 95th percentile of the points' ΔE76
with the distribution-free error of an order statistic (half the distance between the order statistics one
binomial standard deviation, sqrt(n q (1 - q)), below and above rank n q); RMS figures sqrt(mean ΔE²) by the
delta method (SE of the mean of ΔE² / (2 RMS)); ``flat_texels`` the flat centres' share times I. The render noise
of each sampled texel is part of the spread, so the standard error covers it; what it does not cover is the
noise's bias (its inflation of ΔE76, corrected by ``delta_e76_mean_corrected``, and the SSIM noise correction's
residual), which the adaptive render keeps small: ΔE76 as in the full evaluation, SSIM to a noise ratio of
``SAMPLE_SSIM_NOISE_RATIO`` (a bias of ~0.004, small against the sampling error, at a third of the samples; the
measurement is ``evaluation.noise``'s).
The mottle's per-texel values are heavy-tailed (a few texels carry much of the mean), so a sample of ~100 windows
often misses them and its standard error understates the error (docs/quality.md).

**Paired differences** (``differences``): every result is rendered on the same sampled texels with the same seeds,
so a difference between two results (ours against a baseline) is estimated texel by texel, and its standard
error comes from the spread of the per-texel differences: much smaller than either figure's where the results'
errors go together texel by texel (the sampling error of which texels were drawn cancels).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..color import RGB, delta_e76, delta_e2000, lab_stderr, linear_to_lab, normalise_lab
from ..errors import ParameterError
from ..loss import E1_WEIGHT_SCALE, TexelLoss
from ..model import Texels
from .metrics import Metrics, mottle_per_texel
from .noise import NoiseModel

DEFAULT_SAMPLE_WINDOWS = 100  # window centres (SSIM, e3, mottle), the first of the points
#: the adaptive render's SSIM noise ratio target with a sample (``noise.SSIM_NOISE_RATIO`` without): SSIM read
#: 0.0035 low at r = 0.30 (noise.py's measurements), a sixth of the sampling error of the default windows
SAMPLE_SSIM_NOISE_RATIO = 0.3
SIGMA = 1.5  # the figures' SSIM window (voxels), as ``TexelLoss`` in ``evaluate``
QUANTILE = 95.0
#: the figures compared by ``differences`` (per-texel values, centres' for SSIM and mottle)
PAIRED = ("delta_e76_mean", "delta_e76_mean_corrected", "delta_e2000_mean", "ssim", "mottle_l2")


class SampleError(ParameterError):
    """A texel sample that cannot be drawn (bad sizes: ``texel_sample``, ``sample_windows``)."""


@dataclass
class TexelSample:
    """A random sample of a scene's ``population`` texels (module docstring): ``points`` (int64 (n,), sorted scene
    texel indices), ``centres`` (int64 (m,), the window centres, some of the points) and ``windows`` (int64 (W,),
    sorted: every texel of the centres' windows). ``groups``: the two texel groups rendered, points and windows."""

    population: int
    points: np.ndarray
    centres: np.ndarray
    windows: np.ndarray
    seed: int
    radius: int

    @classmethod
    def draw(cls, texels: Texels, n: int, m: int, seed: int, sigma: float = SIGMA) -> TexelSample:
        """n points (at most all texels) and m window centres (at most n) of ``texels``."""
        population = len(texels)
        n, m = sample_size(n, m, population)
        draw = np.random.default_rng(int(seed)).choice(population, n, replace=False)
        radius = int(3.5 * sigma + 0.5)
        pos = texels.pos_vox
        near = cKDTree(pos).query_ball_point(pos[draw[:m]], radius + 1e-6, p=np.inf)
        windows = np.unique(np.concatenate([np.asarray(w, np.int64) for w in near]))
        return cls(population, np.sort(draw), draw[:m].astype(np.int64), windows, int(seed), radius)

    @property
    def groups(self) -> list[np.ndarray]:
        return [self.points, self.windows]

    @property
    def centre_rows(self) -> np.ndarray:
        """The centres' rows in ``windows``."""
        return np.searchsorted(self.windows, self.centres)

    def to_json(self) -> dict:
        return {
            "population": self.population,
            "texels": len(self.points),
            "windows": len(self.centres),
            "window_texels": len(self.windows),
            "window_radius": self.radius,
            "seed": self.seed,
        }


def sample_size(texels: int, windows: int | None, population: int) -> tuple[int, int]:
    """(points, windows) of a texel sample of ``texels`` points (0: none, every texel rendered; ``evaluation.choice``
    picks it when the user does not) and ``windows`` SSIM windows (None: ``DEFAULT_SAMPLE_WINDOWS``), each at most
    the population (windows at most the points)."""
    windows = DEFAULT_SAMPLE_WINDOWS if windows is None else windows
    if texels < 0 or texels == 1:
        raise SampleError(f"`texel_sample` must be 0 (every texel) or at least 2 texels, got {texels}")
    if texels and windows < 2:
        raise SampleError(f"`sample_windows` must be at least 2, got {windows}")
    n = min(int(texels), population)
    return n, min(int(windows), n)


def mean_se(x: np.ndarray, population: int) -> tuple[float, float]:
    """Mean of a simple random sample ``x`` (k,) and its finite-population-corrected standard error."""
    x = np.asarray(x, np.float64)
    k = len(x)
    if k < 2:
        return (float(x.mean()) if k else math.nan), math.nan
    return float(x.mean()), float(x.std(ddof=1) / math.sqrt(k) * math.sqrt(max(0.0, 1.0 - k / population)))


def quantile_se(x: np.ndarray, q: float, population: int) -> tuple[float, float]:
    """The ``q`` percentile of sample ``x`` and its order-statistic standard error (module docstring)."""
    x = np.sort(np.asarray(x, np.float64))
    n, p = len(x), q / 100.0
    half = math.sqrt(n * p * (1 - p))
    lo, hi = int(max(0, math.floor(n * p - half))), int(min(n - 1, math.ceil(n * p + half)))
    fpc = math.sqrt(max(0.0, 1.0 - n / population))
    return float(np.percentile(x, q)), float((x[hi] - x[lo]) / 2 * fpc)


def per_texel(loss: TexelLoss, windows, points, target_lab, sample: TexelSample) -> dict:
    """The per-texel values of a result rendered on the sample's texels: ``windows`` = (rgb, var) (W, C) channel
    values of the loss's first colour map (linear sRGB, or a spectral render's bands under one light: ``loss`` a
    single light's view, ``TexelLoss.under``) and their variance on the window texels (``loss`` built on them),
    ``points`` = (rgb, var) (n, C) on the points,
    ``target_lab`` (n, 3) the points' targets. Points' ``delta_e76``, ``delta_e2000``, ``noise`` (the colour's
    standard error, ΔE), ``noise_contribution``, and centres' ``ssim`` (mean over L*a*b*), ``e3``, ``mottle`` and
    ``mottle_target`` (NaN where the centre is not flat)."""
    rgb, var = (np.asarray(a, np.float64) for a in windows)
    rgb_p, var_p = (np.asarray(a, np.float64) for a in points)
    cmap = loss.colours[0]
    to_lab = linear_to_lab if cmap is RGB else cmap.lab  # the RGB path exactly as before
    lab_p = to_lab(rgb_p)
    ct = sample.centre_rows
    sob = loss.S @ (normalise_lab(to_lab(rgb)) - loss.target_n)
    r = len(rgb)
    e3 = sum((sob[a * r + ct] ** 2).sum(1) for a in range(3)) * (100.0 / (3.0 * 4.0 * 32.0))
    p, p_target = mottle_per_texel(loss, rgb, var)
    flat = loss.flat[ct]
    return {
        "delta_e76": delta_e76(lab_p, target_lab),
        "delta_e2000": delta_e2000(lab_p, target_lab),
        "noise": lab_stderr(rgb_p, var_p) if cmap is RGB else cmap.lab_stderr(rgb_p, var_p),
        "noise_contribution": NoiseModel.of(rgb_p, var_p, target_lab, cmap).per_texel(),
        "ssim": loss.ssim_map(rgb, var)[ct].mean(1),
        "e3": e3,
        "mottle": np.where(flat, p[ct], np.nan),
        "mottle_target": np.where(flat, p_target[ct], np.nan),
    }


def sampled_figures(loss: TexelLoss, values: dict, sample: TexelSample) -> tuple[Metrics, dict]:
    """``Metrics`` estimated from a result's per-texel ``values`` (``per_texel``), and the standard error of each
    figure by name (module docstring)."""
    big = sample.population
    est, err = {}, {}

    def put(name, pair):
        est[name], err[name] = pair

    de = values["delta_e76"]
    put("delta_e76_mean", mean_se(de, big))
    put("delta_e76_p95", quantile_se(de, QUANTILE, big))
    put("delta_e2000_mean", mean_se(values["delta_e2000"], big))
    put("ssim", mean_se(values["ssim"], big))
    put("e1", mean_se(de * de, big))
    put("e3", mean_se(values["e3"], big))
    est["e2"], err["e2"] = 1.0 - est["ssim"], err["ssim"]
    g = loss.gamma / loss.gamma.sum()
    terms = [(g[0] * E1_WEIGHT_SCALE, "e1"), (g[1], "e2"), (g[2], "e3")]
    est["loss"] = sum(w * est[k] for w, k in terms if w > 0)
    err["loss"] = math.sqrt(sum((w * err[k]) ** 2 for w, k in terms if w > 0))  # the two samples as independent
    flat = ~np.isnan(values["mottle"])
    est["flat_texels"] = int(round(flat.mean() * big))
    err["flat_texels"] = mean_se(flat.astype(np.float64), big)[1] * big
    for key, name in (("mottle", "mottle_l2"), ("mottle_target", "mottle_l2_target")):
        est[name], err[name] = mean_se(values[key][flat], big) if flat.any() else (None, None)
    se, contrib = values["noise"], values["noise_contribution"]
    put("delta_e76_noise", mean_se(se, big))
    put("delta_e76_noise_contribution", mean_se(contrib, big))
    put("delta_e76_mean_corrected", mean_se(de - contrib, big))
    for name, sq in (("delta_e76_rms", de * de), ("delta_e76_rms_denoised", de * de - se * se)):
        m2, s2 = mean_se(sq, big)
        est[name] = math.sqrt(max(m2, 0.0))
        err[name] = s2 / (2 * est[name]) if est[name] > 0 else math.nan
    return Metrics(**est), {k: _finite(v) for k, v in err.items() if v is not None}


def differences(values: dict, pairs, sample: TexelSample) -> dict:
    """ "a - b" -> figure -> {"value", "stderr"} for each (a, b) of ``pairs`` (result names of ``values``: name ->
    ``per_texel``), from the per-texel differences on the shared sample (module docstring)."""
    big, out = sample.population, {}
    for a, b in pairs:
        va, vb = values[a], values[b]
        diff = {
            "delta_e76_mean": va["delta_e76"] - vb["delta_e76"],
            "delta_e76_mean_corrected": (va["delta_e76"] - va["noise_contribution"])
            - (vb["delta_e76"] - vb["noise_contribution"]),
            "delta_e2000_mean": va["delta_e2000"] - vb["delta_e2000"],
            "ssim": va["ssim"] - vb["ssim"],
            "mottle_l2": (va["mottle"] - vb["mottle"])[~np.isnan(va["mottle"])],
        }
        out[f"{a} - {b}"] = {}
        for name in PAIRED:
            v, s = mean_se(diff[name], big) if len(diff[name]) else (math.nan, math.nan)
            out[f"{a} - {b}"][name] = {"value": _finite(v), "stderr": _finite(s)}
    return out


def _finite(v: float) -> float | None:
    """``v``, or None for NaN (not valid JSON): a figure with too few sampled texels to estimate it."""
    return None if v is None or math.isnan(v) else float(v)


def sample_lines(ev) -> list[str]:
    """Plain-text lines of an ``Evaluation``'s texel sample: each result's main figures with their standard errors,
    and the paired differences (none without a sample)."""
    if ev.texel_sample is None:
        return []
    t = ev.texel_sample
    lines = [
        f"texel sample: {t['texels']} of {t['population']} texels, {t['windows']} SSIM windows of "
        f"{t['window_texels']} texels; figures +- their standard errors:"
    ]
    for name, r in ev.results():
        m, e = r.metrics, r.stderr or {}
        lines.append(
            f"  {name:<18}dE76 {m.delta_e76_mean:.2f} +- {_num(e.get('delta_e76_mean')):.2f}, corrected "
            f"{_num(m.delta_e76_mean_corrected):.2f} +- {_num(e.get('delta_e76_mean_corrected')):.2f}, dE2000 "
            f"{m.delta_e2000_mean:.2f} +- {_num(e.get('delta_e2000_mean')):.2f}, SSIM {m.ssim:.3f} +- "
            f"{_num(e.get('ssim')):.3f}"
        )
    for pair, figs in (ev.differences or {}).items():
        f = {k: (_num(v["value"]), _num(v["stderr"])) for k, v in figs.items()}
        lines.append(
            f"  {pair:<30}dE76 {f['delta_e76_mean'][0]:+.2f} +- {f['delta_e76_mean'][1]:.2f}, corrected "
            f"{f['delta_e76_mean_corrected'][0]:+.2f} +- {f['delta_e76_mean_corrected'][1]:.2f}, SSIM "
            f"{f['ssim'][0]:+.3f} +- {f['ssim'][1]:.3f} (paired)"
        )
    return lines


def _num(v) -> float:
    return math.nan if v is None else float(v)
