"""Units and grids, in one place (docs/conventions.md).

Lengths are in mm, coefficients in mm^-1. The optimisation grid has cubic voxels of ``OPT_DPI`` (300 DPI,
25.4 / 300 ≈ 0.0847 mm, docs/method.md §2); the printer grid is anisotropic, ``PRINTER_DPI`` (x, y) dots per inch and
``PRINTER_LAYER_UM`` µm layers in z (docs/method.md §7). Vectors of sizes and resolutions are (x, y, z).
"""

from __future__ import annotations

import numpy as np

from .errors import ParameterError

MM_PER_INCH = 25.4
#: resolution of the optimisation grid (dots per inch; voxels are cubes)
OPT_DPI = 300.0
#: printer resolution in x and y (dots per inch) and its layer thickness (µm) by default
PRINTER_DPI = (600.0, 300.0)
PRINTER_LAYER_UM = 27.0


def voxel_mm(dpi: float = OPT_DPI) -> float:
    """Edge of a voxel (mm) of a grid of ``dpi`` dots per inch; a one-line ValueError unless ``dpi`` is positive."""
    if not (np.isfinite(dpi) and dpi > 0):
        raise ParameterError(f"`dpi` must be positive, got {dpi}")
    return MM_PER_INCH / float(dpi)


def dpi_of(voxel_mm_xyz) -> np.ndarray:
    """Dots per inch (float64 array) of voxel sizes in mm."""
    return MM_PER_INCH / np.asarray(voxel_mm_xyz, np.float64)


def parse_dpi(text: str) -> tuple[float, ...]:
    """'600x300' or '600x300x940' -> tuple of 2 or 3 positive floats (x, y[, z] dots per inch)."""
    try:
        vals = tuple(float(v) for v in str(text).lower().split("x"))
    except ValueError:
        vals = ()
    if len(vals) not in (2, 3) or not all(np.isfinite(v) and v > 0 for v in vals):
        raise ParameterError(f"`dpi` must look like 600x300 or 600x300x940 (positive numbers), got '{text}'")
    return vals


def parse_size_mm(text: str) -> tuple[float, float, float]:
    """'WxHxD' in mm -> (W, H, D)."""
    try:
        w, h, d = (float(v) for v in text.lower().split("x"))
    except ValueError:
        raise ParameterError(
            f"`size_mm` must look like 15x10x2.5 (width x height x depth in mm), got '{text}'"
        ) from None
    if min(w, h, d) <= 0:
        raise ParameterError(f"`size_mm` sizes must be positive, got '{text}'")
    return w, h, d


def parse_duration(text: str) -> float:
    """Seconds of a duration as people write it: "1800", "90s", "30m", "1h", "1h30m", "2h15m30s"."""
    import re

    t = str(text).strip().lower().replace(" ", "")
    m = re.fullmatch(r"(?:(\d+(?:\.\d+)?)h)?(?:(\d+(?:\.\d+)?)m(?:in)?)?(?:(\d+(?:\.\d+)?)s?)?", t)
    if not t or m is None or not any(m.groups()):
        raise ValueError(f"a duration must look like 1800, 90s, 30m or 1h30m, got '{text}'")
    h, mi, s = (float(g) if g else 0.0 for g in m.groups())
    seconds = 3600 * h + 60 * mi + s
    if not seconds > 0:
        raise ValueError(f"a duration must be positive, got '{text}'")
    return seconds


def format_duration(seconds: float) -> str:
    """A wall time for people: "1 h 02 min", "3 min 05 s" or "42 s"."""
    s = int(round(max(seconds, 0.0)))
    if s >= 3600:
        return f"{s // 3600} h {s % 3600 // 60:02d} min"
    return f"{s // 60} min {s % 60:02d} s" if s >= 60 else f"{s} s"
