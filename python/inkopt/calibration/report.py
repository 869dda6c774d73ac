"""What ``inkopt calibrate`` reports: per-patch residuals of the fit, the held-out patches' ΔE2000 from a fit
without them (``calibration.json``), the ink file's provenance, and the picture of measured vs predicted swatches.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..io import upgrade_format, write_json

REPORT_FORMAT = 1


@dataclass
class PatchResidual:
    """One patch: CIELAB measured and predicted by the fit on all patches, its ΔE76 and ΔE2000; for a held-out
    patch also the prediction of the fit that did not see it (``holdout_lab``) and its ΔE2000."""

    sample_id: str
    description: str
    measured_lab: list[float]
    predicted_lab: list[float]
    delta_e76: float
    delta_e2000: float
    held_out: bool = False
    holdout_lab: list[float] | None = None
    holdout_delta_e2000: float | None = None


@dataclass
class CalibrationReport:
    """calibration.json: where the measurements came from (``measurements``: path, ``measurement_digest``,
    ``measurement_kind`` "lab", "xyz" or "spectral", ``illuminant``), the starting table's name, the fit's figures
    (mean and p95 ΔE2000 over the fitted patches, held-out mean and p95 ΔE2000 and how many, g, iterations,
    seconds), every patch's :class:`PatchResidual`, and the table fitted: ``model`` "rgb" (CIELAB fit) or
    "spectral" (per-band reflectance fit, ``calibration.spectral``) with its band centres ``wavelengths_nm``."""

    measurements: str
    measurement_digest: str
    measurement_kind: str
    illuminant: str
    start: str
    ink_file: str
    g: float
    fit_mean_delta_e2000: float
    fit_p95_delta_e2000: float
    holdout_count: int
    holdout_mean_delta_e2000: float | None
    holdout_p95_delta_e2000: float | None
    iterations: int
    seconds: float
    patches: list[PatchResidual] = field(default_factory=list)
    format_version: int = REPORT_FORMAT
    model: str = "rgb"
    wavelengths_nm: list[float] | None = None

    def summary(self) -> dict:
        """The figures without the patches (the ink file's provenance carries them)."""
        d = asdict(self)
        d.pop("patches")
        d.pop("format_version")
        return d

    def to_json(self, path) -> Path:
        return write_json(path, asdict(self))

    @classmethod
    def from_json(cls, path) -> CalibrationReport:
        import json

        data = upgrade_format(
            json.loads(Path(path).read_text()),
            kind="calibration report",
            where=path,
            current=REPORT_FORMAT,
            upgrades={},
        )
        data["patches"] = [PatchResidual(**p) for p in data.get("patches", [])]
        return cls(**data)


def p95(values) -> float | None:
    v = np.asarray(values, np.float64)
    return float(np.percentile(v, 95)) if v.size else None


def swatch_figure(path, report: CalibrationReport, columns: int = 12) -> Path:
    """Each patch as a swatch split in two, measured (left) and predicted (right, by the fit that did not see it
    for a held-out patch, framed in red), labelled with its SAMPLE_ID and ΔE2000."""
    from ..color import to_srgb8
    from ..pictures import _pyplot
    from .measure import lab_to_rgb

    plt = _pyplot()
    n = len(report.patches)
    rows = max(1, int(np.ceil(n / columns)))
    fig, ax = plt.subplots(figsize=(columns * 1.0, rows * 1.05 + 0.6))
    ax.set_xlim(0, columns)
    ax.set_ylim(rows, 0)
    ax.set_axis_off()
    for k, p in enumerate(report.patches):
        r, c = divmod(k, columns)
        pred = p.holdout_lab if p.held_out and p.holdout_lab is not None else p.predicted_lab
        de = p.holdout_delta_e2000 if p.held_out and p.holdout_delta_e2000 is not None else p.delta_e2000
        for half, lab in ((0, p.measured_lab), (1, pred)):
            rgb = to_srgb8(np.clip(lab_to_rgb(np.asarray(lab)[None], report.illuminant), 0, 1))[0] / 255.0
            ax.add_patch(plt.Rectangle((c + 0.05 + 0.45 * half, r + 0.05), 0.45, 0.7, color=rgb))
        if p.held_out:
            ax.add_patch(plt.Rectangle((c + 0.05, r + 0.05), 0.9, 0.7, fill=False, edgecolor="red", linewidth=1.5))
        ax.text(c + 0.5, r + 0.9, f"{p.sample_id}  {de:.2f}", ha="center", va="center", fontsize=6)
    hold = (
        f"; held out (red): mean ΔE2000 {report.holdout_mean_delta_e2000:.2f}"
        if report.holdout_mean_delta_e2000 is not None
        else ""
    )
    ax.set_title(
        f"measured (left) | predicted (right), {report.illuminant}: fit mean ΔE2000 {report.fit_mean_delta_e2000:.2f}"
        + hold,
        fontsize=9,
    )
    from ..io import save_figure

    save_figure(path, fig, dpi=120)
    plt.close(fig)
    return Path(path)
