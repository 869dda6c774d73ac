"""Whether an evaluation renders every texel or a texel sample (``evaluation.sample``): whichever is predicted to
take less time at the same accuracy of the mean ΔE76, from a short pilot render.

**Accuracy.** Rendering every texel, the mean ΔE76 has no sampling error, only what is left of the render noise
after its correction: the noise adds at most ``noise.TARGET_NOISE_DE76`` (0.5) and its estimate is within
``noise.ESTIMATE_RANGE`` (x0.65-1.35) of the truth, so the corrected mean is off by up to 0.35 x 0.5 =
``TARGET_STDERR_DE76`` = 0.175 ΔE76. A sample of n of the I texels, rendered to the same noise target, adds its
sampling error s / sqrt(n) · sqrt(1 - n / I) (s: the standard deviation of the per-texel ΔE76); the sample asked
for has that error equal to the full render's residual, n = n0 / (1 + n0 / I) with n0 = (s / 0.175)², and at
least ``MIN_SAMPLE_TEXELS`` (the 95th percentile's order statistics need texels above it). SSIM and the mottle
come from the sample's windows: their sampling error (~0.01 SSIM with 100 windows) stays above the full render's
noise bias (~0.002); the rule does not equalise it, each figure's standard error says it.

**Cost** (``CostModel``). The continuous result is rendered on ``PILOT_TEXELS`` random texels (at most a quarter of
them) at ``noise.PILOT_SPP`` samples (with a fixed ``spp``, at most that many): the seconds per texel-sample, s,
and, as ``noise.adaptive_render`` plans them (``NoiseModel.spp_for``), the samples every texel needs (ΔE76 noise
and SSIM noise ratio ``noise.SSIM_NOISE_RATIO``), which the sample's points get too (``renders.texel_groups``: the
same noise bias), and the samples its windows need (``sample.SAMPLE_SSIM_NOISE_RATIO``); a fixed ``spp`` is used
as it is. Every texel costs I x spp_full
texel-samples, the sample n x spp_points + W x spp_windows, W the texels of its windows counted on the sample
drawn. The printed results and the baselines are rendered on the same texels with their own samples and are taken
to scale alike, so the predicted seconds are the continuous result's. The choice itself depends on counts of
texel-samples only, not on the machine's speed or load (the pilot's seconds per texel-sample scale both alike).

**Choice** (``choose_sampling``): the sample when it is predicted to take at most 1 / ``SAMPLE_MIN_GAIN`` of the
full render's time and draws fewer texels than there are, else every texel. The margin is there because the
sample gives up the pictures and predictions.npz and measures SSIM and the mottle less precisely: worth it only
for a clear gain. ``texel_sample`` (0: every texel, N: a sample of N) forces the choice without a pilot.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..color import RGB, delta_e76, linear_to_lab
from ..model import Texels
from .noise import (
    ESTIMATE_RANGE,
    PILOT_SPP,
    PLAN_MARGIN,
    SEED_STRIDE,
    SSIM_NOISE_RATIO,
    TARGET_NOISE_DE76,
    NoiseModel,
)
from .sample import SAMPLE_SSIM_NOISE_RATIO, TexelSample, sample_size

#: the sample's standard error of the mean ΔE76: the full render's residual after the noise correction
TARGET_STDERR_DE76 = round((ESTIMATE_RANGE[1] - 1.0) * TARGET_NOISE_DE76, 6)
MIN_SAMPLE_TEXELS = 1000
PILOT_TEXELS = 2000  # texels of the pilot, at most a quarter of the scene's
SAMPLE_MIN_GAIN = 2.0  # the sample's predicted time at most 1/this of every texel's
PILOT_SEED_PASS = 32  # the pilot's seed: seed + this x noise.SEED_STRIDE, no pass of a result uses it

#: a pilot render: (texels, spp, seed) -> (rgb (k, 3), var_mean (k, 3)) linear
PilotRender = Callable[[Texels, int, int], tuple]


@dataclass(frozen=True)
class CostModel:
    """What the pilot measured: ``texels`` rendered at ``spp`` in ``seconds``; ``delta_e76_std`` the standard
    deviation of their ΔE76; the samples per texel that every texel (``spp_full``), the sample's points
    (``spp_points``) and its window texels (``spp_windows``) are predicted to need."""

    texels: int
    spp: int
    seconds: float
    delta_e76_std: float
    spp_full: int
    spp_points: int
    spp_windows: int

    @property
    def seconds_per_texel_sample(self) -> float:
        return self.seconds / max(self.texels * self.spp, 1)

    @classmethod
    def of_pilot(cls, rgb, var, target_lab, seconds: float, spp: int, fixed_spp: int | None, max_spp: int, cmap=RGB):
        """The cost model of a pilot render (rgb, var (k, C) channel values of colour map ``cmap``, default linear
        sRGB; its targets (k, 3) CIELAB) at ``spp``; ``fixed_spp``: the evaluation's fixed samples (None: adaptive,
        capped at ``max_spp``)."""
        rgb, var = np.asarray(rgb, np.float64), np.asarray(var, np.float64)
        de = delta_e76(linear_to_lab(rgb) if cmap is RGB else cmap.lab(rgb), target_lab)
        std = float(de.std(ddof=1)) if len(de) > 1 else 0.0
        if fixed_spp is not None:
            return cls(len(rgb), spp, seconds, std, fixed_spp, fixed_spp, fixed_spp)
        model = NoiseModel.of(rgb, var, target_lab, cmap)
        target = PLAN_MARGIN * TARGET_NOISE_DE76
        full = model.spp_for(spp, target, max_spp, PLAN_MARGIN * SSIM_NOISE_RATIO)
        windows = model.spp_for(spp, math.inf, max_spp, PLAN_MARGIN * SAMPLE_SSIM_NOISE_RATIO)
        return cls(len(rgb), spp, seconds, std, full, full, windows)  # the points as every texel

    def sample_texels(self, population: int, target: float = TARGET_STDERR_DE76) -> int:
        """Points whose standard error of the mean ΔE76 is ``target`` (finite-population corrected), at least
        ``MIN_SAMPLE_TEXELS``, at most ``population`` (module docstring)."""
        n0 = (self.delta_e76_std / target) ** 2
        n = math.ceil(n0 / (1.0 + n0 / population))
        return int(min(population, max(n, MIN_SAMPLE_TEXELS)))


@dataclass(frozen=True)
class SamplingChoice:
    """Every texel (``sample`` None) or a texel sample, and why: ``forced`` by ``texel_sample``, else predicted from
    the pilot's ``cost`` (``full_seconds`` and ``sample_seconds``: the continuous result's predicted render times;
    ``window_texels``: those of the sample drawn for the prediction, whether taken or not; ``target``: the sample's
    standard error of the mean ΔE76)."""

    sample: TexelSample | None
    forced: bool
    cost: CostModel | None = None
    population: int = 0
    window_texels: int = 0
    full_seconds: float | None = None
    sample_seconds: float | None = None
    target: float = TARGET_STDERR_DE76

    @property
    def name(self) -> str:
        return "every texel" if self.sample is None else "texel sample"

    def to_json(self) -> dict:
        """evaluation.json's ``sampling_choice``."""
        d = {"choice": self.name, "forced": self.forced}
        if self.cost is None:
            return d
        c = self.cost
        return {
            **d,
            "target_stderr_delta_e76": self.target,
            "min_gain": SAMPLE_MIN_GAIN,
            "predicted_for": "continuous",
            "pilot": {"texels": c.texels, "spp": c.spp, "seconds": c.seconds, "delta_e76_std": c.delta_e76_std},
            "every_texel": {"texels": self.population, "spp": c.spp_full, "seconds": self.full_seconds},
            "sample": {
                "texels": c.sample_texels(self.population, self.target),
                "window_texels": self.window_texels,
                "spp": c.spp_points,
                "spp_windows": c.spp_windows,
                "seconds": self.sample_seconds,
            },
        }

    def describe(self) -> str:
        """One log line: the choice and, when predicted, both predictions."""
        if self.cost is None:
            return f"sampling: {self.name} (as asked)"
        c = self.cost
        return (
            f"sampling: {self.name}; predicted for the continuous result: every texel ({self.population} x "
            f"{c.spp_full} spp) {self.full_seconds:.0f} s, a sample ({c.sample_texels(self.population, self.target)} "
            f"texels x {c.spp_points} spp + SSIM windows x {c.spp_windows} spp; dE76 standard error {self.target:g}) "
            f"{self.sample_seconds:.0f} s (pilot: {c.texels} texels x {c.spp} spp in {c.seconds:.1f} s)"
        )


def predict(
    cost: CostModel,
    texels: Texels,
    windows: int | None,
    seed: int,
    target: float = TARGET_STDERR_DE76,
) -> SamplingChoice:
    """The choice between every texel of ``texels`` and a sample (``windows`` SSIM windows, None: the default;
    drawn with ``seed``; its mean ΔE76's standard error ``target``) from a pilot's ``cost`` (module docstring)."""
    population = len(texels)
    n, m = sample_size(cost.sample_texels(population, target), windows, population)
    sample = TexelSample.draw(texels, n, m, seed)
    per = cost.seconds_per_texel_sample
    full = population * cost.spp_full * per
    part = (n * cost.spp_points + len(sample.windows) * cost.spp_windows) * per
    take = n < population and part * SAMPLE_MIN_GAIN <= full
    return SamplingChoice(sample if take else None, False, cost, population, len(sample.windows), full, part, target)


def pilot(
    render: PilotRender, texels: Texels, target_lab, spp: int | None, max_spp: int, seed: int, cmap=RGB
) -> CostModel:
    """``CostModel`` of a pilot render through ``render`` on ``PILOT_TEXELS`` random texels of ``texels`` (at most a
    quarter, at least 2), targets ``target_lab`` (I, 3) CIELAB; ``spp``: the evaluation's fixed samples (None:
    adaptive); ``cmap``: the colour map of the render's channels."""
    k = min(len(texels), max(2, min(PILOT_TEXELS, len(texels) // 4)))
    rows = np.sort(np.random.default_rng([int(seed), PILOT_SEED_PASS]).choice(len(texels), k, replace=False))
    pilot_spp = PILOT_SPP if spp is None else min(int(spp), PILOT_SPP)
    t0 = time.perf_counter()
    rgb, var = render(texels.subset(rows), pilot_spp, int(seed) + PILOT_SEED_PASS * SEED_STRIDE)
    seconds = time.perf_counter() - t0
    return CostModel.of_pilot(rgb, var, np.asarray(target_lab)[rows], seconds, pilot_spp, spp, max_spp, cmap)


def choose_sampling(
    render: PilotRender,
    texels: Texels,
    target_lab,
    options,
    seed: int,
    cmap=RGB,
    target: float = TARGET_STDERR_DE76,
) -> SamplingChoice:
    """Every texel or a texel sample as ``options`` (``EvaluateOptions``: ``texel_sample``, ``sample_windows``,
    ``spp``, ``max_spp``) ask: forced by ``texel_sample``, else predicted from a pilot through ``render`` (module
    docstring) for a sample whose mean ΔE76 has standard error ``target``. ``seed``: the evaluation's render seed
    (the sample is drawn with it)."""
    o = options
    if o.texel_sample is not None:
        n, m = sample_size(o.texel_sample, o.sample_windows, len(texels))
        return SamplingChoice(TexelSample.draw(texels, n, m, seed) if n else None, True)
    cost = pilot(render, texels, target_lab, o.spp, o.max_spp, seed, cmap)
    return predict(cost, texels, o.sample_windows, seed, target)
