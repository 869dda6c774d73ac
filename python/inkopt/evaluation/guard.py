"""The baseline guard: a run's result against the extrusion baseline in the run's own terms (docs/quality.md).

A run measures the figures of ``GUARD_BASELINE``'s mixture (``baselines.baseline_layers``, from the ink set's colour
table) once at its start, with its own renderer, lighting, texels and evaluation seeds, as it measures its start
(``run_optimisation``; kept in the checkpoints). At the end ``BaselineCheck`` compares the result's figures with
them: a result worse beyond the figures' noise is reported (``warning()``, report.json's ``beats_baseline``).

The figure compared is the noise-corrected mean ΔE76 (``Metrics.delta_e76_mean_corrected``), not the training loss: it
is the figure the run's report, ``inkopt evaluate``'s table and the user compare results by; its noise correction has a
measured accuracy (``noise.ESTIMATE_RANGE``), which gives the tolerance below; the loss's colour term (mean ΔE76², the
slabs' default; on meshes the mean ΔE76) is inflated by the noise with no correction of known accuracy, and with an SSIM
or edge weight the loss's scale differs from run to run. The loss of both is recorded beside it.

The figure's uncertainty (``figure_error``): the correction's accuracy, ``ESTIMATE_RANGE[1] - 1`` (35 %) of the
estimated noise contribution, plus the mean's sampling error, a texel's ΔE76 varying by about its CIELAB standard
error over √3 (the noise along the error's direction), over √I texels. Figures of a texel sample (a large object's
start and baseline, ``runfigures``) take the sample's standard error instead of the last term (``sampled_error``):
it covers the render noise and which texels were drawn. A result is worse than the baseline when its
figure exceeds the baseline's by more than the two uncertainties combined (in quadrature); above it by less, the
run notes that the two are not told apart by its figures (``note()``; ``inkopt evaluate`` measures both noise-free).

The colour table: the default ink set's ships with the package; another set's is built the first time and then
cached (970 patches for 5 inks: the packaged table took 147 s to build). A run measures the baseline only when its
table is in the cache or the package (``table_available``; a run started from a baseline has just built and cached
it): a table built for the guard alone would add minutes to a short run, and to each of ``inkopt select-inks``' many
ink subsets.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..model import Volume
from ..optim import Optimization
from .colour_table import DEFAULT_MAX_STDERR, DEFAULT_PATCH_MM, PACKAGED, cache_dir, default_step, table_key
from .metrics import Metrics
from .noise import ESTIMATE_RANGE

#: the baseline a run compares its result with
GUARD_BASELINE = "extrusion"
#: the noise correction's relative accuracy (``noise.ESTIMATE_RANGE``: within 0.65-1.35 of the true inflation)
CORRECTION_ERROR = ESTIMATE_RANGE[1] - 1.0


def figure_error(m: Metrics, texels: int) -> float:
    """Uncertainty (ΔE76) of ``m.delta_e76_mean_corrected`` over ``texels`` texels (module docstring); 0 without
    noise figures."""
    if m.delta_e76_noise_contribution is None:
        return 0.0
    sampling = (m.delta_e76_noise or 0.0) / math.sqrt(3.0 * max(int(texels), 1))
    return CORRECTION_ERROR * m.delta_e76_noise_contribution + sampling


def sampled_error(m: Metrics, stderr: dict, points: int) -> float:
    """Uncertainty (ΔE76) of a texel sample's ``m.delta_e76_mean_corrected`` (``evaluation.sample``, its standard
    errors ``stderr`` by figure, ``points`` texels): the correction's accuracy and the sample's standard error, which
    covers the render noise and which texels were drawn; at least the render noise's share of ``figure_error``, which
    the finite-population correction would shrink where the sample is most of the texels."""
    contribution = m.delta_e76_noise_contribution or 0.0
    noise = (m.delta_e76_noise or 0.0) / math.sqrt(3.0 * max(int(points), 1))
    return CORRECTION_ERROR * contribution + max(float(stderr["delta_e76_mean_corrected"]), noise)


def kept_figures(m: Metrics, spp: int, texels: int, sample: dict | None = None) -> dict:
    """The figures a run keeps of its start or of a baseline (JSON-able; ``Optimization.keep_start_figures``), of
    every one of ``texels`` texels, or of a texel sample: ``sample`` = {"sample": ``TexelSample.to_json()``,
    "stderr": the figures' standard errors, "choice": ``SamplingChoice.to_json()``} (its loss is not kept: the
    sample estimates the figures' loss, not the run's)."""
    if sample is None:
        error = figure_error(m, texels)
    else:
        error = sampled_error(m, sample["stderr"], sample["sample"]["texels"])
    return {
        "delta_e76_mean": m.delta_e76_mean,
        "ssim": m.ssim,
        "delta_e76_mean_corrected": m.delta_e76_mean_corrected,
        "delta_e76_noise_contribution": m.delta_e76_noise_contribution,
        "delta_e76_error": error,
        "loss": m.loss if sample is None else None,
        "eval_spp": int(spp),
        "texel_sample": sample,
    }


def comparable(figures: dict | None) -> bool:
    """Whether kept figures carry what a ``BaselineCheck`` compares (a checkpoint's older start figures do not)."""
    return figures is not None and figures.get("delta_e76_mean_corrected") is not None and "delta_e76_error" in figures


def table_available(volume: Volume) -> bool:
    """Whether the colour table that ``baselines.baseline_layers`` uses for ``volume``'s inks (its g and ior) is in
    the cache or the package, so that the baseline costs no table build."""
    inks = volume.inks
    key = table_key(inks, volume.g, volume.ior, DEFAULT_PATCH_MM, default_step(len(inks)), DEFAULT_MAX_STDERR)
    name = f"colour_table_{key}.npz"
    return (cache_dir() / name).is_file() or (PACKAGED / name).is_file()


@dataclass(frozen=True)
class BaselineCheck:
    """The result's noise-corrected mean ΔE76 (``result``, uncertainty ``result_error``) against the baseline
    ``kind``'s kept figures ``baseline`` (``kept_figures``)."""

    kind: str
    result: float
    result_error: float
    baseline: dict

    @classmethod
    def of(cls, metrics: Metrics, error: float, kind: str, baseline: dict) -> BaselineCheck:
        return cls(kind, float(metrics.delta_e76_mean_corrected), float(error), dict(baseline))

    @property
    def difference(self) -> float:
        """Result minus baseline, ΔE76 (negative: the result is better)."""
        return self.result - float(self.baseline["delta_e76_mean_corrected"])

    @property
    def tolerance(self) -> float:
        """The two figures' uncertainties combined: differences within it are not told apart."""
        return math.hypot(self.result_error, float(self.baseline["delta_e76_error"]))

    @property
    def beats(self) -> bool:
        """False exactly when the result is worse than the baseline beyond the figures' noise."""
        return self.difference <= self.tolerance

    def _figures(self, verb: str) -> str:
        """'the result (its figure) VERB the baseline (its figure)'."""
        b = self.baseline
        sample = b.get("texel_sample")
        on = "" if not sample else f" on {sample['sample']['texels']} sampled texels"
        return (
            f"the result (noise-corrected ΔE76 {self.result:.2f} ± {self.result_error:.2f}) {verb} the {self.kind} "
            f"baseline ({b['delta_e76_mean_corrected']:.2f} ± {b['delta_e76_error']:.2f}, {b['eval_spp']} spp{on})"
        )

    def warning(self) -> str | None:
        """The log line of a result worse than the baseline beyond the noise, else None."""
        if self.beats:
            return None
        advice = (
            f"start the run from the baseline (init {self.kind!r}) or give it more iterations or time; "
            "`inkopt evaluate` compares both noise-free"
        )
        return f"warning: {self._figures('is worse than')} under the run's lighting: {advice}"

    def note(self) -> str | None:
        """A log line when the result is above the baseline but within the noise, else None."""
        if not self.beats or self.difference <= 0:
            return None
        within = "by the run's figures (within their noise); `inkopt evaluate` measures both noise-free"
        return f"note: {self._figures('is not told apart from')} {within}"

    def to_json(self) -> dict:
        """report.json's ``baseline`` entry: kind -> the baseline's kept figures and the comparison (result minus
        baseline, its tolerance, the result's uncertainty; ΔE76)."""
        comparison = {
            "difference_delta_e76": self.difference,
            "tolerance_delta_e76": self.tolerance,
            "result_delta_e76_error": self.result_error,
        }
        return {self.kind: {**self.baseline, **comparison}}


def keep_baseline_figures(run: Optimization, measure: Callable[[np.ndarray], dict], log: Callable[[str], None]) -> None:
    """The run driver's step before the iterations: ``GUARD_BASELINE``'s figures kept with ``run``
    (``Optimization.keep_baseline_figures``, so that a resume does not measure them again): the start's own when the
    run starts from that baseline (not rendered twice), else ``measure(x)`` of the baseline's variables x (F, N) (one
    pilot with the run's renderer, as the start's figures and on the same texels: every one or the start's sample,
    ``runfigures``), or a note in ``log`` when its colour table is not cached
    (module docstring)."""
    kind = GUARD_BASELINE
    if comparable((run.baseline_figures or {}).get(kind)):
        return
    if run.cfg.init == kind and comparable(run.start_figures):
        run.keep_baseline_figures(kind, run.start_figures)
    elif table_available(run.base):
        run.keep_baseline_figures(kind, measure(run.initial_variables(kind)))
    else:
        log(
            f"note: the colour table of these inks is not cached, so the result is not checked against the {kind} "
            "baseline (`inkopt evaluate` builds the table once)"
        )


def check_baseline(
    run: Optimization, metrics: Metrics, log: Callable[[str], None], error: float | None = None
) -> BaselineCheck | None:
    """The result's figures ``metrics`` (uncertainty ``error``, ΔE76; None: ``figure_error`` of every texel's)
    against the baseline figures kept with ``run``, the warning (or note) in ``log``; None when the run kept
    none."""
    kept = (run.baseline_figures or {}).get(GUARD_BASELINE)
    if not comparable(kept) or metrics.delta_e76_mean_corrected is None:
        return None
    error = figure_error(metrics, len(run.texels)) if error is None else error
    check = BaselineCheck.of(metrics, error, GUARD_BASELINE, kept)
    line = check.warning() or check.note()
    if line:
        log(line)
    return check
