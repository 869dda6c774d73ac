"""What a run tells its user as it goes: progress lines for a log that is not a terminal, and which settings a
checkpoint was made with when they differ from the run's."""

from __future__ import annotations

import time

from ..units import format_duration


def changed_settings(old: dict, new: dict) -> str:
    """The settings two checkpoint keys differ in, as "NAME OLD -> NEW, ..." ("problem": the target, texels or
    constraints)."""
    names = {"problem": "the target, texels or constraints (scene)"}
    out = []
    for k in sorted(set(old) | set(new)):
        if old.get(k) != new.get(k):
            what = names.get(k, k)
            out.append(what if k == "problem" else f"{what} {old.get(k)!r} -> {new.get(k)!r}")
    return ", ".join(out)


class ProgressLines:
    """Progress as log lines, for a log that is not a terminal (a file, a scheduler): "iteration i/N: loss L,
    ΔE76 D, S s/iteration, ETA T" after the first iteration, then whenever ``every_s`` seconds have passed since
    the last line, and after the last iteration. The ETA is this invocation's mean time per iteration times the
    iterations left. ``clock``: seconds (monotonic)."""

    def __init__(self, total: int, start: int, log, every_s: float = 30.0, clock=time.perf_counter):
        self.total, self.start, self.log, self.every_s, self.clock = int(total), int(start), log, float(every_s), clock
        self.t0 = self.last = clock()
        self.first = True

    def update(self, iteration: int, loss: float, delta_e76: float) -> None:
        now = self.clock()
        if not (self.first or iteration >= self.total or now - self.last >= self.every_s):
            return
        per = (now - self.t0) / max(iteration - self.start, 1)
        self.log(
            f"iteration {iteration}/{self.total}: loss {loss:.4g}, ΔE76 {delta_e76:.2f}, {per:.1f} s/iteration, "
            f"ETA {format_duration(per * (self.total - iteration))}"
        )
        self.first, self.last = False, now
