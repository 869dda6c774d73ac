"""Measurements of calibration patches and the renderer's colours in one frame: CIELAB under the measurement's
illuminant (CIE 1931 2° observer), through ``colour-science`` (observer, illuminants, Bradford chromatic
adaptation).

A measurement is a spectral reflectance (``SPECTRAL_NM380 ... SPECTRAL_NM730``, ArgyllCMS's ``SPEC_380 ...
SPEC_730``: any evenly spaced bands covering 400-700 nm, at the wavelengths the header's ``SPECTRAL_BANDS``,
``SPECTRAL_START_NM`` and ``SPECTRAL_END_NM`` give, divided by its ``SPECTRAL_NORM``; without one, as fractions or
percent: a table whose largest value exceeds 2 is read as percent), integrated under the illuminant (ASTM E308);
or CIELAB (``LAB_L LAB_A LAB_B``, under the illuminant, as colour instruments report); or CIE XYZ (``XYZ_X XYZ_Y
XYZ_Z`` on the 0-100 scale, as ArgyllCMS's .ti3 files hold them), relative to the file's white
(``ILLUMINANT_WHITE_POINT_XYZ``, D50 without it) and adapted by Bradford to the illuminant's where that differs
(an approximation: spectral columns are exact), then CIELAB.
A prediction is the renderer's linear RGB (sRGB primaries, D65 white, ``inkopt.color``): its XYZ, adapted from
that white to the illuminant's by Bradford, then CIELAB relative to the illuminant's white (a perfect white
reflector has L* = 100 in both frames).
The illuminant is D50 or D65 (colour-science's tables and chromaticities, as instruments report) or, for spectral
measurements only, any light of ``spectral.lights``: a named one (A, F11, LED-B3) or a FILE.csv of (nm, relative
power) rows, whose white is that of a perfect reflector under it. CIELAB and XYZ measurements were taken under
the instrument's illuminant, so only D50 and D65 are taken with them.
"""

from __future__ import annotations

import warnings
from functools import lru_cache

import numpy as np

from ..color import RGB_TO_XYZ, WHITE_XYZ
from ..errors import ParameterError
from .cgats import CgatsTable

ILLUMINANTS = ("D50", "D65")
OBSERVER = "CIE 1931 2 Degree Standard Observer"
LAB_FIELDS = ("LAB_L", "LAB_A", "LAB_B")
XYZ_FIELDS = ("XYZ_X", "XYZ_Y", "XYZ_Z")
PERCENT_ABOVE = 2.0
# the header keywords that say how a table's measurement columns are read
MEASUREMENT_KEYWORDS = (
    "SPECTRAL_BANDS",
    "SPECTRAL_START_NM",
    "SPECTRAL_END_NM",
    "SPECTRAL_NORM",
    "ILLUMINANT_WHITE_POINT_XYZ",
)
ASTM_INTERVALS = (1.0, 5.0, 10.0, 20.0)  # the band widths (nm) ASTM E308 integrates as they are


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


def illuminant_name(name: str) -> str:
    """An illuminant as reports name it: D50 or D65 (any case), a named light of ``spectral.lights`` (any case,
    spelled as there: "A", "F11", "LED-B3"), else the light file's path as given."""
    from ..spectral.lights import NAMED

    up = str(name).upper()
    return up if up in ILLUMINANTS else {k.upper(): k for k in NAMED}.get(up, str(name))


def illuminant_sd(illuminant: str):
    """The illuminant's ``colour.SpectralDistribution``: colour-science's D50 or D65 table as it is, else the light
    of ``spectral.lights.load_light`` (a named light or a FILE.csv of nm, relative power rows) on its 1 nm grid
    (360-830 nm), as the renderer's colour maps see it. A ParameterError naming `illuminant` for an unknown name or
    a bad file."""
    colour = _colour()
    name = illuminant_name(illuminant)
    if name in ILLUMINANTS:
        return colour.SDS_ILLUMINANTS[name]
    from ..spectral.lights import GRID_NM, load_light

    return colour.SpectralDistribution(dict(zip(GRID_NM, load_light(name).on_grid())), name=name)


def white_xy(illuminant: str) -> np.ndarray:
    """Chromaticity (2,) of the illuminant for the 2° observer: colour-science's tabulated one for D50 and D65,
    else that of a perfect white reflector under the light (:func:`illuminant_sd`, ASTM E308 integration)."""
    colour = _colour()
    name = illuminant_name(illuminant)
    if name in ILLUMINANTS:
        return np.asarray(colour.CCS_ILLUMINANTS[OBSERVER][name], np.float64)
    return _light_white_xy(name).copy()


@lru_cache(maxsize=8)
def _light_white_xy(name: str) -> np.ndarray:
    """:func:`white_xy` of a light other than D50 and D65, computed once per name in a process (a fit asks for it
    at every evaluation)."""
    return _white_xy_of(illuminant_sd(name))


def _white_xy_of(sd_ill) -> np.ndarray:
    """The chromaticity (2,) of a perfect white reflector (reflectance 1 over 360-830 nm) under ``sd_ill``."""
    colour = _colour()
    flat = colour.SpectralDistribution(dict(zip(np.arange(360.0, 831.0), np.ones(471))))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        xyz = colour.sd_to_XYZ(flat, colour.MSDS_CMFS[OBSERVER], sd_ill)
    return np.asarray(colour.XYZ_to_xy(xyz), np.float64)


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
        if c.startswith("SPECTRAL_NM") and c[len("SPECTRAL_NM") :].isdigit():
            out.append((int(c[len("SPECTRAL_NM") :]), c))
    return sorted(out)


def _keyword(table: CgatsTable, name: str) -> str | None:
    """A header keyword's value (keywords compared in upper case), or None."""
    return next((v for k, v in table.header.items() if k.upper() == name), None)


def _header_number(table: CgatsTable, name: str) -> float | None:
    v = _keyword(table, name)
    if v is None:
        return None
    try:
        x = float(v)
    except ValueError:
        raise MeasurementError(f"header keyword {name} is '{v}', not a number") from None
    if not np.isfinite(x):
        raise MeasurementError(f"header keyword {name} is {v}")
    return x


def spectral_wavelengths(table: CgatsTable, spec: list[tuple[int, str]]) -> np.ndarray:
    """The wavelengths (W,) nm of the spectral columns ``spec`` (``spectral_fields``): from the header's
    ``SPECTRAL_BANDS``, ``SPECTRAL_START_NM`` and ``SPECTRAL_END_NM`` where it gives them (ArgyllCMS names its
    columns by the rounded wavelength: ``SPEC_383`` is 383.33 nm in its 3.3 nm mode), else the fields' names.
    MeasurementError unless they are evenly spaced and cover 400-700 nm, or disagree with the header."""
    wl = np.array([w for w, _ in spec], np.float64)
    bands = _header_number(table, "SPECTRAL_BANDS")
    if bands is not None:
        start = _header_number(table, "SPECTRAL_START_NM")
        end = _header_number(table, "SPECTRAL_END_NM")
        start, end = wl[0] if start is None else start, wl[-1] if end is None else end
        if bands != len(wl) or not end > start:
            raise MeasurementError(
                f"the header declares {bands:g} spectral bands from {start:g} to {end:g} nm, but the table has "
                f"{len(wl)} spectral columns from {wl[0]:g} to {wl[-1]:g} nm"
            )
        declared = np.linspace(start, end, len(wl))
        off = np.flatnonzero(np.abs(declared - wl) > 1.0)
        if len(off):
            raise MeasurementError(
                f"spectral column {spec[off[0]][1]} is not at {declared[off[0]]:.4g} nm, where the header's "
                f"SPECTRAL_START_NM, SPECTRAL_END_NM and SPECTRAL_BANDS put it"
            )
        wl = declared
    steps = np.diff(wl)
    if len(wl) < 4 or wl[0] > 400 or wl[-1] < 700 or np.any(steps <= 0) or np.ptp(steps) > 1e-6 * steps.mean():
        raise MeasurementError(
            f"spectral columns must be evenly spaced and cover 400-700 nm; got {len(wl)} bands {wl[0]:g}-{wl[-1]:g} nm"
        )
    return wl


def _spectral_lab(table: CgatsTable, spec, ids, illuminant: str) -> np.ndarray:
    """CIELAB of the spectral columns (:func:`measured_reflectance`) under ``illuminant``."""
    wl, refl = measured_reflectance(table, spec, ids)
    return spectral_to_lab(wl, refl, illuminant)


def measured_reflectance(table: CgatsTable, spec=None, ids=None) -> tuple[np.ndarray, np.ndarray]:
    """The spectral columns' wavelengths (W,) nm (:func:`spectral_wavelengths`) and reflectance (P, W) float64 as
    fractions: divided by the header's ``SPECTRAL_NORM`` (ArgyllCMS: 100, percent) where it gives one, else read
    as percent when the table's largest value exceeds ``PERCENT_ABOVE``. MeasurementError for a table without
    spectral columns or with values outside [0, 1.5] (-0.01 allowed for noise)."""
    spec = spectral_fields(table) if spec is None else spec
    if not spec:
        raise MeasurementError("the measurements have no spectral columns (SPECTRAL_NM380 ... / SPEC_380 ...)")
    if ids is None:
        if not table.has("SAMPLE_ID"):
            raise MeasurementError("the measurements have no SAMPLE_ID column")
        ids = table.column("SAMPLE_ID")
    if not ids:
        raise MeasurementError("the measurements have no rows (nothing between BEGIN_DATA and END_DATA)")
    wl = spectral_wavelengths(table, spec)
    refl = np.stack([_numbers(table.column(c), c, ids) for _, c in spec], axis=1)
    norm = _header_number(table, "SPECTRAL_NORM")
    if norm is not None and not norm > 0:
        raise MeasurementError(f"header keyword SPECTRAL_NORM must be positive, got {norm:g}")
    refl = refl / (norm if norm is not None else 100.0 if refl.max() > PERCENT_ABOVE else 1.0)
    bad = np.flatnonzero((refl < -0.01).any(1) | (refl > 1.5).any(1))
    if len(bad):
        raise MeasurementError(f"patch {ids[bad[0]]}: spectral reflectance outside [0, 1.5] (or [0, 150] %)")
    return wl, refl


def file_white(table: CgatsTable) -> np.ndarray:
    """The white (3,) XYZ, Y = 1, that a table's XYZ columns are relative to: its ``ILLUMINANT_WHITE_POINT_XYZ``
    keyword (ArgyllCMS writes it for an illuminant other than D50), else D50 (ArgyllCMS's and the instruments'
    default for reflective measurements)."""
    v = _keyword(table, "ILLUMINANT_WHITE_POINT_XYZ")
    if v is None:
        return _colour().xy_to_XYZ(white_xy("D50"))
    try:
        white = np.array([float(x) for x in v.split()], np.float64)
    except ValueError:
        white = np.zeros(0)
    if white.shape != (3,) or not np.all(np.isfinite(white)) or not np.all(white > 0):
        raise MeasurementError(f"header keyword ILLUMINANT_WHITE_POINT_XYZ is '{v}', not three positive numbers")
    return white / white[1]


def _xyz_lab(table: CgatsTable, ids, illuminant: str) -> np.ndarray:
    """CIELAB under ``illuminant`` of the XYZ columns: on the 0-100 scale (Y of the perfect white 100, as ArgyllCMS
    and CGATS write them; a table whose largest value is at most ``PERCENT_ABOVE`` is read as fractions), relative
    to the file's white (``file_white``), adapted by Bradford to the illuminant's where that differs."""
    colour = _colour()
    xyz = np.stack([_numbers(table.column(f), f, ids) for f in XYZ_FIELDS], axis=1)
    xyz = xyz / (100.0 if xyz.max() > PERCENT_ABOVE else 1.0)
    bad = np.flatnonzero((xyz < -0.01).any(1) | (xyz > 2.0).any(1))
    if len(bad):
        raise MeasurementError(f"patch {ids[bad[0]]}: XYZ {(xyz[bad[0]] * 100).tolist()} outside 0..200")
    source, target = file_white(table), colour.xy_to_XYZ(white_xy(illuminant))
    if np.abs(source - target).max() > 2e-3:
        cat = colour.adaptation.matrix_chromatic_adaptation_VonKries(source, target, transform="Bradford")
        xyz = xyz @ cat.T
    return colour.XYZ_to_Lab(xyz, white_xy(illuminant))


def measured_lab(table: CgatsTable, illuminant: str = "D50") -> tuple[np.ndarray, str]:
    """(P, 3) CIELAB of every row under ``illuminant`` and the kind read: "spectral", "lab" or "xyz", the first the
    table has. Spectral columns win (they are integrated under the chosen illuminant; a LAB column may have been
    computed under another); LAB columns are taken as under ``illuminant``; XYZ columns (ArgyllCMS's .ti3) are
    converted from the file's white (``_xyz_lab``)."""
    if not table.has("SAMPLE_ID"):
        raise MeasurementError("the measurements have no SAMPLE_ID column")
    ids = table.column("SAMPLE_ID")
    if not ids:
        raise MeasurementError("the measurements have no rows (nothing between BEGIN_DATA and END_DATA)")
    spec = spectral_fields(table)
    if spec:
        return _spectral_lab(table, spec, ids, illuminant), "spectral"
    if illuminant_name(illuminant) not in ILLUMINANTS:
        raise ParameterError(
            f"`illuminant` {illuminant}: CIELAB and XYZ measurements are under the instrument's illuminant, one of "
            f"{', '.join(ILLUMINANTS)}; another light needs spectral measurements"
        )
    illuminant = _check_illuminant(illuminant)
    if all(table.has(f) for f in LAB_FIELDS):
        lab, kind = np.stack([_numbers(table.column(f), f, ids) for f in LAB_FIELDS], axis=1), "lab"
    elif all(table.has(f) for f in XYZ_FIELDS):
        lab, kind = _xyz_lab(table, ids, illuminant), "xyz"
    else:
        missing = [f for f in LAB_FIELDS if not table.has(f)]
        raise MeasurementError(
            f"no measurement columns: missing {', '.join(missing)} (or XYZ_X XYZ_Y XYZ_Z, or SPECTRAL_NM380 ... "
            "SPECTRAL_NM730 / SPEC_380 ... SPEC_730)"
        )
    bad = np.flatnonzero((lab[:, 0] < 0) | (lab[:, 0] > 100.5) | (np.abs(lab[:, 1:]) > 200).any(1))
    if len(bad):
        raise MeasurementError(
            f"patch {ids[bad[0]]}: L*a*b* {lab[bad[0]].tolist()} out of range (L* 0-100, |a*|,|b*| <= 200)"
        )
    return lab, kind


def spectral_to_lab(wavelengths_nm, reflectance, illuminant: str) -> np.ndarray:
    """Reflectance (P, W) at ``wavelengths_nm`` (W,) evenly spaced -> CIELAB (P, 3) under ``illuminant``, 2°
    observer, ASTM E308 integration (``colour.sd_to_XYZ``). ASTM E308 takes 1, 5, 10 or 20 nm bands starting at a
    whole nm: other bands (ArgyllCMS's 3.3 nm) are first interpolated linearly onto whole nm."""
    colour = _colour()
    cmfs = colour.MSDS_CMFS[OBSERVER]
    sd_ill = illuminant_sd(illuminant)
    white = white_xy(illuminant) if illuminant_name(illuminant) in ILLUMINANTS else _white_xy_of(sd_ill)
    wl = np.asarray(wavelengths_nm, np.float64)
    reflectance = np.asarray(reflectance, np.float64)
    step = wl[1] - wl[0]
    if not (np.any(np.abs(step - np.array(ASTM_INTERVALS)) < 1e-6) and abs(wl[0] - round(wl[0])) < 1e-6):
        grid = np.arange(np.ceil(wl[0] - 1e-6), np.floor(wl[-1] + 1e-6) + 1.0)
        reflectance = np.stack([np.interp(grid, wl, r) for r in reflectance]) if len(reflectance) else reflectance
        wl = grid
    out = np.empty((len(reflectance), 3))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for k, r in enumerate(reflectance):
            sd = colour.SpectralDistribution(dict(zip(np.round(wl, 6), r)))
            xyz = colour.sd_to_XYZ(sd, cmfs, sd_ill) / 100.0
            out[k] = colour.XYZ_to_Lab(xyz, white)
    return out
