"""Measurements of calibration patches and the renderer's colours in one frame: CIELAB under the measurement's
illuminant (CIE 1931 2° observer), through ``colour-science`` (observer, illuminants, Bradford chromatic
adaptation).

A measurement is CIELAB (``LAB_L LAB_A LAB_B``, under the illuminant, as colour instruments report) or a spectral
reflectance (``SPECTRAL_NM380 ... SPECTRAL_NM730``, any evenly spaced bands covering 400-700 nm, as fractions or
percent: a table whose largest value exceeds 2 is read as percent), integrated under the illuminant (ASTM E308).
A prediction is the renderer's linear RGB (sRGB primaries, D65 white, ``inkopt.color``): its XYZ, adapted from
that white to the illuminant's by Bradford, then CIELAB relative to the illuminant's white (a perfect white
reflector has L* = 100 in both frames).
"""

from __future__ import annotations

import warnings

import numpy as np

from ..color import RGB_TO_XYZ, WHITE_XYZ
from .cgats import CgatsTable

ILLUMINANTS = ("D50", "D65")
OBSERVER = "CIE 1931 2 Degree Standard Observer"
LAB_FIELDS = ("LAB_L", "LAB_A", "LAB_B")
PERCENT_ABOVE = 2.0


class MeasurementError(ValueError):
    """Missing, malformed or out-of-range measurements (one line)."""


def _colour():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    return colour


def _check_illuminant(name: str) -> str:
    up = str(name).upper()
    if up not in ILLUMINANTS:
        raise MeasurementError(f"illuminant must be one of {list(ILLUMINANTS)}, got '{name}'")
    return up


def white_xy(illuminant: str) -> np.ndarray:
    """Chromaticity (2,) of the illuminant for the 2° observer."""
    return np.asarray(_colour().CCS_ILLUMINANTS[OBSERVER][_check_illuminant(illuminant)], np.float64)


def rgb_to_xyz_matrix(illuminant: str) -> np.ndarray:
    """(3, 3): linear RGB -> XYZ adapted (Bradford) from the sRGB D65 white to the illuminant's, Y of white 1."""
    colour = _colour()
    target = colour.xy_to_XYZ(white_xy(illuminant))
    cat = colour.adaptation.matrix_chromatic_adaptation_VonKries(WHITE_XYZ, target, transform="Bradford")
    return cat @ RGB_TO_XYZ


def rgb_to_lab(rgb, illuminant: str) -> np.ndarray:
    """Linear RGB (..., 3) -> CIELAB (..., 3) under ``illuminant`` (module docstring)."""
    xyz = np.asarray(rgb, np.float64) @ rgb_to_xyz_matrix(illuminant).T
    return _colour().XYZ_to_Lab(xyz, white_xy(illuminant))


def rgb_to_lab_jacobian(rgb, illuminant: str) -> np.ndarray:
    """d Lab / d rgb, (P, 3, 3) (row: L*, a*, b*; column: R, G, B), by central differences (step 1e-6)."""
    rgb = np.asarray(rgb, np.float64)
    h = 1e-6
    jac = np.empty(rgb.shape + (3,))
    for c in range(3):
        d = np.zeros(3)
        d[c] = h
        jac[..., :, c] = (rgb_to_lab(rgb + d, illuminant) - rgb_to_lab(rgb - d, illuminant)) / (2 * h)
    return jac


def lab_to_rgb(lab, illuminant: str) -> np.ndarray:
    """CIELAB under ``illuminant`` -> linear RGB (the inverse of :func:`rgb_to_lab`; for pictures)."""
    xyz = _colour().Lab_to_XYZ(np.asarray(lab, np.float64), white_xy(illuminant))
    return xyz @ np.linalg.inv(rgb_to_xyz_matrix(illuminant)).T


def _numbers(values, what: str, ids) -> np.ndarray:
    out = np.empty(len(values))
    for k, (v, sid) in enumerate(zip(values, ids)):
        if v.strip() == "":
            raise MeasurementError(f"patch {sid} has no measurement ({what} is empty)")
        try:
            out[k] = float(v)
        except ValueError:
            raise MeasurementError(f"patch {sid}: {what} is '{v}', not a number") from None
        if not np.isfinite(out[k]):
            raise MeasurementError(f"patch {sid}: {what} is {v}")
    return out


def spectral_fields(table: CgatsTable) -> list[tuple[int, str]]:
    """(wavelength nm, field as written) of the table's spectral columns, by wavelength."""
    from .cgats import canonical_field

    out = []
    for f in table.fields:
        c = canonical_field(f)
        if c.startswith("SPECTRAL_NM"):
            out.append((int(c[len("SPECTRAL_NM") :]), c))
    return sorted(out)


def measured_lab(table: CgatsTable, illuminant: str = "D50") -> tuple[np.ndarray, str]:
    """(P, 3) CIELAB of every row under ``illuminant`` and the kind read ("spectral" or "lab"). Spectral columns
    win when both are present (they are converted under the chosen illuminant; a LAB column may have been
    computed under another)."""
    illuminant = _check_illuminant(illuminant)
    ids = table.column("SAMPLE_ID")
    spec = spectral_fields(table)
    if spec:
        wl = np.array([w for w, _ in spec], np.float64)
        steps = np.diff(wl)
        if len(wl) < 4 or wl[0] > 400 or wl[-1] < 700 or np.any(steps <= 0) or np.ptp(steps) > 0:
            raise MeasurementError(
                f"spectral columns must be evenly spaced and cover 400-700 nm; got {len(wl)} bands "
                f"{wl[0]:g}-{wl[-1]:g} nm"
            )
        refl = np.stack([_numbers(table.column(c), c, ids) for _, c in spec], axis=1)
        if refl.max() > PERCENT_ABOVE:
            refl = refl / 100.0
        bad = np.flatnonzero((refl < -0.01).any(1) | (refl > 1.5).any(1))
        if len(bad):
            raise MeasurementError(f"patch {ids[bad[0]]}: spectral reflectance outside [0, 1.5] (or [0, 150] %)")
        return spectral_to_lab(wl, refl, illuminant), "spectral"
    missing = [f for f in LAB_FIELDS if not table.has(f)]
    if missing:
        raise MeasurementError(
            f"no measurement columns: missing {', '.join(missing)} (or SPECTRAL_NM380 ... SPECTRAL_NM730)"
        )
    lab = np.stack([_numbers(table.column(f), f, ids) for f in LAB_FIELDS], axis=1)
    bad = np.flatnonzero((lab[:, 0] < 0) | (lab[:, 0] > 100.5) | (np.abs(lab[:, 1:]) > 200).any(1))
    if len(bad):
        raise MeasurementError(
            f"patch {ids[bad[0]]}: L*a*b* {lab[bad[0]].tolist()} out of range (L* 0-100, |a*|,|b*| <= 200)"
        )
    return lab, "lab"


def spectral_to_lab(wavelengths_nm, reflectance, illuminant: str) -> np.ndarray:
    """Reflectance (P, W) at ``wavelengths_nm`` (W,) -> CIELAB (P, 3) under ``illuminant``, 2° observer, ASTM
    E308 integration (``colour.sd_to_XYZ``)."""
    colour = _colour()
    cmfs = colour.MSDS_CMFS[OBSERVER]
    sd_ill = colour.SDS_ILLUMINANTS[_check_illuminant(illuminant)]
    out = np.empty((len(reflectance), 3))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for k, r in enumerate(np.asarray(reflectance, np.float64)):
            sd = colour.SpectralDistribution(dict(zip(np.asarray(wavelengths_nm, float), r)))
            xyz = colour.sd_to_XYZ(sd, cmfs, sd_ill) / 100.0
            out[k] = colour.XYZ_to_Lab(xyz, white_xy(illuminant))
    return out
