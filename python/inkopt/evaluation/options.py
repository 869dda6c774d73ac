"""The options of an evaluation (``evaluate.evaluate_run``): one frozen ``EvaluateOptions``, checked once when it is
made, used alike by the command line (``inkopt evaluate``), the demo and scripts."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import ParameterError
from ..lighting import Lighting
from ..model import Quantization
from ..printing.quantize import check_quantization
from .colour_table import DEFAULT_PATCH_MM, ColourTable
from .noise import MAX_SPP

__all__ = ["EvaluateOptions"]


@dataclass(frozen=True)
class EvaluateOptions:
    """Every option of an evaluation; a bad value raises ``ParameterError`` naming it.

    Samples: ``spp`` samples per scene texel, used exactly, or None: adaptive (``evaluate``'s module docstring), at
    most ``max_spp`` per result and within ``time_budget`` seconds for all the adaptive renders together (shared
    out evenly among the results still to render; None: no budget). ``seed``: the render seed (the renders use
    ``noise.EVAL_SEED_OFFSET + seed``); ``threads``: render threads (None: all cores); ``lighting``: the display
    lighting every result is rendered under (``inkopt.lighting``: a ``Lighting``, "uniform" or a map file; None:
    uniform; the baselines' colour table stays a uniform-light property of the inks).

    Printed results: ``method``, the quantization method of ours (when quantized.npz is missing) and of the
    baselines (None: that of quantized.npz, else ``Quantization``'s default). ``baselines``: render the print-shop
    baselines, their colour table ``table`` (None: ``colour_table(inks, g, ior, patch_mm)``, cached) of patches
    ``patch_mm`` thick, looked up by the blend of the nearest entries (``refine``) or the nearest entry.

    ``translucency``: measure the translucency figures (None: when the scene is constrained or
    ``translucency_compare``, the run directory of an unconstrained run of the same target, is given).
    ``texel_sample``, ``sample_windows``: figures from a random sample of that many scene texels and SSIM windows
    (``evaluation.sample``; 0 texels renders every texel; None: every texel or a sample, whichever
    ``evaluation.choice`` predicts to be faster at the same accuracy; windows None: ``sample.DEFAULT_SAMPLE_WINDOWS``).

    Output: ``out``, the evaluation file (None: DIR/evaluation.json; its pictures are named after it, e.g. E.json:
    E_top.png, E_views.png), so that earlier ones can be kept; ``write``: write it, the pictures and
    predictions.npz (else only return the ``Evaluation``)."""

    spp: int | None = None
    max_spp: int = MAX_SPP
    time_budget: float | None = None
    seed: int = 0
    threads: int | None = None
    lighting: Lighting | str | None = None
    method: str | None = None
    baselines: bool = True
    table: ColourTable | None = field(default=None, compare=False, repr=False)
    patch_mm: float = DEFAULT_PATCH_MM
    refine: bool = True
    translucency: bool | None = None
    translucency_compare: str | Path | None = None
    texel_sample: int | None = None
    sample_windows: int | None = None
    out: str | Path | None = None
    write: bool = True

    def __post_init__(self):
        for name in ("spp", "max_spp"):
            value = getattr(self, name)
            if value is not None and not value >= 1:
                raise ParameterError(f"`{name}` must be at least 1, got {value}")
        if self.time_budget is not None and not self.time_budget > 0:
            raise ParameterError(f"`time_budget` must be a positive number of seconds, got {self.time_budget}")
        if self.method is not None:
            check_quantization(Quantization(self.method))
        if not (math.isfinite(self.patch_mm) and self.patch_mm > 0):
            raise ParameterError(f"`patch_mm` must be a positive thickness in mm, got {self.patch_mm}")
        if self.texel_sample is not None and (self.texel_sample < 0 or self.texel_sample == 1):
            raise ParameterError(
                f"`texel_sample` must be 0 (every texel) or at least 2 texels, got {self.texel_sample}"
            )
        if self.sample_windows is not None and self.sample_windows < 2:
            raise ParameterError(f"`sample_windows` must be at least 2, got {self.sample_windows}")
        if self.out is not None and Path(self.out).suffix != ".json":
            raise ParameterError(f"`out` must name a .json file, got {Path(self.out)}")
