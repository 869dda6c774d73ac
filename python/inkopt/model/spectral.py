"""Spectral inks: scattering and absorption coefficients per wavelength band instead of per RGB channel.

Light of different wavelengths travels independently through an ink mixture, so a spectral table's bands are
rendered as the RGB renderer renders its channels: in groups of three bands, each group an :class:`InkTable`
whose "R, G, B" are three of the bands (:meth:`SpectralInkTable.band_groups`). Mixtures mix per band as they mix
per channel (``model.inks.mix``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .inks import DEFAULT_G, InkTable, ink_name_problem

#: channels the renderer carries per path group (R, G, B)
GROUP = 3


@dataclass(frozen=True)
class SpectralInkTable:
    """N inks over B wavelength bands. ``wavelengths_nm`` (B,) float64, strictly increasing band centres in nm;
    ``sigma_s`` and ``sigma_a`` (N, B) float64 in mm^-1; one Henyey-Greenstein ``g`` for every ink and band."""

    names: tuple[str, ...]
    wavelengths_nm: np.ndarray
    sigma_s: np.ndarray
    sigma_a: np.ndarray
    g: float = DEFAULT_G

    def __post_init__(self):
        names = tuple(self.names)
        object.__setattr__(self, "names", names)
        for name in names:
            if problem := ink_name_problem(name):
                raise ValueError(f"ink name {name!r} {problem}")
        if len(set(names)) != len(names) or not names:
            raise ValueError("ink names must be non-empty and unique")
        wl = np.asarray(self.wavelengths_nm, dtype=np.float64)
        if wl.ndim != 1 or wl.size < 1 or not np.all(np.isfinite(wl)) or np.any(np.diff(wl) <= 0):
            raise ValueError("wavelengths_nm must be a non-empty, strictly increasing list of finite numbers")
        object.__setattr__(self, "wavelengths_nm", wl)
        for key in ("sigma_s", "sigma_a"):
            arr = np.asarray(getattr(self, key), dtype=np.float64)
            if arr.shape != (len(names), wl.size):
                raise ValueError(f"spectral ink table {key} must have shape ({len(names)}, {wl.size}), got {arr.shape}")
            if not np.all(np.isfinite(arr)) or np.any(arr < 0):
                raise ValueError(f"spectral ink table {key} must be finite and non-negative")
            object.__setattr__(self, key, arr)
        if not -1.0 < self.g < 1.0:
            raise ValueError(f"Henyey-Greenstein g must lie in (-1, 1), got {self.g}")

    def __len__(self) -> int:
        return len(self.names)

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
