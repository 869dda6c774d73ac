"""Calibration: fit the ink table (σs, σa per channel, or per wavelength band from spectral measurements, of every
ink, the shared g) to a lab's own printed and measured patches (docs/calibration.md).

``chart`` designs the patch set and checks that it identifies every parameter; ``cgats`` reads and writes
CGATS.17 tables; ``job`` writes the printable chart and its layout; ``measure`` turns CIELAB or spectral
measurements and the renderer's linear RGB into CIELAB under the measurement's illuminant (``colour-science``);
``spectral`` fits a spectral table per band to measured reflectance (and the library's spectral form to its RGB
colours); ``stack`` is the measurement model (a laterally infinite two-layer stack under light from the upper
hemisphere: adding-doubling, and the Monte Carlo renderer as its reference); ``fit`` minimises the colour error;
``report`` and ``calibrate`` write the ink file, its report and picture.
"""

from .calibrate import CalibrateOptions, calibrate
from .cgats import CgatsError, CgatsTable
from .chart import Chart, ChartError, Patch, chart_from_table, check_identifiable, design_chart
from .fit import FitResult, fit_inks, predict_lab, predict_rgb
from .job import write_chart
from .measure import MeasurementError, measured_lab, rgb_to_lab
from .report import CalibrationReport, PatchResidual
from .spectral import SpectralFitResult, fit_spectral_inks, predict_reflectance, spectral_form
from .stack import Stack, reflectance_ad, reflectance_mc

__all__ = [
    "CalibrateOptions",
    "CalibrationReport",
    "CgatsError",
    "CgatsTable",
    "Chart",
    "ChartError",
    "FitResult",
    "MeasurementError",
    "Patch",
    "PatchResidual",
    "SpectralFitResult",
    "Stack",
    "calibrate",
    "chart_from_table",
    "check_identifiable",
    "design_chart",
    "fit_inks",
    "fit_spectral_inks",
    "measured_lab",
    "predict_lab",
    "predict_reflectance",
    "predict_rgb",
    "reflectance_ad",
    "reflectance_mc",
    "rgb_to_lab",
    "spectral_form",
    "write_chart",
]
