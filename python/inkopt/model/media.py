"""The three forms of a volume's medium (``Dense`` coefficients, an ink ``Mixture``, ink ``Labels``) and the
quantization settings of a labels volume; ``Volume`` (``model.volume``) holds one medium on its grid.

Conventions (docs/conventions.md): arrays are (z, y, x[, c]); coefficients in mm^-1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from .inks import InkTable

EMPTY = 255  # the label of a voxel without ink


class VolumeError(ParameterError):
    """A volume that cannot be rendered or held; the message is one line naming the problem (and the parameters
    that would change it, in backticks: ``errors.ParameterError``)."""


# ----------------------------------------------------------------------------------------- medium forms
@dataclass
class Dense:
    """Per-voxel coefficients (z, y, x, 3) float32 mm^-1."""

    sigma_s: np.ndarray
    sigma_a: np.ndarray
    form = "dense"

    def __post_init__(self):
        for key in ("sigma_s", "sigma_a"):
            arr = np.ascontiguousarray(getattr(self, key), dtype=np.float32)
            if arr.ndim != 4 or arr.shape[3] != 3:
                raise VolumeError(f"{key} must have shape (z, y, x, 3), got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise VolumeError(f"{key} contains NaN or infinite values")
            if np.any(arr < 0):
                raise VolumeError(f"{key} contains negative coefficients")
            setattr(self, key, arr)
        if self.sigma_s.shape != self.sigma_a.shape:
            raise VolumeError(f"sigma_s {self.sigma_s.shape} and sigma_a {self.sigma_a.shape} differ in shape")

    @property
    def shape(self):
        return self.sigma_s.shape[:3]

    def arrays(self) -> dict:
        return {"sigma_s": self.sigma_s, "sigma_a": self.sigma_a}


@dataclass
class Mixture:
    """Per-voxel ink shares (z, y, x, N) float32 of the ink table ``inks``."""

    mixture: np.ndarray
    inks: InkTable
    form = "mixture"

    def __post_init__(self):
        m = np.ascontiguousarray(self.mixture, dtype=np.float32)
        if m.ndim != 4 or m.shape[3] != len(self.inks):
            raise VolumeError(f"mixture must have shape (z, y, x, {len(self.inks)}), got {m.shape}")
        step = max(1, 2**22 // max(1, m[0].size))  # checked in slabs of layers: bounded temporaries
        for z in range(0, m.shape[0], step):
            part = m[z : z + step]
            if not np.all(np.isfinite(part)) or np.any(part < 0):
                raise VolumeError("mixture must be finite and non-negative")
        self.mixture = m

    @property
    def shape(self):
        return self.mixture.shape[:3]

    def arrays(self) -> dict:
        return {"mixture": self.mixture, **self.inks.to_arrays()}


@dataclass
class Labels:
    """One ink index per voxel (z, y, x) uint8 of the ink table ``inks``; ``EMPTY`` = no ink."""

    labels: np.ndarray
    inks: InkTable
    form = "labels"

    def __post_init__(self):
        lab = np.ascontiguousarray(self.labels)  # a read-only memory map (a label file) stays one
        if lab.dtype != np.uint8 or lab.ndim != 3:
            raise VolumeError(f"labels must be uint8 (z, y, x), got {lab.dtype} {lab.shape}")
        step = max(1, 2**24 // max(1, lab[0].size))  # checked in slabs of layers: bounded temporaries
        for z in range(0, lab.shape[0], step):
            used = lab[z : z + step][lab[z : z + step] != EMPTY]
            if used.size and int(used.max()) >= len(self.inks):
                raise VolumeError(f"labels use ink {int(used.max())} but the ink table has {len(self.inks)}")
        self.labels = lab

    @property
    def shape(self):
        return self.labels.shape

    def arrays(self) -> dict:
        return {"labels": self.labels, **self.inks.to_arrays()}


Medium = Dense | Mixture | Labels


@dataclass(frozen=True)
class Quantization:
    """How a labels volume was made from a mixture (``inkopt.printing.quantize``); dpi is (x, y, z). ``ink_order``:
    the order of the inks' bands in blue-noise dithering, "lightness" (lightest first, ``dither.lightness_order``)
    or "index" (the ink set's order; files that do not say were made so)."""

    method: str = "blue-noise"
    seed: int = 0
    dpi: tuple[float, float, float] | None = None
    upsample: str = "nearest"
    ink_order: str = "lightness"

    def arrays(self) -> dict:
        out = {"method": np.array(self.method), "seed": np.int64(self.seed), "upsample": np.array(self.upsample)}
        out["ink_order"] = np.array(self.ink_order)
        if self.dpi is not None:
            out["dpi"] = np.asarray(self.dpi, np.float64)
        return out

    @classmethod
    def from_arrays(cls, data) -> Quantization | None:
        if "method" not in data:
            return None
        return cls(
            str(data["method"]),
            int(data["seed"]) if "seed" in data else 0,
            tuple(float(v) for v in np.asarray(data["dpi"]).reshape(-1)) if "dpi" in data else None,
            str(data["upsample"]) if "upsample" in data else "nearest",
            str(data["ink_order"]) if "ink_order" in data else "index",
        )
