"""Tests of inkopt.evaluation.noise: the Monte Carlo inflation of a mean ΔE76, its estimate and adaptive spp, on
synthetic colours with Gaussian noise of known variance in linear RGB (the noise-free figures are known)."""

import numpy as np
import pytest

from inkopt.color import delta_e76, linear_to_lab
from inkopt.evaluation.noise import (
    ESTIMATE_RANGE,
    SEED_STRIDE,
    SSIM_NOISE_RATIO,
    TARGET_NOISE_DE76,
    NoiseModel,
    Sampling,
    adaptive_render,
    chi3_mean,
)

I = 20000  # noqa: E741 (I is the texel count throughout the package)


def synthetic(err: float, seed: int = 1):
    """Targets t and noise-free predictions c (linear RGB, I x 3): c = t times log-normal errors of size err."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(0.02, 0.9, (I, 3))
    c = np.clip(t * np.exp(rng.normal(0, err, (I, 3))), 1e-3, 1)
    return t, c


def noisy(c, var, rng):
    return np.maximum(c + np.sqrt(var) * rng.standard_normal(c.shape), 1e-4)


def test_chi3_mean_against_sampling():
    """g(λ) = E|λ e + z| (noncentral chi, 3 d.o.f.) against 200 000 samples: within 4 standard errors."""
    rng = np.random.default_rng(0)
    for lam in (0.0, 0.5, 1.0, 2.0, 5.0):
        z = rng.standard_normal((200_000, 3))
        z[:, 0] += lam
        r = np.linalg.norm(z, axis=1)
        assert abs(r.mean() - chi3_mean(lam)) < 4 * r.std() / np.sqrt(len(r))
    assert chi3_mean(0.0) == pytest.approx(2 * np.sqrt(2 / np.pi))
    assert chi3_mean(1e6) - 1e6 == pytest.approx(1e-6, rel=1e-3)  # g(λ) - λ → 1/λ


@pytest.mark.parametrize("err", [0.0, 0.05, 0.2])
@pytest.mark.parametrize("rel", [0.02, 0.05, 0.1])
def test_estimate_within_stated_range(err, rel):
    """The estimated inflation of the mean ΔE76 is within ESTIMATE_RANGE of the true one (raw mean - noise-free
    mean, up to 4 standard errors of the raw mean's own sampling noise) for noise adding ~0.07-6.5 ΔE76."""
    t, c = synthetic(err)
    lab_t = linear_to_lab(t)
    truth = delta_e76(linear_to_lab(c), lab_t).mean()
    var = np.full((I, 3), 1.0) * (rel * c) ** 2
    ch = noisy(c, var, np.random.default_rng(2))
    de = delta_e76(linear_to_lab(ch), lab_t)
    infl = de.mean() - truth
    slack = 4 * (de - delta_e76(linear_to_lab(c), lab_t)).std() / np.sqrt(I)
    est = NoiseModel.of(ch, var, lab_t).contribution()
    lo, hi = ESTIMATE_RANGE
    assert lo * infl - slack <= est <= hi * infl + slack, (infl, est)


def fake_renderer(c, var1, calls):
    """A render of noise-free colours c with per-sample variance var1: the mean of n samples has variance var1/n;
    the seed picks the noise (a different seed per pass: independent passes)."""

    def render(n, seed):
        calls.append((n, seed))
        rng = np.random.default_rng(seed % 2**32 + seed // SEED_STRIDE)
        v = var1 / n
        return noisy(c, v, rng), v, n

    return render


def test_adaptive_render_reaches_target_and_is_near_noise_free():
    """Per-sample noise that adds ~6 ΔE76 at 64 spp: the adaptive render raises spp until the estimated
    contribution is below the target; the raw mean is then within target x (upper end of ESTIMATE_RANGE) of the
    noise-free mean (the estimate may be low by that factor), plus 4 standard errors."""
    t, c = synthetic(0.2)
    lab_t = linear_to_lab(t)
    truth = delta_e76(linear_to_lab(c), lab_t)
    var1 = 64 * (0.1 * c) ** 2
    calls = []
    ad = adaptive_render(fake_renderer(c, var1, calls), lab_t, Sampling(seed=7))
    assert ad.noise <= TARGET_NOISE_DE76
    assert ad.spp == sum(ad.passes) and len(calls) == len(ad.passes) >= 2
    assert len({s for _, s in calls}) == len(calls)  # independent seeds
    np.testing.assert_allclose(ad.var, var1 / ad.spp, rtol=1e-12)  # pooled variance = that of spp samples
    de = delta_e76(linear_to_lab(ad.rgb), lab_t)
    slack = 4 * (de - truth).std() / np.sqrt(I)
    assert de.mean() - truth.mean() <= TARGET_NOISE_DE76 / ESTIMATE_RANGE[0] + slack
    assert abs(de.mean() - ad.noise - truth.mean()) <= (ESTIMATE_RANGE[1] - 1) * ad.noise + slack
    # the plan is not wasteful: half the samples would not have reached both targets
    half = NoiseModel.of(ad.rgb, 2 * ad.var, lab_t)
    assert half.contribution() > 0.9 * TARGET_NOISE_DE76 * 0.9 or half.ssim_ratio > 0.9 * SSIM_NOISE_RATIO * 0.9


def test_adaptive_render_samples_until_ssim_noise_is_small():
    """Errors far above the noise (ΔE76 target met by the pilot) but noise variance comparable to SSIM's K2: the
    adaptive render goes on until the SSIM noise ratio is at most SSIM_NOISE_RATIO (r scales as 1/spp, so the
    planned spp hits it in one round), and not far beyond it."""
    t, c = synthetic(1.5)
    lab_t = linear_to_lab(t)
    var1 = 64 * (0.08 * c) ** 2
    pilot = NoiseModel.of(c, var1 / 64, lab_t)
    assert pilot.contribution() <= TARGET_NOISE_DE76 and pilot.ssim_ratio > 2 * SSIM_NOISE_RATIO
    ad = adaptive_render(fake_renderer(c, var1, []), lab_t, Sampling(seed=3))
    final = NoiseModel.of(ad.rgb, ad.var, lab_t)
    assert final.ssim_ratio <= SSIM_NOISE_RATIO < NoiseModel.of(ad.rgb, 2 * ad.var, lab_t).ssim_ratio
    # r is the largest channel's mean per-texel variance of normalised L*a*b* over K2, ∝ 1/spp
    np.testing.assert_allclose(NoiseModel.of(c, var1 / 640, lab_t).ssim_ratio, pilot.ssim_ratio / 10, rtol=1e-9)


def test_explicit_spp_is_exact_and_cap_holds():
    t, c = synthetic(0.05)
    calls = []
    ad = adaptive_render(fake_renderer(c, (0.1 * c) ** 2 * 64, calls), linear_to_lab(t), Sampling(spp=32))
    assert calls == [(32, 0)] and ad.spp == 32
    calls = []
    ad = adaptive_render(fake_renderer(c, (0.1 * c) ** 2 * 1e6, calls), linear_to_lab(t), Sampling(max_spp=256))
    assert ad.spp == 256 and ad.noise > TARGET_NOISE_DE76 and calls[0][0] == 64


def test_spp_for_takes_the_larger_of_both_requirements():
    """spp_for plans for whichever rule needs more samples: the ΔE76 contribution (bisection, r set to 0) or the
    SSIM noise ratio (r ∝ 1/spp: ceil(spp r / ratio))."""
    from dataclasses import replace

    t, c = synthetic(0.2)
    model = NoiseModel.of(c, (0.1 * c) ** 2, linear_to_lab(t))
    de_only = replace(model, ssim_ratio=0.0)
    n_de = de_only.spp_for(64, 0.5, 4096)
    assert de_only.contribution(64 / n_de) <= 0.5 < de_only.contribution(64 / (0.95 * n_de))
    assert replace(model, ssim_ratio=1.0).spp_for(64, 1e9, 4096) == 640
    assert replace(model, ssim_ratio=1.0).spp_for(64, 0.5, 4096) == max(640, n_de)
    assert replace(model, ssim_ratio=100.0).spp_for(64, 0.5, 4096) == 4096  # the cap


def test_ssim_ratio_matches_sampled_noise():
    """r is the largest channel's mean variance of normalised L*a*b* over K2: against sampled small noise."""
    from inkopt.color import normalise_lab
    from inkopt.loss import K2

    t, c = synthetic(0.2)
    c, t = c[:2000], t[:2000]
    var = (0.01 * c) ** 2
    rng = np.random.default_rng(5)
    samples = np.stack(
        [normalise_lab(linear_to_lab(c + np.sqrt(var) * rng.standard_normal(c.shape))) for _ in range(400)]
    )
    empirical = samples.var(0).mean(0).max() / K2
    # 400 draws x 2000 texels: the sampled mean variance's relative standard error is ~0.2 %; 5 % leaves room for
    # the delta method's curvature error at 1 % noise, but not for a wrong channel scale (1/100 vs 1/255: 6.5x)
    np.testing.assert_allclose(NoiseModel.of(c, var, linear_to_lab(t)).ssim_ratio, empirical, rtol=0.05)


def test_time_budget_caps_the_samples_and_passes_say_their_time():
    """A render that costs 10 ms per sample per texel and noise that would need well over 1000 spp: with a 3 s budget
    the pilot (a 4-spp probe that times the samples, then 60 more: 0.64 s) leaves room for 236 more, which is what
    is rendered; the result says it was capped, and the log line gives the pass's expected time."""
    t, c = synthetic(0.05)
    now = [0.0]
    render = fake_renderer(c, (0.1 * c) ** 2 * 1e6, [])

    def timed(n, seed):
        now[0] += 0.01 * n
        return render(n, seed)

    lines = []
    ad = adaptive_render(timed, linear_to_lab(t), Sampling(time_budget=3.0), log=lines.append, clock=lambda: now[0])
    assert ad.passes == [4, 60, 236] and ad.spp == 300 and ad.capped and ad.noise > TARGET_NOISE_DE76
    assert now[0] <= 3.0 + 1e-9
    assert "236 more, ~2 s (capped)" in lines[0]
    free = adaptive_render(timed, linear_to_lab(t), clock=lambda: now[0])
    assert free.spp > 1000  # without the budget it would have gone on


def test_time_budget_below_the_pilot_keeps_to_it():
    """A budget smaller than the 64-spp pilot's time: the 4-spp probe times the samples and the pilot stops at what
    fits (0.4 s at 10 ms per sample: 40 spp in all), and the result says it was capped."""
    t, c = synthetic(0.05)
    now = [0.0]
    render = fake_renderer(c, (0.1 * c) ** 2 * 1e6, [])

    def timed(n, seed):
        now[0] += 0.01 * n
        return render(n, seed)

    ad = adaptive_render(timed, linear_to_lab(t), Sampling(time_budget=0.4), clock=lambda: now[0])
    assert ad.passes == [4, 36] and ad.spp == 40 and ad.capped and now[0] <= 0.4 + 1e-9


@pytest.mark.parametrize(
    "kw,name",
    [
        ({"spp": 0}, "spp"),
        ({"max_spp": 0}, "max_spp"),
        ({"pilot_spp": 0}, "pilot_spp"),
        ({"time_budget": -1}, "time_budget"),
        ({"time_budget": float("nan")}, "time_budget"),
        ({"target": 0}, "target"),
        ({"ratio": -1.0}, "ratio"),
    ],
)
def test_sampling_names_the_bad_parameter(kw, name):
    from inkopt.errors import ParameterError

    with pytest.raises(ParameterError) as exc:
        Sampling(**kw)
    assert exc.value.parameters == (name,)
    Sampling(time_budget=0.0, target=float("inf"), ratio=float("inf"))  # no budget left, no target: allowed
