"""``inkopt calibrate``: measured chart -> fitted ink table, report and picture.

Steps: read the CGATS.17 file (chart columns and measurements), check that it identifies every parameter, convert
the measurements to CIELAB under the illuminant, draw the hold-out (``fit.choose_holdout``), fit without the
held-out patches and predict them, then fit all patches (starting from the first fit's table) for the ink file.
Spectral measurements are fitted spectrally (``calibration.spectral``: reflectance per band on a 20 or 10 nm grid
over 400-700 nm, a spectral ink file) unless ``spectral=False`` asks for the CIELAB fit of an RGB table; CIELAB and
XYZ measurements always take the CIELAB fit. The reports' figures are CIELAB under the illuminant either way.
The ink file carries ``provenance`` (the measurement file's digest, illuminant, start table, residual figures).
Every output is checked for (and its folder for taking a new file) before anything is read or written, and
written atomically.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..color import delta_e76, delta_e2000
from ..errors import ParameterError
from ..io import file_digest
from ..model.inks import write_ink_file
from ..model.spectral import (
    WAVELENGTHS_10NM,
    WAVELENGTHS_20NM,
    SpectralInkTable,
    load_ink_table,
    write_spectral_ink_file,
)
from .cgats import CgatsTable, canonical_field
from .cgats import read as read_cgats
from .chart import Chart, chart_from_table, check_identifiable, start_table
from .fit import FitResult, choose_holdout, fit_inks
from .measure import (
    LAB_FIELDS,
    MEASUREMENT_KEYWORDS,
    XYZ_FIELDS,
    illuminant_name,
    measured_lab,
    measured_reflectance,
    spectral_to_lab,
)
from .report import CalibrationReport, PatchResidual, p95, swatch_figure


def output_paths(out_inks) -> dict:
    """The ink file and, beside it, ``<stem>.report.json`` and ``<stem>.swatches.png``; one-line error unless the
    folder exists and takes a new file (a probe file is made and removed there, so a fit of a minute or more
    does not end in a write error)."""
    p = Path(out_inks)
    if p.suffix.lower() != ".json":
        raise ParameterError(f"`out_inks` must name a .json ink file, got {out_inks}")
    if not p.parent.is_dir():
        raise ParameterError(f"`out_inks`: folder {p.parent} does not exist")
    if p.is_dir():
        raise ParameterError(f"`out_inks` {out_inks} is a folder; name the .json ink file to write")
    try:
        fd, probe = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".probe", dir=p.parent)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise ParameterError(f"`out_inks`: cannot write in folder {p.parent} ({exc.strerror or exc})") from None
    return {"inks": p, "report": p.with_suffix(".report.json"), "picture": p.with_suffix(".swatches.png")}


def is_measurement_field(name: str) -> bool:
    c = canonical_field(name)
    return c in (*LAB_FIELDS, *XYZ_FIELDS) or c.startswith("SPECTRAL_NM")


def _rows_by_id(table: CgatsTable, where: str) -> dict:
    """SAMPLE_ID -> row of an instrument's file; a SAMPLE_ID that appears twice is an error (which row would be
    the patch's measurement?)."""
    rows: dict = {}
    for no, (sid, r) in enumerate(zip(table.column("SAMPLE_ID"), table.rows), start=1):
        if sid in rows:
            raise ValueError(f"{where}: SAMPLE_ID {sid} appears twice (data rows {rows[sid][0]} and {no}); keep one")
        rows[sid] = (no, r)
    return {sid: r for sid, (_, r) in rows.items()}


def merge_measurements(chart: CgatsTable, measured: CgatsTable, where: str) -> CgatsTable:
    """The chart's columns with the measurement columns of ``measured`` (an instrument's file), joined on
    SAMPLE_ID, and the measured file's header keywords that say how to read them (``MEASUREMENT_KEYWORDS``);
    every patch of the chart must have been measured (ValueError naming the first that was not), and no SAMPLE_ID
    measured twice."""
    fields = [f for f in measured.fields if is_measurement_field(f)]
    if not fields:
        raise ValueError(
            f"{where}: no measurement columns (LAB_L LAB_A LAB_B, XYZ_X XYZ_Y XYZ_Z, or SPECTRAL_NM380 ... "
            "SPECTRAL_NM730 / SPEC_380 ... SPEC_730)"
        )
    cols = [measured.fields.index(f) for f in fields]
    if not measured.has("SAMPLE_ID"):
        raise ValueError(f"{where}: no SAMPLE_ID column to match the chart's patches")
    rows = _rows_by_id(measured, where)
    keep = [i for i, f in enumerate(chart.fields) if not is_measurement_field(f)]
    if not chart.has("SAMPLE_ID"):
        raise ValueError("the chart file has no SAMPLE_ID column")
    out = []
    for sid, r in zip(chart.column("SAMPLE_ID"), chart.rows):
        m = rows.get(sid)
        if m is None:
            raise ValueError(f"{where}: patch {sid} of the chart has no measurement (no row with that SAMPLE_ID)")
        out.append([r[i] for i in keep] + [m[c] for c in cols])
    header = {k: v for k, v in chart.header.items() if k.upper() not in MEASUREMENT_KEYWORDS}
    header.update({k: v for k, v in measured.header.items() if k.upper() in MEASUREMENT_KEYWORDS})
    return CgatsTable([chart.fields[i] for i in keep] + fields, out, header, chart.source)


BAND_GRIDS = {20.0: WAVELENGTHS_20NM, 10.0: WAVELENGTHS_10NM}


@dataclass(frozen=True)
class CalibrateOptions:
    """How a fit is made: ``start`` the starting ink table (a preset, list or ink file), ``illuminant`` of the
    measurements ("D50" or "D65"; spectral measurements: any light ``spectral.lights.load_light`` takes),
    ``holdout`` the share of patches held out to test the fit (drawn with ``seed``), ``fit_g`` whether the shared
    g is fitted (else kept at the start's), ``spectral`` whether spectral measurements are fitted spectrally (else
    reduced to CIELAB for an RGB table), on bands ``band_nm`` apart over 400-700 nm (20: 16 bands, or 10: 31
    bands)."""

    start: str = "vero-cmykw"
    illuminant: str = "D50"
    holdout: float = 0.2
    seed: int = 0
    fit_g: bool = True
    spectral: bool = True
    band_nm: float = 20.0

    def validate(self) -> None:
        if not (np.isfinite(self.holdout) and 0 <= self.holdout < 1):
            raise ParameterError(f"`holdout` must lie in [0, 1), got {self.holdout}")
        if self.band_nm not in BAND_GRIDS:
            raise ParameterError(f"`band_nm` must be one of {sorted(BAND_GRIDS)}, got {self.band_nm:g}")

    def grid(self) -> np.ndarray:
        """(B,) nm: the spectral table's band centres."""
        return BAND_GRIDS[self.band_nm]


@dataclass(frozen=True)
class _Fit:
    """The fits of ``calibrate``: the chart, its measured CIELAB (P, 3), the held-out patches' indices and their
    predictions by the fit without them ((H, 3) or None), and the fit of all patches (``fit.FitResult``) with the
    first fit's evaluations and seconds."""

    chart: Chart
    lab: np.ndarray
    kind: str
    held: np.ndarray
    hold_lab: np.ndarray | None
    full: FitResult
    iterations: int
    seconds: float


def calibrate(
    measured, out_inks, options: CalibrateOptions = CalibrateOptions(), chart_file=None, log=print
) -> CalibrationReport:
    """Fit the ink table of the chart file ``measured`` and write the ink file ``out_inks`` with its report and
    picture (:func:`output_paths`). With ``chart_file``, ``measured`` is an instrument's file that holds only
    SAMPLE_ID and measurement columns, matched to the chart's patches by SAMPLE_ID. Returns the report."""
    options.validate()
    paths = output_paths(out_inks)
    table = read_cgats(measured)
    if chart_file is not None:
        table = merge_measurements(read_cgats(chart_file), table, str(measured))
    chart = chart_from_table(table, str(chart_file or measured))
    check_identifiable(chart)
    fit = _fit(chart, table, options, log)
    report = _report(fit, measured, options, paths)
    swatch_figure(paths["picture"], report)
    report.to_json(paths["report"])
    extra = {} if chart_file is None else {"chart": str(chart_file), "chart_digest": file_digest(chart_file)}
    provenance = {"made_by": "inkopt calibrate", **report.summary(), **extra}
    if isinstance(fit.full.inks, SpectralInkTable):
        write_spectral_ink_file(paths["inks"], fit.full.inks, provenance)
    else:
        write_ink_file(paths["inks"], fit.full.inks, provenance)
    return report


def _fit(chart, table: CgatsTable, options: CalibrateOptions, log) -> _Fit:
    """Fit without the held-out patches and predict them, then fit all patches from the first fit's table: the
    spectral fit (:func:`_fit_spectral`) for spectral measurements unless ``options.spectral`` is off, else the
    CIELAB fit."""
    from .fit import predict_lab

    illuminant = options.illuminant
    lab, kind = measured_lab(table, illuminant)
    if kind == "spectral" and options.spectral:
        return _fit_spectral(chart, table, lab, options, log)
    start = load_ink_table(options.start)
    if isinstance(start, SpectralInkTable):
        raise ParameterError(
            f"`start` {options.start} is a spectral ink table; a CIELAB fit ({kind} measurements) starts from an "
            "RGB one"
        )
    start_inks = start_table(chart, start)
    held = choose_holdout(chart, options.holdout, options.seed)
    keep = np.setdiff1d(np.arange(len(chart)), held)
    log(
        f"{len(chart)} patches of {', '.join(chart.inks)} ({kind}, {illuminant_name(illuminant)}); {len(held)} held out"
    )
    iterations, seconds, hold_lab, first = 0, 0.0, None, start_inks
    if len(held):
        r = fit_inks(chart.subset(keep), lab[keep], start_inks, illuminant, fit_g=options.fit_g)
        hold_lab = predict_lab(chart.subset(held), r.inks, illuminant)
        iterations, seconds, first = r.iterations, r.seconds, r.inks
        log(f"fit without the held-out patches: {r.iterations} evaluations, {r.seconds:.1f} s")
    full = fit_inks(chart, lab, first, illuminant, fit_g=options.fit_g)
    log(f"fit of all patches: {full.iterations} evaluations, {full.seconds:.1f} s, g = {full.inks.g:.3f}")
    return _Fit(chart, lab, kind, held, hold_lab, full, iterations, seconds)


def _fit_spectral(chart, table: CgatsTable, lab: np.ndarray, options: CalibrateOptions, log) -> _Fit:
    """The spectral path of :func:`_fit`: measured reflectance band-averaged onto the options' grid, a per-band
    fit without the held-out patches (their CIELAB predicted from the predicted spectra), then of all patches."""
    from .spectral import band_average, fit_spectral_inks, predict_reflectance, spectral_start

    grid = options.grid()
    wl, refl = measured_reflectance(table)
    try:
        measured = band_average(wl, refl, grid)
    except ValueError as exc:
        raise ParameterError(f"`band_nm` {options.band_nm:g}: {exc}") from None
    first = spectral_start(chart, load_ink_table(options.start), grid)
    held = choose_holdout(chart, options.holdout, options.seed)
    keep = np.setdiff1d(np.arange(len(chart)), held)
    ill = options.illuminant
    log(f"{len(chart)} patches of {', '.join(chart.inks)} (spectral, {len(grid)} bands); {len(held)} held out")
    iterations, seconds, hold_lab = 0, 0.0, None
    if len(held):
        r = fit_spectral_inks(chart.subset(keep), measured[keep], first, fit_g=options.fit_g)
        hold_lab = spectral_to_lab(grid, predict_reflectance(chart.subset(held), r.inks), ill)
        iterations, seconds, first = r.iterations, r.seconds, r.inks
        log(f"fit without the held-out patches: {r.iterations} evaluations, {r.seconds:.1f} s")
    s = fit_spectral_inks(chart, measured, first, fit_g=options.fit_g)
    log(f"fit of all patches: {s.iterations} evaluations, {s.seconds:.1f} s, g = {s.inks.g:.3f}")
    pred_lab = spectral_to_lab(grid, s.predicted, ill)
    full = FitResult(s.inks, pred_lab, s.iterations, s.seconds, s.cost, s.converged, s.message)
    return _Fit(chart, lab, "spectral", held, hold_lab, full, iterations, seconds)


def _residuals(fit: _Fit) -> tuple[list[PatchResidual], np.ndarray, np.ndarray]:
    """Every patch's residual, the fit's ΔE2000 (P,) and the held-out patches' (H,)."""
    lab, pred = fit.lab, fit.full.predicted_lab
    de00, de76 = delta_e2000(pred, lab), delta_e76(pred, lab)
    hold_de = delta_e2000(fit.hold_lab, lab[fit.held]) if fit.hold_lab is not None else np.zeros(0)
    hold_at = {int(i): k for k, i in enumerate(fit.held)}
    patches = []
    for i, p in enumerate(fit.chart.patches):
        k = hold_at.get(i)
        patches.append(
            PatchResidual(
                p.sample_id,
                p.describe(fit.chart.inks),
                [float(v) for v in lab[i]],
                [float(v) for v in pred[i]],
                float(de76[i]),
                float(de00[i]),
                k is not None,
                None if k is None else [float(v) for v in fit.hold_lab[k]],
                None if k is None else float(hold_de[k]),
            )
        )
    return patches, de00, hold_de


def _report(fit: _Fit, measured, options: CalibrateOptions, paths: dict) -> CalibrationReport:
    patches, de00, hold_de = _residuals(fit)
    spectral = isinstance(fit.full.inks, SpectralInkTable)
    return CalibrationReport(
        measurements=str(measured),
        measurement_digest=file_digest(measured),
        measurement_kind=fit.kind,
        illuminant=illuminant_name(options.illuminant),
        start=str(options.start),
        ink_file=str(paths["inks"]),
        g=float(fit.full.inks.g),
        fit_mean_delta_e2000=float(de00.mean()),
        fit_p95_delta_e2000=p95(de00),
        holdout_count=int(len(fit.held)),
        holdout_mean_delta_e2000=float(hold_de.mean()) if len(hold_de) else None,
        holdout_p95_delta_e2000=p95(hold_de),
        iterations=int(fit.iterations + fit.full.iterations),
        seconds=float(fit.seconds + fit.full.seconds),
        patches=patches,
        model="spectral" if spectral else "rgb",
        wavelengths_nm=[float(w) for w in fit.full.inks.wavelengths_nm] if spectral else None,
    )
