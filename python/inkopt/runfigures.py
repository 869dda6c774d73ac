"""A run's figures (``RunFigures``): the start's, a baseline's and the result's renders with seeds unused by the
optimisation, their time budgets within a run's time budget (``figure_budgets``), and the choice of the result's
finishing smoothing (``evaluation.finish``), whose render of the chosen candidate is the result's figures' first
pass.

The figures are of every texel, or of a texel sample (``evaluation.sample``): the sample where a short pilot before
the start's figures predicts it at least twice as fast for a mean ΔE76 whose standard error is ``START_STDERR_DE76``
(``evaluation.choice.choose_sampling``; no pilot where no sample could be; ``RunOptions.figure_texel_sample`` forces
either). The start and the baseline (and the result, below) are then measured on the same texels, drawn with the
figures' seed; a resumed run takes the sample its start's figures recorded. The figures' texels then grow with
their spread, not with the object's surface (docs/quality.md, "The run's own check against the extrusion
baseline").

The start's and the baselines' figures: every texel's in one pilot pass (``noise.PILOT_SPP`` samples per texel at
most); a sample's in the time every texel's pass was predicted to take, adaptive to ``inkopt evaluate``'s noise
targets beyond the pilot (a forced sample: one pilot pass); under a time budget both get what fits its share. The
result's figures: adaptive within their share of the run's budget, or without one ``FINAL_FIGURES_SHARE`` of the
run's time; on the sample where it is far smaller than the texels (``RESULT_SAMPLE_MIN_GAIN``), within
``RESULT_SAMPLE_SHARE`` of that time, the finishing choice rendering the sample's points, and every texel is then
rendered in the time left for the pictures and predictions.npz, which need every texel (``ResultFigures.pictures``)."""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import NamedTuple

from .evaluation.choice import MIN_SAMPLE_TEXELS, SAMPLE_MIN_GAIN, SamplingChoice, choose_sampling
from .evaluation.finish import FinishChoice, choice_seconds, choose_finish, iteration_seconds_per_spp
from .evaluation.guard import figure_error, kept_figures, sampled_error
from .evaluation.lights import sampled_light_figures
from .evaluation.metrics import Metrics, prediction_metrics
from .evaluation.noise import (
    EVAL_SEED_OFFSET,
    PILOT_SPP,
    PROBE_SPP,
    AdaptiveResult,
    Sampling,
    adaptive_render,
    first_pass,
)
from .evaluation.renders import TimeShares, render_result, texel_groups
from .evaluation.sample import (
    DEFAULT_SAMPLE_WINDOWS,
    SIGMA,
    TexelSample,
    per_texel,
    sample_size,
    sampled_figures,
)
from .loss import TexelLoss
from .optim import OptimizeConfig

#: Shares of a run's time budget (``OptimizeConfig.time_budget``) given to the start's figures (as much again to the
#: baseline's: ``evaluation.guard``), the result's figures, and kept for writing the result (volume, pictures,
#: predictions, report): the iterations get the rest,
#: the step decay planned to end in time (``optim.stopping``). Not measured optima: the figures are informative
#: and noise-corrected at any spp (their noise is reported), the quality is the iterations'. The figures' shares are
#: of the time left when the run's set-up ends (a coarse-to-fine job's fine stage: what the coarse stage left it),
#: the writing's of the whole budget (it scales with the object, not with the time left).
BUDGET_START_FIGURES, BUDGET_FINAL_FIGURES, BUDGET_WRITING = 0.03, 0.08, 0.04
#: Without a budget, the result's figures add samples beyond the pilot only while they take at most this share of
#: the run's time so far: on a mesh noise-free figures take hundreds of samples per texel where an iteration renders
#: 20 (Spot 20 mm: 553 spp, experiments/results/mesh_convergence.json, entry ``spot20_smooth3_60``). The noise left
#: is corrected for and reported; `inkopt evaluate` measures the printed result against the baselines without noise.
FINAL_FIGURES_SHARE = 0.25
#: the standard error (ΔE76) of the start's and baselines' mean ΔE76 when they are measured on a texel sample: a
#: third of ``evaluation.choice.TARGET_STDERR_DE76``, so that the sampling adds little to the figures' uncertainty,
#: the noise correction's above all (Spot 100 mm, 13 960 points: 0.16 of 0.20 ΔE76 at 1107 spp, 1.09 of 1.15 at 64)
START_STDERR_DE76 = 0.05
#: the share of the result's figures' time (``FINAL_FIGURES_SHARE`` or their budget) their render on a texel sample
#: may take; every texel's render for the pictures and predictions.npz gets what it leaves. Spot 100 mm under a 2-h
#: budget: in 288 s of it the sample's points reached 551 spp, where the noise adds 0.73 to the mean ΔE76, and every
#: texel's render 8 spp in the rest (docs/quality.md)
RESULT_SAMPLE_SHARE = 0.5
#: the result's figures are of the run's texel sample (unless the user asked for it) only where its texels, points
#: and windows, are at most 1 / this of every texel: in half of the figures' time the sample's texels then get at
#: least 8 times the samples every texel's would, where the pictures' render gives up half. Spot 100 mm: 25 947 of
#: 2.43 M texels (94 times fewer), the figures 8.15 ± 0.30 ΔE76 at 551 spp against 12.42 ± 3.21 at 10 over every
#: texel, the pictures 8 spp against 10; Spot 20 mm under a 5-minute deadline: 28 174 of 96 002 (3.4), the
#: figures ± 2.30 at 21 spp and the pictures 4 spp, against ± 2.76 and 13 spp over every texel (docs/quality.md,
#: "The figures from a texel sample")
RESULT_SAMPLE_MIN_GAIN = 16


@dataclass(frozen=True)
class ResultFigures:
    """The result's figures (``RunFigures.final``): ``metrics`` (``Metrics``, CIELAB under the first light) of
    ``render`` (``AdaptiveResult``: of every texel, or of the texel sample's points), the uncertainty ``error``
    (ΔE76) of their noise-corrected mean ΔE76 (``evaluation.guard``), their ``sample`` (None: every texel; else
    {"sample": ``TexelSample.to_json()``, "stderr": the figures' standard errors by name}), and ``pictures``:
    the render of every texel that the pictures and predictions.npz show (``render`` itself without a sample);
    ``by_light``: a spectral run's figures under each light on the texel sample, with their standard errors
    (``evaluation.lights.sampled_light_figures``; None: every texel's, from ``pictures``, or not spectral)."""

    metrics: Metrics
    render: AdaptiveResult
    error: float
    sample: dict | None
    pictures: AdaptiveResult
    by_light: dict | None = None


class _Ask(NamedTuple):
    """What ``choose_sampling`` reads of an evaluation's options, for the start's and baselines' figures."""

    texel_sample: int | None
    spp: int | None
    max_spp: int
    sample_windows: int | None = None


def figure_budgets(cfg: OptimizeConfig, eval_time_budget: float | None, elapsed: float = 0.0) -> tuple:
    """(start's, result's) time budget of the adaptive figures in seconds, or None: the user's
    ``eval_time_budget``, within the shares of what is left of the run's time budget (if it has one) after
    ``elapsed`` seconds (the job's time so far)."""
    if cfg.time_budget is None:
        return eval_time_budget, eval_time_budget
    cap = float("inf") if eval_time_budget is None else eval_time_budget
    left = max(cfg.time_budget - elapsed, 0.0)
    return min(cap, BUDGET_START_FIGURES * left), min(cap, BUDGET_FINAL_FIGURES * left)


def _sample_can_win(texels, seed: int) -> bool:
    """Whether a texel sample of the fewest points (``choice.MIN_SAMPLE_TEXELS``) and the default SSIM windows holds
    at most 1 / ``choice.SAMPLE_MIN_GAIN`` of ``texels`` (the pilot's prediction compares one 64-spp pass of each):
    else no pilot can choose a sample."""
    population = len(texels)
    if population < SAMPLE_MIN_GAIN * MIN_SAMPLE_TEXELS:
        return False
    smallest = TexelSample.draw(texels, MIN_SAMPLE_TEXELS, DEFAULT_SAMPLE_WINDOWS, seed)
    return SAMPLE_MIN_GAIN * (len(smallest.points) + len(smallest.windows)) <= population


class RunFigures:
    """A run's figures: renders with seeds unused by the optimisation (``EVAL_SEED_OFFSET + seed``), the user's
    samples per texel or adaptive ones (at most ``eval_max_spp`` and ``eval_time_budget`` seconds per result). The
    run's own renderer, set to a mixture (only the free voxels change: no grid-sized volume), renders exactly what
    a renderer built from that volume would. ``job``: the run driver's job (its ``run``, ``scene``, ``cfg`` and
    ``options``)."""

    def __init__(self, job):
        self.job = job
        self.spp = int(job.options.eval_spp) if job.options.eval_spp else None  # None: adaptive
        self.seed = EVAL_SEED_OFFSET + job.cfg.seed
        budgets = figure_budgets(job.cfg, job.options.eval_time_budget, job.run.wall_seconds())
        self.start_budget, self.final_budget = budgets
        self.overshoot = 0.0  # the most seconds a start's or baseline's figures took beyond their budget
        self.per_spp = None  # seconds per sample per texel of the latest start's or baseline's figures
        self.replay = None  # the result's first pass, rendered by the finishing choice (``evaluation.finish.Replay``)
        self.choice = None  # the start's and baselines' choice of a texel sample (``evaluation.choice.SamplingChoice``)

    def _pass(self, renderer, n: int, s: int, texels=None):
        """One render pass of the scene's texels (or of ``texels``, some of them): (rgb, var_mean, n)."""
        opts, cfg = self.job.options, self.job.cfg
        texels = self.job.scene.texels if texels is None else texels
        r = renderer.render(texels, n, s, cfg.include_specular, opts.progress)
        return r.rgb, r.var_mean, n

    def _sampling(self, budget, max_spp: int, pilot_in_budget: bool = True) -> Sampling:
        return Sampling(
            seed=self.seed, spp=self.spp, max_spp=max_spp, time_budget=budget, pilot_in_budget=pilot_in_budget
        )

    def _of(self, x, sampling: Sampling, keep_renderer=True, replay=None, held: list | None = None, measure=True):
        """(``AdaptiveResult``, ``Metrics`` or without ``measure`` None) of every texel's render of the mixture of
        variables ``x`` (None: the current ones); ``replay``: a pass rendered already (``evaluation.finish.Replay``);
        ``held``: a one-item list of the run's renderer set to ``x`` already, taken out of it (so that releasing the
        renderer frees it)."""
        run, opts = self.job.run, self.job.options
        renderer = held.pop() if held else run.renderer(x)

        def render(n: int, s: int):
            return self._pass(renderer, n, s)

        res = adaptive_render(
            render if replay is None else replay.render(render),
            run.loss.target_lab,
            sampling,
            log=opts.log,
            clock=None if replay is None else replay.clock,  # the replayed pass's seconds count as spent
            cmap=run.loss.colours[0],  # a spectral run's headline light
        )
        if not keep_renderer:  # its media are not needed beside the loss's window operators that the figures build
            del renderer, render
            run.release_renderer()
        if not measure:
            return res, None
        return res, prediction_metrics(run.loss, res.rgb, res.var)  # CIELAB under the first light

    def start(self, x=None, keep_renderer: bool | None = None) -> dict:
        """The start's figures (one pilot pass at most, of every texel or of the texel sample: module docstring) as
        ``Optimization.keep_start_figures`` keeps them (``evaluation.guard.kept_figures``); ``x``: other variables
        than the current ones (the start's when the run is no longer at its start, a baseline's); the renderer is
        kept if ``keep_renderer`` (None: without ``x``)."""
        max_spp = min(self.job.options.eval_max_spp, PILOT_SPP)
        keep = x is None if keep_renderer is None else keep_renderer
        t0 = time.perf_counter()
        held = [self.job.run.renderer(x)]  # set once; the step that ends with it takes it out
        if self.choice is None:
            self._choose_sample(held[0], max_spp)
        t = time.perf_counter()
        if self.choice.sample is None:
            res, m = self._of(x, self._sampling(self.start_budget, max_spp), keep_renderer=keep, held=held)
            kept = kept_figures(m, res.spp, len(self.job.scene.texels))
            self.per_spp = (time.perf_counter() - t) / max(res.spp, 1)
        else:
            self.per_spp, kept = self._sampled(held, max_spp, keep)
        if self.start_budget is not None:
            self.overshoot = max(self.overshoot, time.perf_counter() - t0 - self.start_budget)
        return kept

    def _choose_sample(self, renderer, max_spp: int) -> None:
        """The start's and baselines' choice of a texel sample (``self.choice``; module docstring): the start's
        sample again when the run kept its figures (a resumed run), every texel when no sample can be at least
        ``SAMPLE_MIN_GAIN`` times smaller than the texels, else by a pilot through
        ``renderer`` (the run's, set to the first figures' mixture). Logged when a sample is taken."""
        job, loss = self.job, self.job.run.loss
        texels, ask = job.scene.texels, _Ask(job.options.figure_texel_sample, self.spp, max_spp)
        kept = self._kept_sample()
        if kept is not None:  # measured on this sample: the baseline and the result on it too
            self.choice = SamplingChoice(kept, False)
            return
        if ask.texel_sample is None and not _sample_can_win(texels, self.seed):
            self.choice = SamplingChoice(None, False)
            return

        def pilot(part, n: int, s: int):
            return self._pass(renderer, n, s, part)[:2]

        cmap = loss.colours[0]
        self.choice = choose_sampling(pilot, texels, loss.target_lab, ask, self.seed, cmap, START_STDERR_DE76)
        s, c = self.choice.sample, self.choice
        if s is not None:
            why = "as asked" if c.forced else f"predicted {c.sample_seconds:.0f} s against {c.full_seconds:.0f} s"
            job.options.log(
                f"the run's figures: a texel sample of {len(s.points)} of {s.population} texels and "
                f"{len(s.centres)} SSIM windows ({len(s.windows)} texels; {why} for every texel)"
            )

    def _kept_sample(self) -> TexelSample | None:
        """The texel sample the run's start figures were measured on (a resumed run's, redrawn), unless the user
        asks for a sample of their own (``RunOptions.figure_texel_sample``); None: none kept."""
        kept = ((self.job.run.start_figures or {}).get("texel_sample") or {}).get("sample")
        if kept is None or self.job.options.figure_texel_sample is not None:
            return None
        return TexelSample.draw(self.job.scene.texels, kept["texels"], kept["windows"], kept["seed"])

    def _result_sample(self) -> TexelSample | None:
        """The texel sample of the result's figures: the start's and baseline's (``self.choice``, decided by
        ``start``), else the one the run's start figures were measured on, else the user's (``RunOptions.
        figure_texel_sample``: no pilot is spent at the end of a run); None: every texel, also where the sample is
        not ``RESULT_SAMPLE_MIN_GAIN`` times smaller than the texels and the user did not ask for it (undecided: the
        start's figures of an older checkpoint, measured after the result's, still choose)."""
        if self.choice is None:
            n = self.job.options.figure_texel_sample
            kept, texels = self._kept_sample(), self.job.scene.texels
            if kept is None and n:
                kept = TexelSample.draw(texels, *sample_size(n, None, len(texels)), self.seed)
            if kept is None:
                return None
            self.choice = SamplingChoice(kept, n is not None)
        s = self.choice.sample
        if s is None or self.choice.forced:
            return s
        return s if RESULT_SAMPLE_MIN_GAIN * (len(s.points) + len(s.windows)) <= s.population else None

    def _sampled(self, held: list, max_spp: int, keep_renderer: bool) -> tuple:
        """(seconds per sample per texel of every texel, the kept figures) of the run's renderer (``held``, as
        ``_of`` takes it) on the texel sample (``_sample_figures``): at most ``max_spp`` samples per texel, or, for
        a sample a pilot chose, adaptive ones (to ``inkopt evaluate``'s noise targets, at most ``eval_max_spp``)
        within the time its prediction gave every texel's pass (and the figures' budget)."""
        c, budget = self.choice, self.start_budget
        if not c.forced and c.full_seconds is not None:  # chosen by a pilot: as long as every texel would take
            budget = c.full_seconds if budget is None else min(budget, c.full_seconds)
            max_spp = self.job.options.eval_max_spp
        per_spp, points, m, err, _ = self._sample_figures(held.pop(), self._sampling(budget, max_spp), keep_renderer)
        taken = {"sample": c.sample.to_json(), "stderr": err, "choice": c.to_json()}
        return per_spp, kept_figures(m, points.spp, c.sample.population, taken)

    def _sample_figures(self, renderer, sampling: Sampling, keep_renderer: bool, replay=None, lights=False) -> tuple:
        """(seconds per sample per texel of every texel, the points' ``AdaptiveResult``, ``Metrics``, their standard
        errors by name, and with ``lights`` a spectral run's figures under each light or else None) of ``renderer``
        (the run's, set to the figures' mixture) on the texel sample's points and window texels
        (``evaluation.sample``), under the run's first colour map (``evaluation.lights.sampled_light_figures`` under
        each), as ``sampling`` asks (its time budget shared by the two groups); ``replay``: the points' first pass
        rendered already (``evaluation.finish.Replay``). The seconds are those of the render passes after the first,
        times the scene's texels (the first pass of a Ray renderer waits for the mixture to reach its workers)."""
        run, opts, scene, loss = self.job.run, self.job.options, self.job.scene, self.job.run.loss
        sample = self.choice.sample
        groups = texel_groups(scene.texels, loss.target_lab, sample)
        passes = []  # (seconds, texel-samples) of each render pass

        def rendered(n: int, s: int, group: int = 0):
            t = time.perf_counter()
            out = self._pass(renderer, n, s, groups[group].texels)
            passes.append((time.perf_counter() - t, n * len(groups[group].texels)))
            return out

        first = rendered if replay is None else replay.render(rendered)  # the points' first pass: replayed

        def source(n: int, s: int, group: int = 0):
            return first(n, s) if group == 0 else rendered(n, s, group)

        clock = time.perf_counter if replay is None else replay.clock  # the replayed pass's seconds count as spent
        shares = TimeShares(sampling.time_budget, clock(), len(groups), clock)
        cmap = loss.colours[0]
        points, windows = render_result(source, groups, sampling, shares, opts.log, cmap, clock)
        timed = passes[1:] or passes
        per_spp = sum(p[0] for p in timed) / max(sum(p[1] for p in timed), 1) * sample.population
        if not keep_renderer:
            del renderer, source, first, rendered
            run.release_renderer()
        on, lights = sample.windows, lights and run.viewing.spectral
        maps = loss.colours if lights else (cmap,)
        window_loss = TexelLoss(loss.target_rgb[on], scene.texels.pos_vox[on], sigma=SIGMA, colours=maps)
        colours = (windows.rgb, windows.var), (points.rgb, points.var)
        if lights:  # every light's figures; the headline's are the first light's
            names = tuple(light.name for light in run.viewing.seen_under())
            by_light, values = sampled_light_figures(window_loss, *colours, groups[0].target_lab, sample, names)
            m, err = sampled_figures(window_loss.under(0), values[0], sample)
            return per_spp, points, m, err, by_light
        values = per_texel(window_loss, *colours, groups[0].target_lab, sample)
        m, err = sampled_figures(window_loss, values, sample)
        return per_spp, points, m, err, None

    def final_reserve(self) -> float | None:
        """Seconds the result's figures are expected to take: their budget plus the most the start's and the
        baseline's figures took beyond theirs (a renderer set to other variables, the figures' window operators:
        at 20 mm 6-13 s on the mesh suite's solids, about as much as the result's figures overran theirs)."""
        return None if self.final_budget is None else self.final_budget + self.overshoot

    def choice_reserve(self) -> float:
        """Seconds the finishing choice takes beyond the result's figures (``evaluation.finish.choice_seconds``): one
        render of their first pass (of every texel, or of the texel sample's points), at the start's or baseline's
        figures' measured seconds per sample when this invocation rendered them, and a step."""
        sample = self._result_sample()
        if sample is None:
            spp = first_pass(self._final_sampling())[0]
        else:  # samples per texel of every texel that take as long
            spp = first_pass(self._sample_figures_sampling())[0] * len(sample.points) / sample.population
        return choice_seconds(self.job.run, spp, self.per_spp)

    def _final_seconds(self) -> float:
        """Seconds the result's figures may take without the user's samples per texel: their budget, or without one
        ``FINAL_FIGURES_SHARE`` of the run's time so far."""
        if self.final_budget is not None:
            return self.final_budget
        return FINAL_FIGURES_SHARE * self.job.run.wall_seconds()

    def _final_sampling(self, left: float | None = None) -> Sampling:
        """The samples of the result's render of every texel: the user's samples, or adaptive ones within
        ``_final_seconds``, or the ``left`` seconds the result's figures on the texel sample left of them (this
        render is then the pictures' alone, its pilot within the time; else the pilot is outside it where the run
        has no budget)."""
        max_spp = self.job.options.eval_max_spp
        if self.spp is not None:
            return self._sampling(None, max_spp)
        if left is not None:
            return self._sampling(max(left, 0.0), max_spp)
        return self._sampling(self._final_seconds(), max_spp, pilot_in_budget=self.final_budget is not None)

    def _sample_figures_sampling(self, total: float | None = None) -> Sampling:
        """The samples of the result's figures on the texel sample: the user's samples, or adaptive ones within
        ``RESULT_SAMPLE_SHARE`` of ``total`` seconds (None: ``_final_seconds``), after a pilot of ``PILOT_SPP`` or,
        under a run budget, of as many as its measured cost fits in that time (``_sample_pilot``)."""
        max_spp = self.job.options.eval_max_spp
        if self.spp is not None:
            return self._sampling(None, max_spp)
        seconds = RESULT_SAMPLE_SHARE * (self._final_seconds() if total is None else total)
        sampling = self._sampling(seconds, max_spp, pilot_in_budget=False)
        return sampling if self.final_budget is None else replace(sampling, pilot_spp=self._sample_pilot(seconds))

    def _sample_pilot(self, seconds: float) -> int:
        """Samples per texel of the pilot of the result's figures on the texel sample under a run budget: as many as
        fit in ``seconds`` at the seconds per sample measured on the start's figures (or on the iterations), from
        ``noise.PROBE_SPP`` to ``PILOT_SPP``. The finishing choice renders the points at the pilot's samples, and its
        paired difference at a 4-spp probe is mostly noise (Spot 100 mm, 13 960 points: -1.40 ± 4.11 on a loss of
        542 at 4 spp, -0.51 ± 0.26 at 64); a 20 mm deadline's whole share fits less than a 64-spp pilot."""
        sample = self.choice.sample
        per_spp = self.per_spp if self.per_spp is not None else iteration_seconds_per_spp(self.job.run)
        if per_spp is None:
            return PROBE_SPP
        pilot_seconds = per_spp * (len(sample.points) + len(sample.windows)) / sample.population
        return int(min(PILOT_SPP, max(PROBE_SPP, seconds // max(pilot_seconds, 1e-12))))

    def choose_finish(self) -> FinishChoice:
        """The result's finishing smoothing where the run's paired render of both candidates says it lowers the loss
        (``evaluation.finish.choose_finish``), on every texel or on the texel sample's points, rendered as the
        result's figures' first pass there, which they then take."""
        run, sample = self.job.run, self._result_sample()
        if sample is None:
            spp, _ = first_pass(self._final_sampling())
            choice, self.replay = choose_finish(run, lambda n, s: self._pass(run.renderer(), n, s), spp, self.seed)
            return choice
        points = self.job.scene.texels.subset(sample.points)
        spp, _ = first_pass(self._sample_figures_sampling())

        def render(n: int, s: int):
            return self._pass(run.renderer(), n, s, points)

        choice, self.replay = choose_finish(run, render, spp, self.seed, sample.points)
        return choice

    def final(self) -> ResultFigures:
        """The result's figures and its render for the pictures (``ResultFigures``): of every texel
        (``_final_sampling``), or of the texel sample (``_sample_figures_sampling``) and then every texel's render
        within the time they left; their first pass the finishing choice's render if it made one."""
        replay, self.replay = self.replay, None
        sample, texels = self._result_sample(), len(self.job.scene.texels)
        if sample is None:
            res, m = self._of(None, self._final_sampling(), keep_renderer=False, replay=replay)
            return ResultFigures(m, res, figure_error(m, texels), None, res)
        clock = time.perf_counter if replay is None else replay.clock  # the replayed pass counts as spent
        t0, total = clock(), self._final_seconds()
        renderer = self.job.run.renderer()
        sampling = self._sample_figures_sampling(total)
        _, points, m, err, by_light = self._sample_figures(renderer, sampling, True, replay, lights=True)
        left = total - (clock() - t0)
        held = [renderer]
        del renderer  # held alone, so that the pictures' render releases it
        pictures, _ = self._of(None, self._final_sampling(left), False, held=held, measure=False)
        taken = {"sample": sample.to_json(), "stderr": err}
        return ResultFigures(m, points, sampled_error(m, err, len(sample.points)), taken, pictures, by_light)
