"""Whether a run's dither is share-compensated, decided by the run's own printed prediction (``inkopt quantize
--compensate-auto``; docs/quality.md, "The compensation decided by the run").

The compensation (``printing.compensate``) gives each ink the share whose dither looks like its mixture on flat
patches of that ink in white. Where a mixture is mostly white that removes the halftone's bias (the eyeball and the
box of the mesh suite: −0.08 to −0.4 ΔE76); where it is not, it overshoots (the spider's fur: +0.3 ΔE76; Spot's
cream: up to +0.16 ΔE2000). No fixed setting suits every mesh, so ``quantize_run_auto`` asks the run:

1. the mixture is quantized twice, plain and compensated, each into a candidate directory inside the run folder
   (``printing.stream.quantize_run`` with ``into``);
2. both label volumes are rendered at printer resolution on one random sample of ``CHOICE_TEXELS`` scene texels
   with the same seed and ``CHOICE_SPP`` samples per texel (``printed.PrintedRenderer``: as the evaluation renders a
   print); the renderer keys its random numbers by (seed, texel, sample), so the two renders share their noise
   wherever the labels agree;
3. per sampled texel, the noise-corrected ΔE76 and the ΔE2000 against the target; the compensated candidate is
   chosen only where it lowers the mean ΔE76 (the figure a mesh run's loss serves) by more than ``GAIN_STDERRS``
   standard errors of the paired per-texel difference and does not raise the mean ΔE2000 by more than as many.
   Keeping the plain dither is the safer side: it is what the calibration chart and the baselines are dithered
   with, and a mesh where the compensation neither clearly gains nor loses keeps it;
4. the winner's files replace the run's (``RunDir.adopt_quantized``); the candidates' folder is removed on any
   exit, and where a killed process left it, by the next job that takes the run's lock.

The run is quantized plain without a choice where the choice cannot judge it (``_plain_reason``): a job without a
target (the calibration chart's), inks whose factors are neither shipped nor cached, a run seen under other lights
than the uniform one or in spectral bands (the choice renders RGB under the uniform light), and a print too large to
render on this machine (the candidates are made layer by layer, as ``inkopt quantize`` makes its labels; the renders
hold them whole). The ΔE2000 is not corrected for the render noise (as the evaluation's is not): a candidate further
from the target has a little less of its noise's inflation, so a loss reads a little small.

Cost: two quantizations instead of one and two renders of the sample (the evaluation's printed render is one); with
a refinement on the printed prediction (``q.refine``) each candidate has its own, since it renders that candidate's
dither.
Seeds: the sample and the renders use the quantization's seed, apart from the optimisation's and the evaluation's.
Conventions: docs/conventions.md.
"""

from __future__ import annotations

import math
import tempfile
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from ..color import delta_e76, delta_e2000, linear_to_lab
from ..errors import ParameterError
from ..lighting import UNIFORM
from ..model import Quantization, VolumeError
from ..model.mixturefile import MixtureSource
from ..printing.compensate import has_compensation
from ..printing.quantize import check_quantization
from ..printing.stream import quantize_run
from ..rundir import RunDir
from .noise import EVAL_SEED_OFFSET, SEED_STRIDE, NoiseModel
from .printed import PrintedRenderer
from .sample import mean_se

#: scene texels of the choice's sample (at most all of them) and samples per scene texel of each candidate's render
#: (shared by its printer texels). The paired difference's error is mostly the two renders' own noise (the
#: candidates' labels differ wherever an ink's share is compensated, so their paths part after a few events), which
#: falls with the texel-samples rendered, not with how they are split: on the eyeball's 20 mm result, ± 0.111 ΔE76
#: at 1000 x 256, 0.065 at 1000 x 1024, 0.056 at 4000 x 256 (docs/quality.md). So many texels at few samples.
CHOICE_TEXELS = 4000
CHOICE_SPP = 256
#: the compensation must lower the mean ΔE76 by more than this many standard errors and may not raise ΔE2000 by more
GAIN_STDERRS = 2.0
#: ``inkopt quantize --compensate`` values: the share compensation on, off, or chosen by the run (None)
COMPENSATE = {"on": True, "off": False, "auto": None}
#: a run's quantization when the user does not say (``inkopt quantize``, and ``inkopt evaluate`` of a run not
#: quantized yet): the run chooses (docs/quality.md, "The compensation decided by the run")
DEFAULT_COMPENSATE = "auto"
#: the candidates' folder in the run folder, ``.compensation.XXXXXXXX.tmp``: removed on exit, and where a killed
#: process left it, by the next job that takes the run's lock (``io.is_temporary``)
STAGE_PREFIX = ".compensation."
#: the choice's seed pass (``EVAL_SEED_OFFSET + seed + CHOICE_SEED_PASS x SEED_STRIDE``): no evaluation pass uses it
CHOICE_SEED_PASS = 48


@dataclass(frozen=True)
class CompensationChoice:
    """What ``quantize_run_auto`` chose: ``compensate`` (the run's labels are the compensated candidate's), the
    paired differences compensated − plain of the mean noise-corrected ΔE76 and the mean ΔE2000 with their standard
    errors, on ``texels`` sampled scene texels of ``population`` rendered at ``spp`` samples each, and the
    ``seconds`` the whole command took (both quantizations and both renders). A run quantized plain without a
    choice says why in ``reason`` (``_plain_reason``) and has ``texels`` 0 and NaN differences."""

    compensate: bool
    delta_e76: float
    delta_e76_stderr: float
    delta_e2000: float
    delta_e2000_stderr: float
    texels: int
    population: int
    spp: int
    seconds: float
    reason: str = ""

    def to_json(self) -> dict:
        """The choice as JSON values (NaN differences as null)."""
        return {k: None if isinstance(v, float) and math.isnan(v) else v for k, v in asdict(self).items()}

    def line(self) -> str:
        if self.reason:
            return f"compensation auto: plain (uncompensated): {self.reason}"
        verdict = "compensated" if self.compensate else "plain (uncompensated)"
        return (
            f"compensation auto: {verdict}; compensated - plain on {self.texels} of {self.population} texels at "
            f"{self.spp} spp: {self.delta_e76:+.3f} +- {self.delta_e76_stderr:.3f} dE76 (noise-corrected), "
            f"{self.delta_e2000:+.3f} +- {self.delta_e2000_stderr:.3f} dE2000; {self.seconds:.1f} s"
        )


def compensate_wins(d76: tuple[float, float], d2000: tuple[float, float], stderrs: float = GAIN_STDERRS) -> bool:
    """The rule (module docstring, step 3) on the paired differences compensated − plain, each (mean, stderr)."""
    if not all(math.isfinite(v) for v in (*d76, *d2000)):
        return False
    return d76[0] < -stderrs * d76[1] and d2000[0] <= stderrs * d2000[1]


def quantize_run_as(
    d: RunDir, q: Quantization, compensate: str = DEFAULT_COMPENSATE, threads: int | None = None, log=None
) -> list[str]:
    """Run ``d`` quantized by the settings ``q`` with the compensation ``compensate`` (a key of ``COMPENSATE``; "on"
    and "off" set ``q.compensate``, "auto" is ``quantize_run_auto``, whose choice ends the returned summary lines)."""
    if compensate not in COMPENSATE:
        raise ParameterError(f"`compensate` must be one of {list(COMPENSATE)}, got {compensate!r}")
    if COMPENSATE[compensate] is None:
        lines, choice = quantize_run_auto(d, q, threads, log)
        d.record_compensation_choice(choice.to_json())
        return [*lines, choice.line()]
    return quantize_run(d, replace(q, compensate=COMPENSATE[compensate]), threads, log)


def quantize_run_auto(
    d: RunDir,
    q: Quantization,
    threads: int | None = None,
    log=None,
    texels: int = CHOICE_TEXELS,
    spp: int = CHOICE_SPP,
) -> tuple[list[str], CompensationChoice]:
    """``inkopt quantize --compensate-auto`` of run ``d`` with the other settings of ``q`` (module docstring);
    returns the chosen candidate's summary lines (``quantize.summary_lines``) and the choice (``quantize_run_as``
    records it in quantized.npz, ``RunDir.record_compensation_choice``)."""
    check_quantization(q)  # before any file is read
    t0 = time.perf_counter()
    if reason := _plain_reason(d, q):
        lines = quantize_run(d, replace(q, compensate=False), threads, log)
        nan = math.nan
        return lines, CompensationChoice(False, nan, nan, nan, nan, 0, 0, spp, time.perf_counter() - t0, reason)
    with tempfile.TemporaryDirectory(prefix=STAGE_PREFIX, suffix=".tmp", dir=d.path) as tmp:
        stage = {c: RunDir(_mkdir(Path(tmp) / c)) for c in ("plain", "compensated")}
        lines = {}
        for name, run in stage.items():  # each with its own refinement where ``q.refine``: it renders its dither
            lines[name] = quantize_run(d, replace(q, compensate=name == "compensated"), threads, log, into=run)
            if log is not None:
                log(f"compensation auto: {name} candidate quantized, {time.perf_counter() - t0:.1f} s")
        try:
            d76, d2000, n, population = paired_figures(d, *stage.values(), q.seed, texels, spp, threads)
        except (VolumeError, MemoryError) as e:  # the print is beyond this machine's renders; the labels are not
            d.adopt_quantized(stage["plain"])
            nan, reason = math.nan, f"the prints could not be rendered here ({str(e).splitlines()[0]})"
            return lines["plain"], CompensationChoice(False, nan, nan, nan, nan, 0, 0, spp, _since(t0), reason)
        wins = compensate_wins(d76, d2000)
        d.adopt_quantized(stage["compensated" if wins else "plain"])
    choice = CompensationChoice(wins, *d76, *d2000, n, population, spp, _since(t0))
    return lines["compensated" if wins else "plain"], choice


def _since(t0: float) -> float:
    return time.perf_counter() - t0


def _plain_reason(d: RunDir, q: Quantization) -> str:
    """Why run ``d`` is quantized plain without a choice, or "": a job without a target (no scene.npz: the
    calibration chart's, whose patches are measured as dithered plain), or inks whose compensation is not shipped or
    cached (auto does not spend the measurement's two minutes unasked)."""
    if not d.scene_path.is_file():
        return "the job has no target to compare the prints with"
    report = d.read_report() if d.report_path.is_file() else {}
    if report.get("viewing"):
        return "a spectral run: the choice renders RGB under the uniform light only"
    if str(report.get("lighting", UNIFORM)) != UNIFORM:
        return f"the run is seen under '{report['lighting']}': the choice renders under the uniform light only"
    with MixtureSource(d.volume_file()) as src:
        known = has_compensation(src.inks, q, src.g, src.ior)
    if not known:
        return (
            "no compensation is measured for these inks on this printer grid (`--compensate` measures it once, "
            "about two minutes, and auto uses it from then on)"
        )
    return ""


def _mkdir(path: Path) -> Path:
    path.mkdir()
    return path


def paired_figures(d: RunDir, plain: RunDir, comp: RunDir, seed: int, texels: int, spp: int, threads=None):
    """The paired differences compensated − plain (each (mean, stderr)) of the noise-corrected ΔE76 and the ΔE2000
    on a random sample of ``texels`` scene texels, both label volumes rendered at ``spp`` with one seed; and the
    sample's size and the scene's texel count."""
    rec = d.load_scene()
    with MixtureSource(d.volume_file()) as src:
        voxel_mm = np.asarray(src.voxel_mm, np.float64)
    population = len(rec.texels)
    n = min(int(texels), population)
    sample = np.sort(np.random.default_rng([int(seed), CHOICE_SEED_PASS]).choice(population, n, replace=False))
    target_lab = linear_to_lab(rec.target_rgb.astype(np.float64))[sample]
    render_seed = EVAL_SEED_OFFSET + int(seed) + CHOICE_SEED_PASS * SEED_STRIDE
    vols = [plain.load_quantized(layered=True), comp.load_quantized(layered=True)]
    printer = PrintedRenderer(vols[0], rec.texels, voxel_mm, rec.kind, threads, groups=[sample])
    e76, e2000 = [], []
    for vol in vols:
        printer.use(vol)
        rgb, var, _ = printer(spp, render_seed)
        lab = linear_to_lab(rgb)
        e76.append(delta_e76(lab, target_lab) - NoiseModel.of(rgb, var, target_lab).per_texel())
        e2000.append(delta_e2000(lab, target_lab))
    printer.use(None)
    del vols
    # no finite-population correction: each texel's render noise is an error of its own even where the sample is
    # every texel
    return mean_se(e76[1] - e76[0], math.inf), mean_se(e2000[1] - e2000[0], math.inf), n, population
