"""The renders of an evaluation (``evaluate``): the texel groups every result is rendered on, the time budget shared
out among the results' renders, and one result's adaptive render (``noise.adaptive_render``) on each group through a
*source*, a callable ``source(spp, seed, group) -> (rgb (I, 3), var_mean (I, 3), weight)`` that counts its walks:
``ContinuousSource`` (a mixture volume on the scene texels) or ``PrintedSource`` (a label volume on the printer
texels, averaged onto the scene texels).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from ..color import RGB, ColourMap
from ..model import Texels
from ..render import Renderer
from .noise import SSIM_NOISE_RATIO, TARGET_NOISE_DE76, AdaptiveResult, Sampling, adaptive_render
from .printed import PrintedRenderer
from .sample import SAMPLE_SSIM_NOISE_RATIO, TexelSample


@dataclass(frozen=True)
class TexelGroup:
    """Scene texels rendered together, their target colours ``target_lab`` (I, 3) CIELAB, and the targets of their
    adaptive render: ``noise_target`` (ΔE76 of noise in the mean) and ``ssim_ratio`` (either inf: none)."""

    texels: Texels
    target_lab: np.ndarray
    noise_target: float
    ssim_ratio: float


def texel_groups(texels: Texels, target_lab: np.ndarray, sample: TexelSample | None) -> list[TexelGroup]:
    """Every texel in one group, or a sample's points (for the ΔE figures) and window texels (for SSIM and the
    mottle), the points to every texel's noise targets (so their noise biases the figures as much as rendering every
    texel would), the windows to their own SSIM target (``evaluation.sample``)."""
    if sample is None:
        return [TexelGroup(texels, target_lab, TARGET_NOISE_DE76, SSIM_NOISE_RATIO)]
    points, windows = (texels.subset(g) for g in sample.groups)
    return [
        TexelGroup(points, target_lab[sample.points], TARGET_NOISE_DE76, SSIM_NOISE_RATIO),
        TexelGroup(windows, target_lab[sample.windows], np.inf, SAMPLE_SSIM_NOISE_RATIO),
    ]


@dataclass
class TimeShares:
    """The adaptive renders' time budget (``total`` seconds, None: none) shared out evenly: each render gets what is
    left of it since ``started`` (on ``clock``, default ``time.perf_counter``) over the ``left`` renders still to do,
    itself included."""

    total: float | None
    started: float
    left: int
    clock: Callable[[], float] = time.perf_counter

    def next(self) -> float | None:
        """The next render's budget in seconds (None without a budget); one render fewer is left."""
        budget = None
        if self.total is not None:
            budget = max(self.total - (self.clock() - self.started), 0.0) / max(self.left, 1)
        self.left -= 1
        return budget


class ContinuousSource:
    """A mixture volume rendered on the texel groups; ``paths`` and ``events`` count its walks."""

    spp_printer = None

    def __init__(self, renderer: Renderer, groups: list[TexelGroup], progress: bool):
        self.renderer, self.groups, self.progress = renderer, groups, progress
        self.paths = self.events = 0

    def __call__(self, spp: int, seed: int, group: int = 0):
        r = self.renderer.render(self.groups[group].texels, spp, seed, progress=self.progress)
        self.paths, self.events = self.paths + r.paths, self.events + r.events
        return r.rgb, r.var_mean, spp


class PrintedSource:
    """The label volume in use by ``printer`` (``PrintedRenderer.use``), rendered on its printer texels and averaged
    onto the scene texels of each group; ``spp_printer`` counts the printer samples of the first group, ``paths``
    and ``events`` the walks of the volume."""

    def __init__(self, printer: PrintedRenderer, progress: bool):
        self.printer, self.progress, self.spp_printer = printer, progress, 0

    def __call__(self, spp: int, seed: int, group: int = 0):
        rgb, var, spp_p = self.printer(spp, seed, progress=self.progress, group=group)
        self.spp_printer += spp_p if group == 0 else 0
        return rgb, var, spp_p

    @property
    def paths(self) -> int:
        return self.printer.paths

    @property
    def events(self) -> int:
        return self.printer.events


@dataclass
class Rendered:
    """One result's renders: an ``AdaptiveResult`` per texel group (``ads``), their ``seconds``, the quantization
    ``method`` (None for the continuous result), the printer samples per texel of the first group (printed results,
    else None) and the mean scattering and interface events per path (0 before any)."""

    ads: list[AdaptiveResult]
    seconds: float
    method: str | None
    spp_printer: int | None
    events_per_path: float


def render_result(
    source,
    groups: list[TexelGroup],
    sampling: Sampling,
    shares: TimeShares,
    log: Callable,
    cmap: ColourMap = RGB,
    clock: Callable[[], float] | None = None,
) -> list:
    """``source`` rendered adaptively on each group (``sampling`` with the group's noise targets and its share of
    the time budget; ``clock``: the renders' clock, ``noise.adaptive_render``'s; ``cmap``: the colour map of the
    source's C channels, a spectral render's bands under the first
    light); one ``AdaptiveResult`` per group."""
    return [
        adaptive_render(
            partial(source, group=g),
            group.target_lab,
            replace(sampling, target=group.noise_target, ratio=group.ssim_ratio, time_budget=shares.next()),
            log=log,
            clock=clock,
            cmap=cmap,
        )
        for g, group in enumerate(groups)
    ]


def events_per_path(source) -> float:
    """Mean scattering and interface events per path of a source's renders (0 before any)."""
    return source.events / source.paths if source.paths else 0.0
