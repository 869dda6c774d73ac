"""Named lights and light files, and the colour of a band prediction under a light.

A light is a relative spectral power distribution S(λ). Reflectance per band is linear in the light's spectrum, so
the light never enters transport: a print's colour under it is a linear map of its B band values,
XYZ = M_light @ r, with M_light (3, B) = CIE 1931 2° colour matching functions x S(λ) x dλ integrated against each
band's share of the reflectance, normalised so that a perfect white (r = 1 in every band) has Y = 1. CIELAB is then
taken relative to that white (:class:`inkopt.color.ColourMap`), as a viewer adapted to the light sees it.

The band values are point samples of the reflectance at the band centres ``wavelengths_nm``, interpolated between
them as colour-science interpolates a measured spectrum (``band_basis``) and held constant beyond the first and last:
band b's weight is the sum, on a 1 nm grid over 360-830 nm, of its interpolation basis function times the colour
matching functions and S(λ). Named lights are colour-science's tables put on that grid as its ``sd_to_XYZ`` puts
them (linearly, constant beyond the table), so the colour of a spectrum equals colour-science's
``sd_to_XYZ(method="Integration")`` (tests/spectral/test_lights.py). A light file's power is 0 outside its rows.

Named lights (colour-science's tables): D50, D65, A, F11 (colour-science's "FL11"), LED-B3. A file: text lines
"nm, relative power" (comma, semicolon, tab or space separated; one optional header line; ``#`` comments), read as
hostile input: bounded in size, every value checked, one ``ParameterError`` naming `illuminant` otherwise.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..color import ColourMap
from ..errors import ParameterError

#: the names a light may be given by and their colour-science table
NAMED = {"D50": "D50", "D65": "D65", "A": "A", "F11": "FL11", "LED-B3": "LED-B3"}
#: the observer's wavelengths (nm): the 1 nm grid of the CIE 1931 2° table
GRID_NM = np.arange(360.0, 831.0)
#: a light file's largest size in bytes and rows
MAX_FILE_BYTES = 1 << 20
MAX_ROWS = 10_000
#: the wavelengths (nm) a light file's rows may lie in
FILE_RANGE_NM = (200.0, 1200.0)
_SPLIT = re.compile(r"[,;\t ]+")


@dataclass(frozen=True)
class Light:
    """A light: ``wavelengths_nm`` (K,) float64 strictly increasing, ``power`` (K,) float64 relative spectral power
    (>= 0; its scale does not matter), linearly interpolated between rows and 0 outside them; ``name``: a named
    light's name or the file's name."""

    name: str
    wavelengths_nm: np.ndarray = field(repr=False)
    power: np.ndarray = field(repr=False)

    def on_grid(self) -> np.ndarray:
        """S(λ) on :data:`GRID_NM` (471,) float64."""
        return np.interp(GRID_NM, self.wavelengths_nm, self.power, left=0.0, right=0.0)

    def colour_map(self, wavelengths_nm) -> ColourMap:
        """The colour of band values under this light: a ColourMap (3, B) for bands centred at ``wavelengths_nm``
        (B,) nm (a spectral ink table's), white (r = 1) at Y = 1. RGB-shaped 3-band tables get no special case."""
        return ColourMap(band_matrix(self, np.asarray(wavelengths_nm, np.float64)), self.name)


@lru_cache(maxsize=1)
def observer() -> np.ndarray:
    """The CIE 1931 2° colour matching functions on :data:`GRID_NM`, (3, 471) float64 (x̄, ȳ, z̄)."""
    import colour

    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    return np.array([np.interp(GRID_NM, cmfs.wavelengths, cmfs.values[:, k]) for k in range(3)])


def band_basis(wavelengths_nm: np.ndarray) -> np.ndarray:
    """(471, B) float64: the weight of each band's value in the reflectance at each :data:`GRID_NM` wavelength;
    every row sums to 1. The reflectance between band centres is interpolated as colour-science interpolates a
    measured spectrum (Sprague on a uniform grid of 6 or more bands, a cubic spline on another grid), held
    constant beyond them; fewer than 6 bands interpolate linearly."""
    wl = np.asarray(wavelengths_nm, np.float64)
    if wl.ndim != 1 or wl.size < 1 or not np.all(np.isfinite(wl)) or np.any(np.diff(wl) <= 0):
        raise ValueError("wavelengths_nm must be a non-empty, strictly increasing list of finite numbers")
    eye = np.eye(wl.size)
    if wl.size < 6:
        return np.stack([np.interp(GRID_NM, wl, eye[b]) for b in range(wl.size)], axis=1)
    return np.stack([_aligned(wl, eye[b]) for b in range(wl.size)], axis=1)


def _aligned(wavelengths: np.ndarray, values: np.ndarray) -> np.ndarray:
    """A spectrum (K,) interpolated and extrapolated onto :data:`GRID_NM` by colour-science's ``align``."""
    import colour

    sd = colour.SpectralDistribution(values, wavelengths)
    return np.asarray(sd.align(colour.SpectralShape(GRID_NM[0], GRID_NM[-1], 1)).values, np.float64)


def band_matrix(light: Light, wavelengths_nm: np.ndarray) -> np.ndarray:
    """M_light (3, B) float64: XYZ = M_light @ r for band values r (B,), a perfect white at Y = 1 (1 nm steps)."""
    weighted = observer() * light.on_grid()  # (3, 471): x̄ S, ȳ S, z̄ S per nm
    y_white = weighted[1].sum()
    if not y_white > 0:
        raise ParameterError(f"`illuminant` {light.name} has no power where the eye sees (360-830 nm)")
    return (weighted @ band_basis(wavelengths_nm)) / y_white


@lru_cache(maxsize=16)
def named_light(name: str) -> Light:
    """One of :data:`NAMED` from colour-science's tables; a ParameterError naming `illuminant` for another name."""
    if name not in NAMED:
        raise ParameterError(f"`illuminant` must be one of {', '.join(NAMED)} or a .csv file, got {name!r}")
    import colour

    sd = colour.SDS_ILLUMINANTS[NAMED[name]]
    # on the observer's grid as colour-science's sd_to_XYZ puts it: linear, constant beyond the table's ends
    return Light(name, GRID_NM.copy(), np.interp(GRID_NM, sd.wavelengths, sd.values))


def load_light(spec: str | Path) -> Light:
    """A light by name (:data:`NAMED`) or from a file of (nm, relative power) rows (see the module docstring)."""
    text = str(spec)
    if text in NAMED:
        return named_light(text)
    path = Path(text)
    if path.suffix.lower() not in (".csv", ".txt"):
        raise ParameterError(f"`illuminant` must be one of {', '.join(NAMED)} or a .csv file, got {text!r}")
    try:
        with open(path, "rb") as fh:
            raw = fh.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise ParameterError(f"`illuminant` {text}: cannot read it ({exc.strerror or exc})") from None
    if len(raw) > MAX_FILE_BYTES:
        raise ParameterError(f"`illuminant` {text}: larger than {MAX_FILE_BYTES} bytes")
    try:
        nm, power = parse_rows(raw.decode("utf-8-sig"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise ParameterError(f"`illuminant` {text}: {one_line(exc)}") from None
    return Light(path.name, nm, power)


def one_line(exc: Exception) -> str:
    """An exception's message on one line, at most 200 characters."""
    return " ".join(str(exc).split())[:200]


def parse_rows(text: str) -> tuple[np.ndarray, np.ndarray]:
    """(nm, power) float64 arrays from a light file's text; a ValueError saying what is wrong otherwise."""
    rows = []
    for number, line in enumerate(text.splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        cells = [c for c in _SPLIT.split(line) if c]
        if len(cells) != 2:
            raise ValueError(f"line {number}: expected two values (nm, relative power), got {len(cells)}")
        try:
            rows.append((float(cells[0]), float(cells[1])))
        except ValueError:
            if rows:  # only the first row may be a header
                raise ValueError(f"line {number}: not two numbers") from None
            rows.append(None)
        if len(rows) > MAX_ROWS:
            raise ValueError(f"more than {MAX_ROWS} rows")
    rows = [r for r in rows if r is not None]
    if len(rows) < 2:
        raise ValueError("needs at least two rows of (nm, relative power)")
    data = np.array(rows, np.float64)
    nm, power = data[:, 0], data[:, 1]
    lo, hi = FILE_RANGE_NM
    if not np.all(np.isfinite(data)):
        raise ValueError("values must be finite")
    if np.any(np.diff(nm) <= 0) or nm[0] < lo or nm[-1] > hi:
        raise ValueError(f"wavelengths must increase strictly and lie in {lo:g}-{hi:g} nm")
    if np.any(power < 0) or not np.any(power > 0):
        raise ValueError("relative powers must be non-negative and not all zero")
    return nm, power


def parse_lights(spec: str) -> tuple[Light, ...]:
    """Lights from a comma-separated list of names or files (``"D65,A"``), at least one, none twice."""
    names = [s.strip() for s in str(spec).split(",")]
    if not names or any(not n for n in names):
        raise ParameterError(f"`illuminants` must be a comma-separated list of lights, got {spec!r}")
    if len(set(names)) != len(names):
        raise ParameterError(f"`illuminants` names a light twice: {spec!r}")
    return tuple(load_light(n) for n in names)
