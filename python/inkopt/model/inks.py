"""Inks and ink mixtures (docs/method.md §3).

An ink is given by its extinction coefficient mu_t (mm^-1) and single-scattering albedo per RGB channel.
Mixtures mix scattering and absorption coefficients *linearly*:

    sigma_s(rho) = sum_n rho_n sigma_s,n        sigma_a(rho) = sum_n rho_n sigma_a,n

All inks share one Henyey-Greenstein phase function (g = 0.4 by default).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..io import upgrade_format, write_json

DEFAULT_G = 0.4
# Ink files: version 0 is the plain {"g", "inks"} object; version 1 adds "format_version" and an optional
# "provenance" object (where a fitted table came from: ``inkopt calibrate``); version 2 adds spectral tables (a
# "wavelengths_nm" list and per ink "sigma_s"/"sigma_a" per band, ``model.spectral``). RGB files of every version
# load alike.
INK_FILE_FORMAT = 2

# Paper's Table 2: name -> (mu_t RGB in mm^-1, albedo RGB).
INK_LIBRARY: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "cyan": ((9.0, 4.5, 7.5), (0.05, 0.7, 0.98)),
    "cyan2": ((6.0, 3.0, 5.0), (0.05, 0.95, 0.98)),
    "magenta": ((2.5, 3.0, 10.0), (0.98, 0.1, 0.9)),
    "magenta2": ((1.7, 2.0, 6.7), (0.98, 0.05, 0.97)),
    "yellow": ((2.25, 3.75, 19.0), (0.997, 0.995, 0.15)),
    "yellow2": ((3.0, 5.0, 19.0), (0.92, 0.92, 0.15)),
    "orange": ((3.0, 4.0, 15.0), (0.98, 0.32, 0.114)),
    "black": ((5.0, 5.5, 6.5), (0.35, 0.35, 0.35)),
    "white": ((6.0, 9.0, 24.0), (0.9991, 0.9997, 0.999)),
    "transparent": ((1e-4, 1e-4, 1e-4), (1.0, 1.0, 1.0)),
}

PRESETS: dict[str, list[str]] = {
    "vero-cmykw": ["cyan", "magenta", "yellow", "black", "white"],
    "vero-cmykw+orange": ["cyan", "magenta", "yellow", "black", "white", "orange"],
    "vero-cmykwt": ["cyan", "magenta", "yellow", "black", "white", "transparent"],
    "paper-6": ["cyan", "cyan2", "magenta", "magenta2", "yellow", "yellow2", "black", "white"],
}


class InkCoefficients:
    """What ink tables share (``InkTable``: RGB channels, ``model.spectral.SpectralInkTable``: wavelength bands):
    ``names`` and ``sigma_s``, ``sigma_a`` (N, channels) in mm^-1, one Henyey-Greenstein ``g``."""

    def _check(self, channels: int, what: str) -> None:
        """One-line ValueError for a bad name, coefficient array or g; the arrays stored as C-contiguous float64
        (the core takes its arrays as they are)."""
        n = len(self.names)
        for name in self.names:
            if problem := ink_name_problem(name):
                raise ValueError(f"ink name {name!r} {problem}")
        for key in ("sigma_s", "sigma_a"):
            arr = np.ascontiguousarray(getattr(self, key), dtype=np.float64)
            if arr.shape != (n, channels):
                raise ValueError(f"{what} {key} must have shape ({n}, {channels}), got {arr.shape}")
            if not np.all(np.isfinite(arr)) or np.any(arr < 0):
                raise ValueError(f"{what} {key} must be finite and non-negative")
            object.__setattr__(self, key, arr)
        if len(set(self.names)) != n or n == 0:
            raise ValueError("ink names must be non-empty and unique")
        if not -1.0 < self.g < 1.0:
            raise ValueError(f"Henyey-Greenstein g must lie in (-1, 1), got {self.g}")

    def __len__(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name.lower())
        except ValueError:
            raise ValueError(f"ink '{name}' is not in this ink set {list(self.names)}") from None


@dataclass(frozen=True)
class InkTable(InkCoefficients):
    """N inks. ``sigma_s`` and ``sigma_a`` are (N, 3) float64 arrays in mm^-1 (R, G, B)."""

    names: tuple[str, ...]
    sigma_s: np.ndarray
    sigma_a: np.ndarray
    g: float = DEFAULT_G

    def __post_init__(self):
        self._check(3, "ink table")

    @property
    def mu_t(self) -> np.ndarray:
        return self.sigma_s + self.sigma_a

    @property
    def albedo(self) -> np.ndarray:
        return np.divide(self.sigma_s, self.mu_t, out=np.ones_like(self.sigma_s), where=self.mu_t > 0)

    @classmethod
    def from_mu_t_albedo(cls, names, mu_t, albedo, g: float = DEFAULT_G) -> InkTable:
        """``names`` (N,) str; ``mu_t`` (N, 3) mm^-1 and ``albedo`` (N, 3) in [0, 1], R, G, B per ink."""
        names = tuple(names)
        if bad := [n for n in names if not isinstance(n, str)]:
            raise ValueError(f"ink name {bad[0]!r} is not a string")
        mu_t = np.asarray(mu_t, dtype=np.float64)
        albedo = np.asarray(albedo, dtype=np.float64)
        for what, arr in (("mu_t", mu_t), ("albedo", albedo)):
            if arr.shape != (len(names), 3):
                raise ValueError(f"ink {what} must be 3 numbers (R, G, B) for each of {len(names)} inks")
        if not np.all((albedo >= 0) & (albedo <= 1)):
            raise ValueError("ink albedo must lie in [0, 1]")
        return cls(tuple(n.lower() for n in names), mu_t * albedo, mu_t * (1.0 - albedo), g)

    @classmethod
    def from_names(cls, names, g: float = DEFAULT_G) -> InkTable:
        names = [n.strip().lower() for n in names if n.strip()]
        unknown = [n for n in names if n not in INK_LIBRARY]
        if unknown:
            raise ValueError(f"unknown ink(s) {unknown}; known: {sorted(INK_LIBRARY)}")
        return cls.from_mu_t_albedo(names, [INK_LIBRARY[n][0] for n in names], [INK_LIBRARY[n][1] for n in names], g)

    @classmethod
    def parse(cls, spec: str) -> InkTable:
        """A preset name (``vero-cmykw``), a comma list of ink names, or a JSON/TOML file of inks.

        File format: ``{"g": 0.4, "inks": [{"name": "cyan", "mu_t": [9, 4.5, 7.5], "albedo": [...]}, ...]}``
        (TOML: ``g = 0.4`` and ``[[inks]]`` tables with the same keys), optionally with ``format_version`` and a
        ``provenance`` object (:func:`read_ink_file`), which the table does not need.
        """
        if spec in PRESETS:
            return cls.from_names(PRESETS[spec])
        path = Path(spec)
        if path.suffix.lower() in (".json", ".toml"):
            return cls.from_file(path)
        return cls.from_names(spec.split(","))

    @classmethod
    def from_file(cls, path) -> InkTable:
        """The ink table of a JSON/TOML ink file (``parse``); anything wrong with it is a one-line ValueError
        naming the file."""
        return cls.from_data(read_ink_file(path), path)

    @classmethod
    def from_data(cls, data: dict, path) -> InkTable:
        """The RGB ink table of an ink file's content ``data`` (:func:`read_ink_file`); ``path`` names the file in
        errors. A spectral file is refused (``model.spectral.load_ink_table`` reads both kinds)."""
        if "wavelengths_nm" in data:
            raise ValueError(
                f"ink file {path} holds a spectral ink table (wavelengths_nm), not an RGB one: load it with "
                "inkopt.model.spectral.load_ink_table where spectral tables are taken"
            )
        try:
            inks = data["inks"]
            if not isinstance(inks, list) or not all(isinstance(i, dict) for i in inks):
                raise TypeError("'inks' must be a list of objects with name, mu_t and albedo")
            g = data.get("g", DEFAULT_G)
            if isinstance(g, bool) or not isinstance(g, (int, float)):
                raise TypeError(f"'g' must be a number, got {g!r}")
            return cls.from_mu_t_albedo(
                [i["name"] for i in inks], [i["mu_t"] for i in inks], [i["albedo"] for i in inks], float(g)
            )
        except KeyError as exc:
            raise ValueError(f"ink file {path}: missing field {exc}") from None
        except (TypeError, ValueError, OverflowError) as exc:
            raise ValueError(f"ink file {path}: {exc}") from None

    def to_arrays(self) -> dict:
        """Arrays for a volume .npz file (see inkopt.model.volume)."""
        return {
            "ink_names": np.array(self.names),
            "ink_sigma_s": self.sigma_s.astype(np.float32),
            "ink_sigma_a": self.sigma_a.astype(np.float32),
        }

    @classmethod
    def from_arrays(cls, data, g: float = DEFAULT_G) -> InkTable:
        return cls(
            tuple(str(n) for n in data["ink_names"]),
            np.asarray(data["ink_sigma_s"]),
            np.asarray(data["ink_sigma_a"]),
            g,
        )


_UNSAFE_IN_NAMES = set("/\\:")  # ink names name files and folders (ink-set runs): no separators, no drives


def ink_name_problem(name) -> str | None:
    """What makes ``name`` no ink name (a phrase), or None: a non-empty string without control characters,
    path separators or drive colons, and not "." or ".." (ink names become file and folder names)."""
    if not isinstance(name, str):
        return "is not a string"
    if not name.strip() or name.strip() in (".", ".."):
        return "is empty" if not name.strip() else "is a folder name"
    if any(ord(c) < 32 or ord(c) == 127 for c in name):
        return "holds a control character"
    if _UNSAFE_IN_NAMES & set(name):
        return "holds '/', '\\' or ':'"
    return None


def read_ink_file(path) -> dict:
    """An ink file (.json or .toml) as a dict at format version :data:`INK_FILE_FORMAT` (``g``, ``inks``,
    ``wavelengths_nm`` if it is spectral and ``provenance`` if the file has one); ValueError (one line) for a
    missing or unreadable file."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"ink file {path} does not exist")
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(path.read_text())
        else:
            try:
                import tomllib
            except ModuleNotFoundError:  # Python 3.10
                import tomli as tomllib
            data = tomllib.loads(path.read_text())
    except RecursionError:
        raise ValueError(f"ink file {path} is nested too deeply to read") from None
    except ValueError as exc:
        raise ValueError(f"ink file {path} is not valid {path.suffix[1:].upper()}: {exc}") from None
    if not isinstance(data, dict):
        raise ValueError(f"ink file {path} must hold an object with 'inks'")
    return upgrade_format(data, kind="ink file", where=path, current=INK_FILE_FORMAT, upgrades={0: dict, 1: dict})


def write_ink_file(path, inks: InkTable, provenance: dict | None = None) -> Path:
    """Write ``inks`` as a JSON ink file (``--inks`` reads it), with ``provenance`` (a JSON object: where the
    table came from) if given; atomic."""
    data = {
        "format_version": INK_FILE_FORMAT,
        "g": float(inks.g),
        "inks": [
            {"name": n, "mu_t": [float(v) for v in inks.mu_t[k]], "albedo": [float(v) for v in inks.albedo[k]]}
            for k, n in enumerate(inks.names)
        ],
    }
    if provenance is not None:
        data["provenance"] = provenance
    return write_json(path, data)


def mix(mixture: np.ndarray, inks: InkTable) -> tuple[np.ndarray, np.ndarray]:
    """Mixture (..., N) float -> (sigma_s, sigma_a), each (..., 3) float32 in mm^-1."""
    mixture = np.asarray(mixture, dtype=np.float32)
    if mixture.shape[-1] != len(inks):
        raise ValueError(f"mixture has {mixture.shape[-1]} inks, ink table has {len(inks)}")
    s = mixture @ inks.sigma_s.astype(np.float32)
    a = mixture @ inks.sigma_a.astype(np.float32)
    return s, a


def mix_grad(grad_sigma_s: np.ndarray, grad_sigma_a: np.ndarray, inks: InkTable) -> np.ndarray:
    """Chain rule through :func:`mix`: de/drho_n = sum_c (de/dsigma_s,c sigma_s,n,c + de/dsigma_a,c sigma_a,n,c).

    Inputs (..., 3), output (..., N) float32.
    """
    return np.asarray(grad_sigma_s, np.float32) @ inks.sigma_s.T.astype(np.float32) + np.asarray(
        grad_sigma_a, np.float32
    ) @ inks.sigma_a.T.astype(np.float32)
