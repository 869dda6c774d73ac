"""The result's finishing smoothing where the run's own render says it lowers the loss (docs/quality.md, "The
finishing smoothing decided by the run").

One pass of the step's smoothing over a run's last iterate (``Optimization.finish``) removes the voxel-scale variation
under the target's flat texels that the loss barely sees. On some results it also moves those voxels off what the
iterations found (the mesh suite's duck at 10 mm under a plan that smoothed its coarse stage too: +0.74 ± 0.01 ΔE76,
paired), on others it lowers the error (Spot 20 mm after a starved deadline run: -0.43 ± 0.04), on the checker and the
eyeball it is within ±0.1-0.3. With ``OptimizeConfig.finish_smooth`` ``FINISH_AUTO`` (``--finish-smooth auto``)
``choose_finish`` renders both candidates, the iterate and the iterate smoothed once, on the run's texels with the same
seed and samples per texel: those of the first pass of the result's figures (``noise.first_pass``), so that the chosen
candidate's render becomes that pass (``Replay``) and the choice costs one render. The renderer keys its random numbers
by (seed, texel, sample): the two renders share their noise wherever the media are alike, and the paired difference's
error is far below either figure's.

What is compared is the squared colour term, the slabs' default loss, whatever the run's ``colour_term``: the mean over
texels of ΔE76² (under the first light), each texel's noise-corrected (``texel_loss``: minus the trace of its CIELAB
covariance, the square's expected excess from the render's noise). The rule: the smoothing is kept unless dropping it
lowers that mean by more than ``DROP_STDERRS`` standard errors of the paired per-texel difference. Keeping is the
default because the pass buys what the loss does not see (Spot 20 mm: mottle 0.34 -> 0.13 (ΔL*)², SSIM +0.011,
experiments/results/finish_smooth.json) and helped or did nothing in every paired measurement but the duck's, whose
loss from it is many standard errors wide; at 2 standard errors a pass that does not change the loss is dropped in ~2 %
of runs. A run whose pass changes nothing (no flat texels, or no smoothing) renders nothing."""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from ..optim import Optimization

#: passes of the step's smoothing in the smoothed candidate
FINISH_PASSES = 1
#: the smoothing is dropped only where the unsmoothed iterate's loss is lower by more than this many standard errors
DROP_STDERRS = 2.0
#: texels per block of the per-texel loss (its Jacobians: 24 B per texel and channel)
BLOCK = 1 << 16


@dataclass(frozen=True)
class FinishChoice:
    """What a run with ``finish_smooth`` auto returned (report.json's ``finish``): ``smoothed`` (the result is the
    iterate after ``FINISH_PASSES`` passes), ``decision`` ("kept": the pass stays; "dropped": the unsmoothed iterate
    has the lower loss beyond the noise; "unchanged": the pass changes no variable, nothing rendered), the two
    candidates' mean noise-corrected ΔE76² over ``texels`` texels rendered at ``spp`` samples each, their paired
    ``difference`` (unsmoothed - smoothed) and its ``stderr``, and the ``seconds`` the choice took (the smoothing, two
    renders, the losses)."""

    smoothed: bool
    decision: str
    loss_smoothed: float | None = None
    loss_unsmoothed: float | None = None
    difference: float | None = None
    stderr: float | None = None
    spp: int | None = None
    texels: int = 0
    seconds: float = 0.0

    @property
    def passes(self) -> int:
        """Passes of the smoothing in the result."""
        return FINISH_PASSES if self.smoothed else 0

    def to_json(self) -> dict:
        return {"setting": "auto", "passes": self.passes, "rule_stderrs": DROP_STDERRS, **asdict(self)}

    def line(self) -> str:
        """The run's log line on the choice."""
        if self.decision == "unchanged":
            return "finishing smoothing: the pass changes nothing here (no flat texels): nothing to choose"
        what = "kept" if self.smoothed else "dropped (the last iterate is the result)"
        return (
            f"finishing smoothing {what}: loss (mean ΔE76², noise-corrected) {self.loss_smoothed:.2f} smoothed, "
            f"{self.loss_unsmoothed:.2f} not; unsmoothed - smoothed {self.difference:+.2f} ± {self.stderr:.2f} "
            f"(paired, {self.spp} spp on {self.texels} texels; dropped below -{DROP_STDERRS:g} SE), "
            f"{self.seconds:.1f} s"
        )


@dataclass
class Replay:
    """A render pass made already (``spp`` samples per texel at ``seed``: its ``result`` (rgb, var_mean, weight),
    taking ``seconds``), handed to the first call that asks for exactly it (``render``); ``clock`` counts its
    seconds once it is handed over, so that an adaptive render plans its further passes and keeps its time budget as
    if it had rendered the pass itself."""

    spp: int
    seed: int
    result: tuple
    seconds: float
    used: bool = False

    def render(self, render):
        """``render(spp, seed)`` with this pass in place of its first call for (``spp``, ``seed``)."""

        def replayed(n: int, s: int):
            if not self.used and (int(n), int(s)) == (self.spp, self.seed):
                self.used = True
                return self.result
            return render(n, s)

        return replayed

    def clock(self) -> float:
        return time.perf_counter() + (self.seconds if self.used else 0.0)


def texel_loss(loss, rgb, var, rows=None) -> np.ndarray:
    """(I,) float64: each texel's squared ΔE76 of predictions ``rgb`` (I, C) against ``loss``'s target under its first
    colour map (its texels ``rows`` (I,) int64; None: all of them), minus the trace of its CIELAB covariance (from
    the variances of the means ``var`` (I, C)), the square's expected excess from the render's noise."""
    cmap, out = loss.colours[0], np.empty(len(rgb), np.float64)
    target = loss.target_lab if rows is None else loss.target_lab[rows]
    for lo in range(0, len(rgb), BLOCK):
        c, v = np.asarray(rgb[lo : lo + BLOCK], np.float64), np.asarray(var[lo : lo + BLOCK], np.float64)
        err = np.sum((cmap.lab(c) - target[lo : lo + BLOCK]) ** 2, axis=1)
        jac = cmap.lab_jacobian(c)  # (b, 3, C)
        out[lo : lo + BLOCK] = err - np.einsum("ikj,ij,ikj->i", jac, v, jac)
    return out


def paired(smoothed: np.ndarray, plain: np.ndarray) -> tuple[float, float]:
    """(mean, standard error) of the per-texel difference ``plain - smoothed`` (I,)."""
    d = plain - smoothed
    se = float(d.std(ddof=1) / np.sqrt(len(d))) if len(d) > 1 else float("inf")
    return float(d.mean()), se


def decide(difference: float, stderr: float) -> bool:
    """Whether the smoothing stays: unless the unsmoothed iterate's loss is lower by more than ``DROP_STDERRS``
    standard errors."""
    return not difference < -DROP_STDERRS * stderr


def _rows(run: Optimization):
    """The rows of x the smoothing can change (all of them without a guide)."""
    sm = run.smoother
    return slice(None) if sm is None or sm.rows is None else sm.rows


def changes_nothing(run: Optimization) -> bool:
    """Whether the pass cannot change the run's variables: no smoothing, or no free voxel under a flat texel."""
    rows = _rows(run)
    return run.smoother is None or (not isinstance(rows, slice) and len(rows) == 0)


def choice_seconds(run: Optimization, spp: int, per_spp: float | None = None) -> float:
    """Seconds to keep for the choice beyond the result's figures (0 where the pass changes nothing): one render of
    ``spp`` samples per texel (the other is the figures' own first pass) at ``per_spp`` seconds per sample per texel
    (measured on the run's figures; None: the median forward render of its iterations so far per sample, or without
    forward renders its gradient pass's), and one step of the iterations (the median; the smoothing is one of its
    parts)."""
    h = run.history
    if changes_nothing(run) or not h.seconds:
        return 0.0
    per_spp = iteration_seconds_per_spp(run) if per_spp is None else per_spp
    return per_spp * spp + float(np.median(h.step_s))


def iteration_seconds_per_spp(run: Optimization) -> float | None:
    """Seconds per sample per texel of every texel of the run's iterations so far: their median forward render's,
    or without forward renders their gradient pass's; None before any iteration."""
    h = run.history
    if not h.seconds:
        return None
    fwd = run.cfg.forward_spp
    return float(np.median(h.render_s)) / fwd if fwd > 0 else float(np.median(h.gradient_s)) / run.cfg.spp


def choose_finish(run: Optimization, render, spp: int, seed: int, on=None) -> tuple[FinishChoice, Replay | None]:
    """Leave ``run.x`` at its last iterate or that iterate after ``FINISH_PASSES`` passes of the smoothing, whichever
    the paired render says (module docstring). ``render(spp, seed) -> (rgb (I, C), var_mean (I, C), weight)`` renders
    the run's current variables on every texel or on its texels ``on`` (I,) int64, a random sample of them (a
    large object's: ``runfigures``). Returns the choice and the chosen candidate's render as a ``Replay`` (None where
    nothing was rendered)."""
    t0 = time.perf_counter()
    rows = _rows(run)
    if changes_nothing(run):
        return FinishChoice(True, "unchanged", seconds=time.perf_counter() - t0), None
    before = run.x[rows].copy()  # the rows the pass changes: the unsmoothed candidate without a second (F, N) array
    run.finish(FINISH_PASSES)
    if np.array_equal(run.x[rows], before):
        return FinishChoice(True, "unchanged", seconds=time.perf_counter() - t0), None
    t = time.perf_counter()
    smoothed, t_smoothed = render(spp, seed), time.perf_counter() - t
    after = run.x[rows].copy()
    run.x[rows] = before
    del before
    t = time.perf_counter()
    plain, t_plain = render(spp, seed), time.perf_counter() - t
    ls, lu = texel_loss(run.loss, *smoothed[:2], on), texel_loss(run.loss, *plain[:2], on)
    diff, se = paired(ls, lu)
    keep = decide(diff, se)
    if keep:
        run.x[rows] = after
    chosen = Replay(int(spp), int(seed), *((smoothed, t_smoothed) if keep else (plain, t_plain)))
    losses = float(ls.mean()), float(lu.mean())
    seconds = time.perf_counter() - t0
    return FinishChoice(keep, "kept" if keep else "dropped", *losses, diff, se, int(spp), len(ls), seconds), chosen
