"""Spectral inks: scattering and absorption coefficients per wavelength band instead of per RGB channel.

Light of different wavelengths travels independently through an ink mixture, so a spectral table's bands are
rendered as the RGB renderer renders its channels: in groups of three bands, each group an :class:`InkTable`
whose "R, G, B" are three of the bands (:meth:`SpectralInkTable.band_groups`). Mixtures mix per band as they mix
per channel (``model.inks.mix``).

Ink files hold RGB or spectral tables in one format (``model.inks.INK_FILE_FORMAT`` 2, docs/inks.md): a spectral
file adds ``"wavelengths_nm"`` (band centres) and gives every ink ``"sigma_s"`` and ``"sigma_a"`` per band in
mm^-1 (:func:`write_spectral_ink_file`); :func:`load_ink_table` reads either kind and the spectral presets.

The built-in (paper's) table is RGB. Its spectral form (``<preset>@spectral``, :func:`library_spectra`) is a
spectral table fitted so that the RGB table's colours of the library's calibration chart, upsampled to spectra
with the Mallett & Yuksel (2019) sRGB basis, are reproduced (``calibration.spectral.spectral_form``, stored in
``data/ink_spectra_*.json`` by experiments/spectral_library.py; the 10 nm form is the 20 nm one interpolated),
starting from the linear upsampling of every σs and σa with that basis (:meth:`SpectralInkTable.from_rgb`).
That the inks' true spectra look like this is an assumption until a lab calibrates its inks spectrally
(``inkopt calibrate`` on spectral measurements).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..io import write_json
from .inks import DEFAULT_G, INK_FILE_FORMAT, InkCoefficients, InkTable, ink_name_problem, read_ink_file

#: channels the renderer carries per path group (R, G, B)
GROUP = 3
#: The default band grid: 16 bands, 400-700 nm every 20 nm. Ink spectra are smooth (absorption bands 50-100 nm
#: wide), the CIE observer under D65 gives light outside 400-700 nm 0.2 % of X, Y, Z, ASTM E308 integrates 20 nm
#: bands as they are; 10 nm (``WAVELENGTHS_10NM``, 31 bands) is what instruments measure and costs twice as much.
WAVELENGTHS_20NM = np.arange(400.0, 701.0, 20.0)
WAVELENGTHS_10NM = np.arange(400.0, 701.0, 10.0)
#: ``<RGB preset or ink list>@<suffix>``: the library inks' spectral form, bands that many nm apart
#: (:func:`load_ink_table`, :func:`library_spectra`)
SPECTRAL_SUFFIXES = {"spectral": 20.0, "spectral10": 10.0}
_DATA = Path(__file__).resolve().parents[1] / "data"
#: The ink library's spectral form per band width (nm), fitted to reproduce the RGB table's colours
#: (experiments/spectral_library.py, docs/inks.md); spectral ink files.
LIBRARY_SPECTRA = {20.0: _DATA / "ink_spectra_20nm.json", 10.0: _DATA / "ink_spectra_10nm.json"}


@dataclass(frozen=True)
class SpectralInkTable(InkCoefficients):
    """N inks over B wavelength bands. ``wavelengths_nm`` (B,) float64, strictly increasing band centres in nm;
    ``sigma_s`` and ``sigma_a`` (N, B) float64 in mm^-1; one Henyey-Greenstein ``g`` for every ink and band."""

    names: tuple[str, ...]
    wavelengths_nm: np.ndarray
    sigma_s: np.ndarray
    sigma_a: np.ndarray
    g: float = DEFAULT_G

    def __post_init__(self):
        object.__setattr__(self, "names", tuple(self.names))
        wl = np.asarray(self.wavelengths_nm, dtype=np.float64)
        if wl.ndim != 1 or wl.size < 1 or not np.all(np.isfinite(wl)) or np.any(np.diff(wl) <= 0):
            raise ValueError("wavelengths_nm must be a non-empty, strictly increasing list of finite numbers")
        object.__setattr__(self, "wavelengths_nm", wl)
        self._check(wl.size, "spectral ink table")

    @classmethod
    def from_rgb(cls, inks: InkTable, wavelengths_nm=WAVELENGTHS_20NM) -> SpectralInkTable:
        """The spectral form of an RGB table: σ(λ) = σ_R b_R(λ) + σ_G b_G(λ) + σ_B b_B(λ) for σs and σa of every
        ink, with the Mallett & Yuksel (2019) sRGB basis b (:func:`rgb_basis`) on ``wavelengths_nm`` (B,) nm.
        The basis is non-negative and sums to 1 at every wavelength, so spectra are non-negative and an ink whose
        R, G, B coefficients are equal stays flat. Linear in σ, not in reflectance: docs/inks.md gives how close
        the colours come to the RGB table's."""
        basis = rgb_basis(wavelengths_nm)
        return cls(
            inks.names, np.asarray(wavelengths_nm, np.float64), inks.sigma_s @ basis, inks.sigma_a @ basis, inks.g
        )

    def resampled(self, wavelengths_nm) -> SpectralInkTable:
        """The table on another band grid (B',) nm: σs and σa interpolated linearly in wavelength, held constant
        beyond the table's first and last band."""
        wl = np.asarray(wavelengths_nm, np.float64)
        s = np.stack([np.interp(wl, self.wavelengths_nm, row) for row in self.sigma_s])
        a = np.stack([np.interp(wl, self.wavelengths_nm, row) for row in self.sigma_a])
        return SpectralInkTable(self.names, wl, s, a, self.g)

    def with_g(self, g: float) -> SpectralInkTable:
        return SpectralInkTable(self.names, self.wavelengths_nm, self.sigma_s, self.sigma_a, float(g))

    @property
    def bands(self) -> int:
        return int(self.wavelengths_nm.size)

    def band_groups(self) -> list[InkTable]:
        """The bands as ceil(B / 3) RGB-shaped tables, bands 3k, 3k+1, 3k+2 in group k; the last group repeats its
        last band to fill three channels (``group_bands`` says which bands are real)."""
        groups = []
        for bands in self.group_bands():
            pick = list(bands) + [bands[-1]] * (GROUP - len(bands))
            groups.append(InkTable(self.names, self.sigma_s[:, pick], self.sigma_a[:, pick], self.g))
        return groups

    def group_bands(self) -> list[tuple[int, ...]]:
        """The band indices of each group of :meth:`band_groups` (the last may hold fewer than three)."""
        return [tuple(range(k, min(k + GROUP, self.bands))) for k in range(0, self.bands, GROUP)]


def rgb_basis(wavelengths_nm) -> np.ndarray:
    """(3, B) float64: the Mallett & Yuksel (2019) sRGB basis spectra (``colour.recovery``, tabulated 380-780 nm
    every 5 nm) averaged over each band of the grid ``wavelengths_nm`` (B,) (:func:`band_edges`; a point sample
    for a single band), the basis interpolated linearly onto 1 nm within. Each column sums to 1 (within 1e-5)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    table = colour.recovery.MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019
    wl = np.asarray(wavelengths_nm, np.float64)
    if wl.ndim != 1 or wl.size < 1 or np.any(np.diff(wl) <= 0):
        raise ValueError("wavelengths_nm must be a non-empty, strictly increasing list")
    lo, hi = band_edges(wl)
    out = np.empty((3, wl.size))
    for b in range(wl.size):
        grid = np.linspace(lo[b], hi[b], max(2, int(np.ceil(hi[b] - lo[b])) + 1))
        for c in range(3):
            out[c, b] = np.interp(grid, table.wavelengths, table.values[:, c]).mean()
    return out


def band_edges(wavelengths_nm) -> tuple[np.ndarray, np.ndarray]:
    """(lo (B,), hi (B,)) nm: the band around each centre of the grid ``wavelengths_nm`` (B,) reaches halfway to
    its neighbours' centres (the grid's first and last step beyond its ends); a single band has zero width."""
    wl = np.asarray(wavelengths_nm, np.float64)
    if wl.size < 2:
        return wl.copy(), wl.copy()
    mids = (wl[1:] + wl[:-1]) / 2
    lo = np.concatenate([[wl[0] - (wl[1] - wl[0]) / 2], mids])
    return lo, np.concatenate([mids, [wl[-1] + (wl[-1] - wl[-2]) / 2]])


def library_spectra(inks: InkTable, band_nm: float = 20.0) -> SpectralInkTable:
    """The spectral form of library inks (``model.inks.INK_LIBRARY``, with the library's coefficients) on bands
    ``band_nm`` (20 or 10) apart over 400-700 nm, from :data:`LIBRARY_SPECTRA`; ValueError for an ink that is not
    the library's (its spectra were never fitted: ``calibration.spectral.spectral_form`` fits them)."""
    from .inks import INK_LIBRARY

    if band_nm not in LIBRARY_SPECTRA:
        raise ValueError(f"band_nm must be one of {sorted(LIBRARY_SPECTRA)}, got {band_nm}")
    for k, name in enumerate(inks.names):
        lib = INK_LIBRARY.get(name)
        if lib is None or not np.allclose([inks.mu_t[k], inks.albedo[k]], lib, rtol=1e-9, atol=1e-12):
            raise ValueError(
                f"ink '{name}' is not the ink library's '{name}': the spectral form (@spectral) exists for library "
                "inks only; calibration.spectral.spectral_form fits one for other inks"
            )
    path = LIBRARY_SPECTRA[band_nm]
    table = spectral_from_data(read_ink_file(path), path)
    rows = [table.index(n) for n in inks.names]
    return SpectralInkTable(inks.names, table.wavelengths_nm, table.sigma_s[rows], table.sigma_a[rows], inks.g)


def load_ink_table(spec: str) -> InkTable | SpectralInkTable:
    """An RGB or spectral ink table: what ``InkTable.parse`` takes (a preset, a comma list of library inks, an
    ink file), a spectral ink file (:func:`write_spectral_ink_file`), or ``<preset or list of library
    inks>@spectral`` (20 nm bands) / ``@spectral10`` (10 nm): their spectral form (:func:`library_spectra`)."""
    base, at, suffix = str(spec).rpartition("@")
    if at and suffix.lower() in SPECTRAL_SUFFIXES:
        return library_spectra(InkTable.parse(base), SPECTRAL_SUFFIXES[suffix.lower()])
    path = Path(spec)
    if path.suffix.lower() in (".json", ".toml"):
        data = read_ink_file(path)
        return spectral_from_data(data, path) if "wavelengths_nm" in data else InkTable.from_data(data, path)
    return InkTable.parse(spec)


def _numbers(value, what: str, count: int | None = None) -> list[float]:
    """A list of finite numbers (not booleans), ``count`` long if given; TypeError/ValueError naming ``what``."""
    if not isinstance(value, list) or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in value):
        raise TypeError(f"{what} must be a list of numbers")
    if count is not None and len(value) != count:
        raise ValueError(f"{what} must hold {count} numbers (one per band), got {len(value)}")
    out = [float(v) for v in value]
    if not all(np.isfinite(out)):
        raise ValueError(f"{what} must be finite")
    return out


def spectral_from_data(data: dict, path) -> SpectralInkTable:
    """The spectral table of an ink file's content ``data`` (``model.inks.read_ink_file``): ``wavelengths_nm``
    (B,) increasing band centres in nm, ``g``, and ``inks`` objects with ``name``, ``sigma_s`` and ``sigma_a`` (B
    numbers each, mm^-1). One-line ValueError naming ``path`` for anything wrong."""
    try:
        wl = _numbers(data["wavelengths_nm"], "'wavelengths_nm'")
        inks = data["inks"]
        if not isinstance(inks, list) or not all(isinstance(i, dict) for i in inks):
            raise TypeError("'inks' must be a list of objects with name, sigma_s and sigma_a")
        g = data.get("g", DEFAULT_G)
        if isinstance(g, bool) or not isinstance(g, (int, float)):
            raise TypeError(f"'g' must be a number, got {g!r}")
        names = [i["name"] for i in inks]
        for n in names:
            if problem := ink_name_problem(n):
                raise ValueError(f"ink name {n!r} {problem}")
        s = [_numbers(i["sigma_s"], f"ink {i['name']!r} sigma_s", len(wl)) for i in inks]
        a = [_numbers(i["sigma_a"], f"ink {i['name']!r} sigma_a", len(wl)) for i in inks]
        shape = (len(inks), len(wl))
        return SpectralInkTable(
            tuple(n.lower() for n in names), wl, np.reshape(s, shape), np.reshape(a, shape), float(g)
        )
    except KeyError as exc:
        raise ValueError(f"ink file {path}: missing field {exc}") from None
    except (TypeError, ValueError, OverflowError) as exc:
        raise ValueError(f"ink file {path}: {exc}") from None


def write_spectral_ink_file(path, inks: SpectralInkTable, provenance: dict | None = None) -> Path:
    """Write ``inks`` as a JSON spectral ink file (:func:`load_ink_table` reads it), with ``provenance`` (a JSON
    object: where the table came from) if given; atomic."""
    data = {
        "format_version": INK_FILE_FORMAT,
        "g": float(inks.g),
        "wavelengths_nm": [float(w) for w in inks.wavelengths_nm],
        "inks": [
            {"name": n, "sigma_s": [float(v) for v in inks.sigma_s[k]], "sigma_a": [float(v) for v in inks.sigma_a[k]]}
            for k, n in enumerate(inks.names)
        ],
    }
    if provenance is not None:
        data["provenance"] = provenance
    return write_json(path, data)
