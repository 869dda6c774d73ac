"""When a run ends: the end of its step-decay schedule, planned from the trend of the training curve and from a
time budget (``OptimizeConfig.stop_gain``, ``stop_horizon``, ``time_budget``).

A run steps at a constant size and then, over its last ``decay`` fraction, halves the step three times
(``optimizers.step_factor``), so the end must be known before the decay begins. :class:`Schedule` keeps that end
and moves it, before the decay has begun, to the earliest of:

- ``iterations`` (the maximum);
- **converged**: once the training ΔE76 is not expected to fall by more than ``stop_gain`` over the next
  ``stop_horizon`` iterations, the decay begins at once (end = iteration / (1 - decay)). The expectation is the
  least-squares slope of the training ΔE76 over the recent window (the last third of the iterations, at least
  ``WINDOW_MIN``) plus ``Z`` standard errors towards a larger fall: an uncertain trend keeps the run going. The
  standard error allows for the curve's serial correlation (the adjoint's running average and the momentum make
  neighbouring iterations' noise alike): it is inflated by sqrt((1 + rho) / (1 - rho)), rho the residuals' lag-1
  correlation (corrected for its small-sample bias, -(1 + 3 rho) / n for AR(1) noise, and clipped to
  [0, ``RHO_MAX``]). The curves fall ever more slowly, so the recent slope overstates
  what is left to gain: the rule errs towards running longer.
- **time budget**: the last iteration whose end, at the median time of the recent iterations, leaves
  ``reserve`` seconds (the final evaluation and writing; a coarse stage's also its fine stage's predicted cost,
  which depends on the run's own set-up time) within the budget; during the decay the run still
  stops when the next iteration would not fit.

Once the decay has begun the end holds (the decay's stages are fractions of the run's length), so a run stops
exactly where its plan said. The whole state is in the checkpoint: a resumed run plans as the uninterrupted one.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

#: fewest iterations in the trend window, and the first iteration the convergence rule is checked at: the first
#: tens of iterations fall steeply and then bend, and a short window's slope is mostly noise
WINDOW_MIN = 20
CHECK_FROM = 30
#: standard errors added to the slope towards a larger fall (~2.3 % one-sided for a Gaussian slope estimate)
Z = 2.0
#: largest lag-1 correlation allowed for (beyond it the window holds too few independent values to judge)
RHO_MAX = 0.9
#: iterations whose median time predicts the next ones' (robust to a slow first iteration or a checkpoint write)
TIME_WINDOW = 10

REASONS = ("iterations", "converged", "time budget")

#: seconds a run keeps after its last iteration: a number, or a function of the run's seconds outside its iterations
#: so far (its set-up: scene, start, estimate, start's figures) giving them
Reserve = float | Callable[[float], float]


@dataclass(frozen=True)
class Trend:
    """The least-squares line through the recent training ΔE76: ``slope`` (ΔE76 per iteration), its standard error
    ``slope_se`` (allowing for serial correlation ``rho``) and the window's length ``n``."""

    slope: float
    slope_se: float
    rho: float
    n: int

    def expected_gain(self, horizon: int) -> float:
        """An upper bound (``Z`` standard errors) of the fall in ΔE76 over the next ``horizon`` iterations."""
        return max(0.0, -(self.slope - Z * self.slope_se)) * horizon


def training_trend(values, window: int | None = None) -> Trend | None:
    """The :class:`Trend` of the last ``window`` values (default: the last third, at least ``WINDOW_MIN``) of a
    per-iteration curve; None while the curve is shorter than ``WINDOW_MIN``."""
    y = np.asarray(values, np.float64)
    n = max(WINDOW_MIN, len(y) // 3) if window is None else int(window)
    if len(y) < max(n, 3):
        return None
    y = y[-n:]
    t = np.arange(n, dtype=np.float64) - (n - 1) / 2.0
    sxx = float(t @ t)
    slope = float(t @ (y - y.mean())) / sxx
    r = y - y.mean() - slope * t
    s2 = float(r @ r) / (n - 2)
    rho = 0.0
    if s2 > 0:
        rho = float((r[:-1] @ r[1:]) / (r @ r))
        rho = float(np.clip(rho + (1.0 + 3.0 * rho) / n, 0.0, RHO_MAX))  # the lag-1 estimate's bias, to first order
    se = math.sqrt(s2 / sxx * (1.0 + rho) / (1.0 - rho))
    return Trend(slope, se, rho, n)


@dataclass
class Schedule:
    """The planned end of a run (``end``: the iteration count it stops at, which its step decay is planned for)
    and why (``reason``, one of ``REASONS``). ``converged_at``: the iteration the convergence rule fired at
    (None: not yet), with the ``gain`` it expected then; ``frozen``: the decay has begun and the end holds.
    ``fixed``: the end is the configuration's and nothing moves it (a run stopped early on purpose and continued
    later, ``OptimizeConfig.schedule_iterations``)."""

    end: int
    reason: str = "iterations"
    converged_at: int | None = None
    gain: float | None = None
    frozen: bool = False
    fixed: bool = False

    @classmethod
    def for_config(cls, cfg) -> Schedule:
        fixed = cfg.schedule_iterations is not None or (cfg.stop_gain <= 0 and cfg.time_budget is None)
        return cls(end=cfg.schedule_length, fixed=fixed)

    def plan(self, cfg, iteration: int, delta_e76, seconds, elapsed: float, reserve: Reserve = 0.0) -> None:
        """Move the end for the next iteration (module docstring). ``delta_e76``, ``seconds``: the training ΔE76
        and wall time of every iteration so far; ``elapsed``: the run's wall time so far, set-up included;
        ``reserve``: seconds kept for after the last iteration, or a function of the run's seconds outside its
        iterations so far giving them (``Reserve``)."""
        if self.fixed:
            return
        per = float(np.median(seconds[-TIME_WINDOW:])) if len(seconds) else None
        left = None
        if cfg.time_budget is not None and per is not None:
            kept = reserve(elapsed - float(np.sum(seconds))) if callable(reserve) else reserve
            left = cfg.time_budget - kept - elapsed
        if self.frozen:
            if left is not None and left < per and iteration < self.end:
                self.end, self.reason = iteration, "time budget"
            return
        end, reason = cfg.iterations, "iterations"
        if self.converged_at is None and cfg.stop_gain > 0 and iteration >= CHECK_FROM:
            trend = training_trend(delta_e76)
            if trend is not None and trend.expected_gain(cfg.stop_horizon) < cfg.stop_gain:
                self.converged_at, self.gain = iteration, trend.expected_gain(cfg.stop_horizon)
        if self.converged_at is not None:
            p = self.converged_at
            at = p if cfg.decay <= 0 else max(p + 1, math.ceil(p / (1.0 - cfg.decay)))
            if at < end:
                end, reason = at, "converged"
        if left is not None:
            fit = iteration + max(0, math.floor(left / per))
            if fit < end:
                end, reason = fit, "time budget"
        self.end, self.reason = end, reason
        if cfg.decay > 0 and iteration >= (1.0 - cfg.decay) * end:
            self.frozen = True

    def to_arrays(self) -> dict:
        """The checkpoint's entries (``schedule_*``)."""
        return {
            "schedule_end": np.int64(self.end),
            "schedule_reason": np.array(self.reason),
            "schedule_converged_at": np.int64(-1 if self.converged_at is None else self.converged_at),
            "schedule_gain": np.float64(np.nan if self.gain is None else self.gain),
            "schedule_frozen": np.bool_(self.frozen),
        }

    def load(self, d, cfg) -> None:
        """Restore from a checkpoint's entries (absent in a checkpoint of a run planned for its full length: the
        plan starts again from the configuration). A run whose end was its maximum plans again from the new
        maximum, so ``--iterations`` can lengthen a resumed run."""
        if self.fixed or "schedule_end" not in d:
            return
        self.end, self.reason = int(d["schedule_end"]), str(d["schedule_reason"])
        at = int(d["schedule_converged_at"])
        self.converged_at = None if at < 0 else at
        self.gain = None if np.isnan(d["schedule_gain"]) else float(d["schedule_gain"])
        self.frozen = bool(d["schedule_frozen"]) and not (self.reason == "iterations" and self.end != cfg.iterations)

    def describe(self, cfg) -> dict:
        """report.json's ``stop``: why the run ended, where the convergence rule fired and what it expected."""
        return {
            "reason": self.reason,
            "iterations": self.end,
            "converged_at": self.converged_at,
            "expected_gain_delta_e76": self.gain,
            "stop_gain": cfg.stop_gain,
            "stop_horizon": cfg.stop_horizon,
            "time_budget_s": cfg.time_budget,
            "max_iterations": cfg.iterations,
        }
