"""How much Monte Carlo noise adds to a mean ΔE76 and biases SSIM, and renders with enough samples to make both small.

A render gives each texel an estimate ĉ = c + n of its noise-free colour c, with n ≈ N(0, Σ) in CIELAB
(Σ = J diag(var) Jᵀ from the linear-RGB variance of the mean, J = d lab / d rgb: the delta method). The
reported ΔE76 of a texel is |d + n| with d = c - t its noise-free error, so noise inflates the mean ΔE76 by
E|d + n| - |d| > 0 (a norm of a noisy vector is biased up).

**Estimator** (``noise_contribution``), per texel:

- for isotropic noise Σ = σ² I, |d + n| / σ is noncentral-chi distributed with 3 degrees of freedom and
  E|d + n| = σ g(|d|/σ), g(λ) = sqrt(2/π) exp(-λ²/2) + (λ + 1/λ) erf(λ/√2) (exact; g(0) = 2 sqrt(2/π), and
  g(λ) - λ → 1/λ for large λ, i.e. the familiar σ²/|d|);
- for Lab noise, which is not isotropic, σ² is replaced by the variance perpendicular to the error direction
  u = d̂/|d̂|, σ⊥² = (tr Σ - uᵀΣu) / 2: to second order in |n|/|d| the bias is exactly σ⊥²/|d| for any Σ, and
  σ⊥² = σ² for isotropic noise, so the formula is exact in both limits;
- |d| is unknown: D = sqrt(max(|d̂|² - tr Σ / 2, 0)), halfway between the plug-in |d̂| (for which E σ⊥²/|d̂| =
  σ⊥² erf(λ/√2)/|d| is unbiased at large λ) and the moment estimate sqrt(|d̂|² - tr Σ) (unbiased for |d|²);
  where D is small the direction u is mostly noise, so σ⊥² is blended towards the isotropic tr Σ / 3 with weight
  D² / (D² + tr Σ).

The contribution to the mean is the mean of σ (g(D/σ) - D/σ) over texels; ``delta_e76_mean`` minus it is the
bias-corrected mean. Accuracy, measured on Gaussian noise of known variance in linear RGB (tests/evaluation/
test_noise.py; noise adding 0.07 to 6.5 ΔE76 to errors of 0 to 12 ΔE76): the estimate is within a factor
``ESTIMATE_RANGE`` = (0.65, 1.35) of the true inflation; it underestimates (by ~30 %) only where the noise-free
error is far below the noise, and overestimates for very noisy dark colours (the Lab transform's curvature).

**SSIM and mottle** are corrected for the noise by subtracting its delta-method variance from the windowed
statistics (``TexelLoss``, ``metrics.mottle``); that correction is accurate only while the noise variance is small
against SSIM's constant K2 = 0.03² (normalised L*a*b*): SSIM is a ratio of noisy local variances (Jensen), the
corrected variance is clamped at 0, and the delta method misses the Lab transform's curvature (σ⁴ terms). Measured
(``experiments/ssim_noise_bias.py``, ``experiments/results/ssim_noise_bias_{demo,spot20mm}.json``; the demo slab's
and Spot 20 mm's optimised results): with r = the largest channel's mean per-texel noise variance / K2, SSIM
reads 0.017 / 0.029 low at r = 1.2 / 0.8 (64 spp), 0.0035 at r = 0.30 (demo, 256 spp), nothing measurable at
r = 0.075 (1024 spp), and Spot's mottle 0.13 (ΔL*)² high at 64 spp. So the adaptive rule also asks
r ≤ ``SSIM_NOISE_RATIO`` = 0.1 (~0.002 SSIM; r ∝ 1/spp).

**Adaptive samples** (``adaptive_render``): a pilot of ``PILOT_SPP`` samples per texel; Σ scales as 1/spp, so the
contribution at n samples is predicted from the pilot (D fixed, σ⊥ ∝ n^-1/2) and the smallest n whose predicted
contribution is ≤ 0.9 × target (a margin for the pilot's own noise) and whose r is ≤ 0.9 × ``SSIM_NOISE_RATIO``
is chosen, capped at ``MAX_SPP``; the
remaining n - spp samples are rendered with an independent seed and pooled with the pilot (weights by sample
count). If the pooled estimate is still above either target (and below the cap), one more round. A user's cap
(``max_spp``) and time budget (``time_budget``: the samples that the time measured per sample so far says fit)
stop it earlier; the result then says ``capped``. Seeds: pass k uses
``seed + k * SEED_STRIDE``; callers pass ``EVAL_SEED_OFFSET + seed``, disjoint from the optimisation's seeds.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from scipy.special import erf

from ..color import LAB_NORM_SCALE, RGB, ColourMap
from ..errors import ParameterError
from ..loss import K2
from ..units import format_duration

TARGET_NOISE_DE76 = 0.5  # wanted Monte Carlo contribution to the mean ΔE76
PILOT_SPP = 64
#: with a time budget, the first pass has this many samples per texel and times them, so that the rest of the pilot
#: can keep to the budget too (a 64-spp pilot of a 40 mm object takes minutes)
PROBE_SPP = 4
MAX_SPP = 4096
MAX_ROUNDS = 3  # passes after the pilot
PLAN_MARGIN = 0.9  # plan for this fraction of the target
SSIM_NOISE_RATIO = 0.1  # wanted noise variance / K2 for SSIM and mottle (module docstring)
ESTIMATE_RANGE = (0.65, 1.35)  # estimated / true inflation, measured (module docstring)
EVAL_SEED_OFFSET = 2**62  # evaluation seeds: 2**62 + seed, disjoint from the optimisation's (iteration_seeds)
SEED_STRIDE = 2**40  # seed of pass k: seed + k * SEED_STRIDE


def chi3_mean(lam) -> np.ndarray:
    """g(λ) = E|λ e + z| for z ~ N(0, I₃) and a unit vector e (the mean of a noncentral chi, 3 d.o.f.)."""
    lam = np.asarray(lam, np.float64)
    return lam + chi3_excess(lam)


def chi3_excess(lam) -> np.ndarray:
    """g(λ) - λ, computed without cancellation (1/λ beyond λ = 40, where the rest is below 1e-300)."""
    lam = np.asarray(lam, np.float64)
    ls = np.clip(lam, 1e-4, 40.0)
    mid = np.sqrt(2 / np.pi) * np.exp(-0.5 * ls * ls) + (ls + 1 / ls) * erf(ls / np.sqrt(2)) - ls
    lo = np.minimum(lam, 1e-4)
    small = 2 * np.sqrt(2 / np.pi) * (1 + lo * lo / 6) - lo
    return np.where(lam < 1e-4, small, np.where(lam > 40.0, 1.0 / np.maximum(lam, 40.0), mid))


def lab_covariance(rgb, var_mean, cmap: ColourMap = RGB) -> np.ndarray:
    """CIELAB covariance (I, 3, 3) of colour estimates rgb (I, C) with per-channel variances var_mean (I, C), the
    channels' colour map ``cmap`` (default linear sRGB)."""
    jac = cmap.lab_jacobian(np.asarray(rgb, np.float64))
    return np.einsum("ikj,ij,ilj->ikl", jac, np.asarray(var_mean, np.float64), jac)


@dataclass
class NoiseModel:
    """Per-texel parts of the estimator: D (I,) the estimated noise-free |d|, s2 (I,) σ⊥² at the render's spp;
    ``ssim_ratio``: r at the render's spp, the largest channel's mean noise variance of normalised L*a*b* over
    SSIM's K2 (module docstring)."""

    dist: np.ndarray
    s2: np.ndarray
    ssim_ratio: float = 0.0

    @classmethod
    def of(cls, rgb, var_mean, target_lab, cmap: ColourMap = RGB) -> NoiseModel:
        """The model of estimates ``rgb`` (I, C) of variances ``var_mean`` (I, C) under colour map ``cmap``."""
        lab = cmap.lab(np.asarray(rgb, np.float64))
        d = lab - np.asarray(target_lab, np.float64)
        cov = lab_covariance(rgb, var_mean, cmap)
        n2 = np.sum(d * d, 1)
        tr = np.trace(cov, axis1=1, axis2=2)
        u = d / np.sqrt(np.maximum(n2, 1e-300))[:, None]
        perp = np.where(n2 > 0, 0.5 * (tr - np.einsum("ik,ikl,il->i", u, cov, u)), tr / 3)
        dist2 = np.maximum(n2 - 0.5 * tr, 0.0)
        w = dist2 / np.maximum(dist2 + tr, 1e-300)
        v = np.diagonal(cov, axis1=1, axis2=2) * LAB_NORM_SCALE**2
        ratio = float(v.mean(0).max() / K2) if len(v) else 0.0
        return cls(np.sqrt(dist2), np.maximum(w * perp + (1 - w) * tr / 3, 0.0), ratio)

    def per_texel(self, scale: float = 1.0) -> np.ndarray:
        """Expected inflation E|d + n| - |d| per texel, with the variance multiplied by ``scale``."""
        s = np.sqrt(self.s2 * scale)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = np.where(s > 0, self.dist / s, np.inf)
        return np.where(s > 0, s * chi3_excess(lam), 0.0)

    def contribution(self, scale: float = 1.0) -> float:
        return float(self.per_texel(scale).mean())

    def converged(self, target: float, ratio: float = SSIM_NOISE_RATIO) -> bool:
        """Noise contribution ≤ target and SSIM noise ratio ≤ ratio."""
        return self.contribution() <= target and self.ssim_ratio <= ratio

    def spp_for(self, spp_now: int, target: float, max_spp: int, ratio: float = SSIM_NOISE_RATIO) -> int:
        """The smallest spp ≥ spp_now (≤ max_spp) whose predicted contribution is ≤ target and predicted SSIM
        noise ratio ≤ ratio."""
        need = int(min(max_spp, max(spp_now, math.ceil(spp_now * self.ssim_ratio / ratio))))
        return max(need, self._spp_for_contribution(spp_now, target, max_spp))

    def _spp_for_contribution(self, spp_now: int, target: float, max_spp: int) -> int:
        if self.contribution() <= target:
            return int(spp_now)
        if self.contribution(spp_now / max_spp) > target:
            return int(max_spp)
        lo, hi = int(spp_now), int(max_spp)  # contribution(lo) > target >= contribution(hi)
        while hi - lo > max(1, lo // 64):
            mid = int(math.sqrt(lo * hi))
            mid = min(max(mid, lo + 1), hi - 1)
            if self.contribution(spp_now / mid) <= target:
                hi = mid
            else:
                lo = mid
        return hi


def noise_contribution(rgb, var_mean, target_lab) -> float:
    """The estimated Monte Carlo contribution to the mean ΔE76 (module docstring)."""
    return NoiseModel.of(rgb, var_mean, target_lab).contribution()


@dataclass
class AdaptiveResult:
    """Pooled colours rgb (I, 3), variance of their means var (I, 3), total samples per texel spp (in the
    caller's units), the passes' spp, the estimated noise contribution of the pooled result, and ``capped``: the
    samples stopped at ``max_spp`` or the time budget before the noise targets were met."""

    rgb: np.ndarray
    var: np.ndarray
    spp: int
    passes: list
    noise: float
    capped: bool = False


@dataclass(frozen=True)
class Sampling:
    """The samples of one render through ``adaptive_render``: ``seed`` of its first pass (pass k: ``seed + k *
    SEED_STRIDE``); ``spp`` samples per texel in exactly one pass, or None: adaptive (module docstring), a pilot of
    ``pilot_spp`` and then passes until the noise contribution is at most ``target`` ΔE76 and the SSIM noise ratio
    at most ``ratio`` (either inf: no such target), at most ``max_spp`` samples and, with ``time_budget`` (seconds,
    the pilot included unless ``pilot_in_budget`` is False), no more than the time measured per sample says fit."""

    seed: int = 0
    spp: int | None = None
    max_spp: int = MAX_SPP
    time_budget: float | None = None
    pilot_spp: int = PILOT_SPP
    pilot_in_budget: bool = True
    target: float = TARGET_NOISE_DE76
    ratio: float = SSIM_NOISE_RATIO

    def __post_init__(self):
        for name in ("spp", "max_spp", "pilot_spp"):
            value = getattr(self, name)
            if value is not None and not value >= 1:
                raise ParameterError(f"`{name}` must be at least 1, got {value}")
        if self.time_budget is not None and not self.time_budget >= 0:
            raise ParameterError(f"`time_budget` must be a number of seconds >= 0, got {self.time_budget}")
        for name in ("target", "ratio"):
            if not getattr(self, name) > 0:
                raise ParameterError(f"`{name}` must be positive, got {getattr(self, name)}")


@dataclass
class _Pool:
    """Passes pooled by their weights (samples per texel as the render counts them): colours ``rgb`` (I, 3) and
    the variance of their means ``var`` (I, 3), float64; ``total`` samples per texel and each pass's ``passes``."""

    rgb: np.ndarray
    var: np.ndarray
    weight: float
    total: int
    passes: list

    @classmethod
    def first(cls, render, spp: int, seed: int) -> _Pool:
        rgb, var, w = render(spp, seed)
        return cls(np.asarray(rgb, np.float64), np.asarray(var, np.float64), float(w), spp, [spp])

    def add(self, render, spp: int, seed: int) -> None:
        r1, v1, w1 = render(spp, seed)
        r1, v1, w1 = np.asarray(r1, np.float64), np.asarray(v1, np.float64), float(w1)
        w = self.weight
        self.rgb = (w * self.rgb + w1 * r1) / (w + w1)
        self.var = (w * w * self.var + w1 * w1 * v1) / (w + w1) ** 2
        self.weight, self.total = w + w1, self.total + spp
        self.passes.append(spp)


def _fit(sampling: Sampling, clock, t0: float, per_spp: float) -> int:
    """Samples per texel that fit in what is left of the time budget at ``per_spp`` seconds each (not lost to
    rounding)."""
    return int((sampling.time_budget - (clock() - t0)) / max(per_spp, 1e-12) + 1e-6)


def first_pass(sampling: Sampling) -> tuple[int, bool]:
    """(samples per texel of the first pass ``adaptive_render`` makes, at seed ``sampling.seed``; whether it is a
    ``PROBE_SPP`` probe that times the samples before the rest of the pilot): ``spp``, or the pilot, or the probe
    where a time budget bounds the pilot."""
    s = sampling
    first = int(s.spp) if s.spp is not None else min(int(s.pilot_spp), int(s.max_spp))
    probe = s.spp is None and s.time_budget is not None and s.pilot_in_budget and first > PROBE_SPP
    return (PROBE_SPP if probe else first), probe


def _pilot(render, sampling: Sampling, clock, t0: float) -> tuple[_Pool, bool, int]:
    """The first pass (``first_pass``: ``spp``, or the pilot); with a time budget that bounds the pilot, a
    ``PROBE_SPP`` pass that times the samples and then the rest of the pilot that fits. Returns the pool, whether the
    budget cut the pilot, and the index of the next pass."""
    s = sampling
    pilot = min(int(s.pilot_spp), int(s.max_spp))
    first, probe = first_pass(s)
    pool = _Pool.first(render, first, s.seed)
    if not probe:
        return pool, False, 1
    extra = min(pilot - pool.total, max(_fit(s, clock, t0, (clock() - t0) / pool.total), 0))
    capped = extra < pilot - pool.total
    if extra <= 0:
        return pool, capped, 1
    pool.add(render, extra, s.seed + SEED_STRIDE)
    return pool, capped, 2


def _next_pass(model: NoiseModel, pool: _Pool, sampling: Sampling, capped: bool, clock, t0: float, log):
    """Samples per texel of the next pass (0 or less: none fit in the time budget) and whether the samples are
    capped; logs the pass with its expected time."""
    s = sampling
    want = model.spp_for(pool.total, PLAN_MARGIN * s.target, s.max_spp, PLAN_MARGIN * s.ratio)
    capped = capped or want >= s.max_spp
    per_spp = (clock() - t0) / pool.total
    extra = want - pool.total
    if s.time_budget is not None:
        fit = _fit(s, clock, t0, per_spp)
        if fit < extra:
            extra, capped = max(fit, 0), True
    if log is not None and extra <= 0:
        log(f"  noise {model.contribution():.2f} dE76 at {pool.total} spp: the time budget is spent")
    elif log is not None:
        log(
            f"  noise {model.contribution():.2f} dE76, SSIM noise ratio {model.ssim_ratio:.2f} at {pool.total} spp "
            f"(targets {s.target:g}, {s.ratio:g}): {extra} more, ~{format_duration(extra * per_spp)}"
            + (" (capped)" if capped else "")
        )
    return extra, capped


def adaptive_render(
    render, target_lab, sampling: Sampling = Sampling(), log=None, clock=None, cmap: ColourMap = RGB
) -> AdaptiveResult:
    """Render through ``render(spp, seed) -> (rgb (I, 3), var_mean (I, 3), weight)`` (``weight``: the pass's
    samples per texel as pooled, e.g. a printer render's own spp) the samples ``sampling`` asks for: exactly its
    ``spp`` in one pass (the user's choice is honoured), else adaptively against ``target_lab`` (I, 3) CIELAB
    (module docstring); each further pass is logged with its expected time through ``log``. ``clock``: seconds
    (default ``time.perf_counter``). ``cmap``: the colour map of the render's C channels (a spectral render's
    bands under its first light; default linear sRGB, C = 3)."""
    clock = clock or time.perf_counter
    t0 = clock()
    s = sampling
    pool, capped, k0 = _pilot(render, s, clock, t0)
    model = NoiseModel.of(pool.rgb, pool.var, target_lab, cmap)
    for k in range(k0, MAX_ROUNDS + k0):
        if s.spp is not None or model.converged(s.target, s.ratio):
            break
        if pool.total >= s.max_spp:
            capped = True
            break
        extra, capped = _next_pass(model, pool, s, capped, clock, t0, log)
        if extra <= 0:
            break
        pool.add(render, extra, s.seed + k * SEED_STRIDE)
        model = NoiseModel.of(pool.rgb, pool.var, target_lab, cmap)
    converged = model.converged(s.target, s.ratio)
    return AdaptiveResult(
        pool.rgb, pool.var, int(pool.total), pool.passes, model.contribution(), capped and not converged
    )
