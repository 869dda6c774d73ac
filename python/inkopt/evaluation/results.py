"""The results files of a run as typed values: ``Report`` (report.json of ``run.run_optimisation``) and
``Evaluation`` (evaluation.json of ``evaluation.evaluate.evaluate_run``).

``to_json()`` gives the file's JSON object, with the same keys as scripts read them (the figures of
``metrics.Metrics`` flat among the others, the scene's and the lighting's entries too) plus ``format_version``;
``from_json(data, where)`` reads one back, bringing a file of an older format version up to date
(``io.upgrade_format``; a file without ``format_version`` is version 0, whose keys equal version 1's; an
evaluation of version 1 has every key of version 2 but the texel sample's, which it did not use).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields
from pathlib import Path

from ..io import FORMAT_KEY, upgrade_format
from .metrics import Metrics

REPORT_FORMAT = 1
EVALUATION_FORMAT = 2
_SAME_KEYS = {0: dict}  # version 0 -> 1: the keys are the same, only format_version is added
# evaluation version 1 -> 2: the texel sample's keys (``texel_sample``, ``differences``, a result's ``stderr``)
# are new; a version-1 evaluation rendered every texel, which they say by their absence
_EVALUATION_UPGRADES = {0: dict, 1: dict}


def _read(path) -> dict:
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{p} does not exist")
    try:
        return json.loads(p.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{p} is not valid JSON ({exc})") from None


def _is_lighting(key: str) -> bool:
    return key == "lighting" or key.startswith("lighting_")


@dataclass
class Report:
    """What a run measured and how it ran (report.json).

    ``metrics``: the final mixture's figures; ``initial_*``: the starting mixture's; ``delta_e76_max``: the
    largest per-texel ΔE76; ``iterations``, ``spp`` (gradient pass); ``eval_spp`` (the final evaluation's samples
    per texel), ``spp_adaptive``, ``eval_spp_passes``, ``initial_eval_spp``, ``initial_texel_sample`` (the start's
    figures' texel sample and their standard errors, ``evaluation.guard.kept_figures``; None: every texel),
    ``texel_sample`` (the result's figures': ``runfigures.ResultFigures.sample``; their ``eval_spp`` are then the
    sample's points'), ``pictures_spp`` (samples per texel of the render of every texel that the pictures and
    predictions.npz show; None in older reports); wall
    times in seconds (``seconds``: this invocation's; ``seconds_total``: the whole run's across resumes, None in
    older reports; ``time_split``: per iteration, by phase; ``estimate``: the cost estimated before the iterations,
    ``inkopt.estimate.Estimate.to_json()``, None in older reports); ``stop``: why the run ended where it did
    (``optim.stopping.Schedule.describe``: converged, time budget or its maximum; None in older reports);
    ``scene``: the scene's own entries
    (``Scene.report_fields``: sizes, paths, translucency); the optimiser settings (``inks`` .. ``gradient``);
    ``threads``; ``peak_rss_gb`` (GiB); ``lighting``: ``Lighting.describe()``. ``baseline``: the print-shop
    baseline the result is checked against, kind -> its figures at the run's start and the comparison
    (``evaluation.guard.BaselineCheck.to_json``); ``beats_baseline``: False when the result is worse than it beyond
    the figures' noise (both None when the run did not measure the baseline, and in older reports). ``viewing``:
    a spectral run's lights (``spectral.viewing.Viewing.describe``), its headline light (the one ``metrics`` are
    under) and its figures under each light (``evaluation.lights.light_figures``; where the result's figures are of a
    texel sample, ``sampled_light_figures``: that sample's, with ``stderr`` and ``inconstancy_stderr``); None on the
    RGB path.
    """

    metrics: Metrics
    initial_delta_e76_mean: float
    initial_ssim: float
    initial_delta_e76_mean_corrected: float | None
    delta_e76_max: float
    iterations: int
    spp: int
    eval_spp: int
    spp_adaptive: bool
    eval_spp_passes: list
    initial_eval_spp: int
    seconds: float
    seconds_iterations: float
    seconds_per_iteration: float
    time_split: dict
    scene: dict
    inks: list
    gamma: list
    lr: float | None
    optimizer: str
    param: str
    init: str
    seed: int
    decay: float
    smooth: float | None
    adjoint_ema: float | None
    gradient: str
    threads: int | None
    peak_rss_gb: float
    lighting: dict
    seconds_total: float | None = None
    estimate: dict | None = None
    stop: dict | None = None
    finish_smooth: int | None = None  # passes of smoothing over the result (None: a report from before them)
    #: the finishing smoothing's choice of a run with ``finish_smooth`` auto (``evaluation.finish.FinishChoice``'s
    #: JSON); None: the passes were set
    finish: dict | None = None
    baseline: dict | None = None
    beats_baseline: bool | None = None
    viewing: dict | None = None
    colour_term: str | None = None  # the loss's colour term (None: a report from before the choice, squared)
    initial_texel_sample: dict | None = None
    texel_sample: dict | None = None
    pictures_spp: int | None = None

    _RUN = (
        "delta_e76_max",
        "iterations",
        "spp",
        "eval_spp",
        "spp_adaptive",
        "eval_spp_passes",
        "initial_eval_spp",
        "initial_delta_e76_mean_corrected",
        "initial_texel_sample",
        "texel_sample",
        "pictures_spp",
        "seconds",
        "seconds_total",
        "seconds_iterations",
        "seconds_per_iteration",
        "time_split",
        "estimate",
        "stop",
        "baseline",
        "beats_baseline",
        "finish",
    )
    _SETTINGS = (
        "inks",
        "gamma",
        "colour_term",
        "lr",
        "optimizer",
        "param",
        "init",
        "seed",
        "decay",
        "smooth",
        "finish_smooth",
        "adjoint_ema",
        "gradient",
        "threads",
        "peak_rss_gb",
    )

    def to_json(self) -> dict:
        return {
            "initial_delta_e76_mean": self.initial_delta_e76_mean,
            "initial_ssim": self.initial_ssim,
            **self.metrics.to_json(),
            **{k: getattr(self, k) for k in self._RUN},
            **self.scene,
            **{k: getattr(self, k) for k in self._SETTINGS},
            **self.lighting,
            **({} if self.viewing is None else {"viewing": self.viewing}),
            FORMAT_KEY: REPORT_FORMAT,
        }

    @classmethod
    def from_json(cls, data: dict, where="report.json") -> Report:
        """A report from report.json's object (``where`` names the file in errors); entries that are neither
        figures, run facts, settings nor lighting are the scene's."""
        d = upgrade_format(data, kind="run report", where=where, current=REPORT_FORMAT, upgrades=_SAME_KEYS)
        d.pop(FORMAT_KEY)
        named = {f.name for f in fields(cls)} | {f.name for f in fields(Metrics)}
        own = {k: d.get(k) for k in ("initial_delta_e76_mean", "initial_ssim") + cls._RUN + cls._SETTINGS}
        return cls(
            metrics=Metrics.from_json(d),
            **own,
            viewing=d.get("viewing"),
            scene={k: v for k, v in d.items() if k not in named and not _is_lighting(k)},
            lighting={k: v for k, v in d.items() if _is_lighting(k)},
        )

    @classmethod
    def read(cls, path) -> Report:
        """The report of a report.json file."""
        return cls.from_json(_read(path), where=path)


@dataclass
class Measured:
    """One result of an evaluation (the continuous mixture, the quantized print or a baseline): its ``metrics``,
    ``spp`` samples per scene texel in ``spp_passes``, ``seconds``, the quantization ``method`` (None for the
    continuous result), for printed results ``spp_printer``, the samples per printer texel, and
    ``events_per_path``: the renders' mean scattering and interface events per path, what a sample costs (None in
    evaluations written before it was recorded); ``stderr``: figure name -> its sampling standard error when the
    figures come from a texel sample (``evaluation.sample``; None when every texel was rendered), and then
    ``spp``, ``spp_passes`` and ``spp_printer`` are the sampled points' (the ΔE figures'), ``spp_windows`` and
    ``spp_windows_passes`` the SSIM windows' samples per scene texel."""

    metrics: Metrics
    spp: int
    spp_passes: list
    seconds: float
    method: str | None
    spp_printer: int | None = None
    events_per_path: float | None = None
    stderr: dict | None = None
    spp_windows: int | None = None
    spp_windows_passes: list | None = None

    def to_json(self) -> dict:
        d = {**self.metrics.to_json(), "spp": self.spp, "spp_passes": self.spp_passes}
        if self.spp_printer is not None:
            d["spp_printer"] = self.spp_printer
        if self.events_per_path is not None:
            d["events_per_path"] = self.events_per_path
        if self.stderr is not None:
            d.update(stderr=self.stderr, spp_windows=self.spp_windows, spp_windows_passes=self.spp_windows_passes)
        return {**d, "seconds": self.seconds, "method": self.method}

    @classmethod
    def from_json(cls, d: dict) -> Measured:
        return cls(
            Metrics.from_json(d),
            d["spp"],
            d["spp_passes"],
            d["seconds"],
            d["method"],
            d.get("spp_printer"),
            d.get("events_per_path"),
            d.get("stderr"),
            d.get("spp_windows"),
            d.get("spp_windows_passes"),
        )


@dataclass
class Evaluation:
    """An evaluation of a run (evaluation.json; ``evaluation.evaluate``'s module docstring says what each figure
    is). ``spp`` is the continuous result's; ``lighting``: ``Lighting.describe()``; ``quantization``: the
    quantized volume's settings; ``translucency``, ``colour_table``, the gamut floor, ``baselines`` and
    ``pictures`` are None when not measured or written; ``volume_digest`` and ``quantized_digest``: the
    ``io.file_digest`` of the volume.npz and quantized.npz evaluated (None in evaluations written before they were
    recorded). ``texel_sample``: the sample the figures come from (``evaluation.sample.TexelSample.to_json`` with
    the printer texels rendered), None when every texel was rendered; ``differences``: then the paired differences
    between results ("a - b" -> figure -> value and standard error, ``sample.differences``); ``sampling_choice``:
    why every texel or a sample was rendered (``evaluation.choice.SamplingChoice.to_json``: forced, or both
    predicted times; None in evaluations written before it was recorded)."""

    spp: int
    seed: int
    texels: int
    kind: str
    spp_adaptive: bool
    noise_target_delta_e76: float
    noise_target_ssim_ratio: float
    spp_pilot: int
    spp_max: int
    lighting: dict
    continuous: Measured
    quantization: dict
    printer_texels: int
    quantized: Measured
    seconds: float
    translucency: dict | None = None
    colour_table: dict | None = None
    gamut_floor_delta_e76: float | None = None
    gamut_floor_delta_e76_p95: float | None = None
    baselines: dict | None = None  # name -> Measured
    pictures: list | None = None
    volume_digest: str | None = None  # io.file_digest of the volume.npz and quantized.npz evaluated
    quantized_digest: str | None = None
    texel_sample: dict | None = None
    differences: dict | None = None
    sampling_choice: dict | None = None  # evaluation.choice.SamplingChoice.to_json

    _HEAD = (
        "spp",
        "seed",
        "texels",
        "kind",
        "spp_adaptive",
        "noise_target_delta_e76",
        "noise_target_ssim_ratio",
        "spp_pilot",
        "spp_max",
    )
    _FLOOR = ("colour_table", "gamut_floor_delta_e76", "gamut_floor_delta_e76_p95")
    _SOURCES = ("volume_digest", "quantized_digest")
    _SAMPLE = ("texel_sample", "differences", "sampling_choice")

    def to_json(self) -> dict:
        d = {**{k: getattr(self, k) for k in self._HEAD}, **self.lighting, "continuous": self.continuous.to_json()}
        if self.translucency is not None:
            d["translucency"] = self.translucency
        d.update(quantization=self.quantization, printer_texels=self.printer_texels, quantized=self.quantized.to_json())
        d.update({k: getattr(self, k) for k in self._FLOOR if getattr(self, k) is not None})
        if self.baselines is not None:
            d["baselines"] = {k: v.to_json() for k, v in self.baselines.items()}
        d["seconds"] = self.seconds
        if self.pictures is not None:
            d["pictures"] = self.pictures
        d.update({k: getattr(self, k) for k in self._SOURCES + self._SAMPLE if getattr(self, k) is not None})
        d[FORMAT_KEY] = EVALUATION_FORMAT
        return d

    @classmethod
    def from_json(cls, data: dict, where="evaluation.json") -> Evaluation:
        d = upgrade_format(
            data, kind="evaluation", where=where, current=EVALUATION_FORMAT, upgrades=_EVALUATION_UPGRADES
        )
        base = d.get("baselines")
        return cls(
            **{k: d[k] for k in cls._HEAD},
            lighting={k: v for k, v in d.items() if _is_lighting(k)},
            continuous=Measured.from_json(d["continuous"]),
            quantization=d["quantization"],
            printer_texels=d["printer_texels"],
            quantized=Measured.from_json(d["quantized"]),
            seconds=d["seconds"],
            translucency=d.get("translucency"),
            **{k: d.get(k) for k in cls._FLOOR},
            baselines=None if base is None else {k: Measured.from_json(v) for k, v in base.items()},
            pictures=d.get("pictures"),
            **{k: d.get(k) for k in cls._SOURCES + cls._SAMPLE},
        )

    @classmethod
    def read(cls, path) -> Evaluation:
        """The evaluation of an evaluation.json file."""
        return cls.from_json(_read(path), where=path)

    def results(self) -> list[tuple[str, Measured]]:
        """(name, result) rows: the continuous result, the quantized print, then each baseline."""
        rows = [("continuous", self.continuous), ("quantized", self.quantized)]
        return rows + [(f"{k} baseline", v) for k, v in (self.baselines or {}).items()]
