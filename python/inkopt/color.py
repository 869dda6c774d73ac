"""Colour science, in one place: sRGB <-> linear RGB, CIE XYZ, CIELAB and its Jacobian, ΔE76, CIEDE2000.

Conventions (docs/conventions.md): predictions and targets are **linear RGB** (sRGB primaries, D65);
CIELAB uses the white of linear sRGB, i.e. ``WHITE_XYZ = M @ (1, 1, 1)`` with Y_white = 1, so that linear
RGB (1, 1, 1) maps to exactly L*a*b* = (100, 0, 0). ``M`` is scikit-image's sRGB->XYZ matrix; its row sums
(0.950456, 1, 1.088754) differ from scikit-image's D65 reference white (0.95047, 1, 1.08883) by < 1e-4, which
moves a* and b* by at most ~3e-3 (tests compare to scikit-image after adapting between the two whites).
Normalised L*a*b* (for the SSIM and Sobel terms): L*/100, (a* + 128)/255, (b* + 128)/255.

A :class:`ColourMap` generalises linear RGB -> XYZ to any C linear channels (a spectral prediction's bands under
a light: ``inkopt.spectral.lights``), CIELAB relative to the map's white; :data:`RGB` is linear sRGB, and the
``linear_to_*`` functions are it.

All conversions accept any array of shape (..., 3) (a colour map's: (..., C)), compute in float64 and return float64,
except the 8-bit file helpers at the end (``to_srgb8``, ``from_srgb8``).
"""

from __future__ import annotations

import numpy as np

# sRGB (linear) -> XYZ, rows X, Y, Z (scikit-image's xyz_from_rgb, IEC 61966-2-1 primaries, D65).
RGB_TO_XYZ = np.array([[0.412453, 0.357580, 0.180423], [0.212671, 0.715160, 0.072169], [0.019334, 0.119193, 0.950227]])
WHITE_XYZ = RGB_TO_XYZ.sum(axis=1)  # white of linear sRGB, Y = 1
_DELTA = 6.0 / 29.0
_EPS = _DELTA**3
# lab = _LAB_D @ f(xyz / white) + (-16, 0, 0)
_LAB_D = np.array([[0.0, 116.0, 0.0], [500.0, -500.0, 0.0], [0.0, 200.0, -200.0]])
_LAB_OFFSET = np.array([-16.0, 0.0, 0.0])
# d normalise_lab / d lab (constant, diagonal) and the offset of normalise_lab.
LAB_NORM_SCALE = np.array([1.0 / 100.0, 1.0 / 255.0, 1.0 / 255.0])
_LAB_NORM_OFFSET = np.array([0.0, 128.0 / 255.0, 128.0 / 255.0])


def _rgb(arr, name: str = "rgb") -> np.ndarray:
    a = np.asarray(arr, dtype=np.float64)
    if a.ndim < 1 or a.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3), got {a.shape}")
    return a


# ----------------------------------------------------------------------------- colour conversions
def srgb_to_linear(srgb) -> np.ndarray:
    """sRGB-encoded values (..., 3) -> linear RGB (IEC 61966-2-1); the linear segment extends below 0."""
    s = _rgb(srgb, "srgb")
    hi = np.power(np.maximum((s + 0.055) / 1.055, 0.0), 2.4)
    return np.where(s > 0.04045, hi, s / 12.92)


def linear_to_srgb(rgb) -> np.ndarray:
    """Linear RGB (..., 3) -> sRGB encoding (IEC 61966-2-1); no clipping (negatives stay linear)."""
    x = _rgb(rgb)
    hi = 1.055 * np.power(np.maximum(x, 0.0031308), 1.0 / 2.4) - 0.055
    return np.where(x > 0.0031308, hi, 12.92 * x)


def linear_to_xyz(rgb) -> np.ndarray:
    """Linear RGB (..., 3) -> CIE XYZ (..., 3), Y of white = 1."""
    return RGB.xyz(rgb)


def _f(t: np.ndarray) -> np.ndarray:
    return np.where(t > _EPS, np.cbrt(t), t / (3.0 * _DELTA**2) + 4.0 / 29.0)


def _fprime(t: np.ndarray) -> np.ndarray:
    c = np.cbrt(np.maximum(t, _EPS))
    return np.where(t > _EPS, 1.0 / (3.0 * c * c), 1.0 / (3.0 * _DELTA**2))


class ColourMap:
    """What turns a prediction's channel values into colour: ``matrix`` (3, C) float64 maps C linear channel values
    (RGB: C = 3; spectral bands: C = B) to CIE XYZ; CIELAB is taken relative to ``white`` = ``matrix @ 1`` (the
    colour of a perfect white, normalised to Y = 1 by whoever builds the matrix). ``name`` says which light or
    space (for reports). :data:`RGB` is linear sRGB (D65); ``inkopt.spectral.lights`` builds one per light for a
    band grid. Every method takes any array of shape (..., C) and computes in float64."""

    def __init__(self, matrix, name: str = "sRGB"):
        m = np.array(matrix, dtype=np.float64)
        if m.ndim != 2 or m.shape[0] != 3 or m.shape[1] < 1 or not np.all(np.isfinite(m)):
            raise ValueError(f"a colour map's matrix must be a finite (3, C) array, got shape {m.shape}")
        white = m.sum(axis=1)
        if not np.all(white > 0):
            raise ValueError(f"a colour map's white {white.tolist()} must be positive")
        m.setflags(write=False)
        self.matrix, self.white, self.name = m, white, str(name)

    @property
    def channels(self) -> int:
        return int(self.matrix.shape[1])

    def _values(self, arr, name: str = "values") -> np.ndarray:
        a = np.asarray(arr, dtype=np.float64)
        if a.ndim < 1 or a.shape[-1] != self.channels:
            raise ValueError(f"{name} must have shape (..., {self.channels}), got {a.shape}")
        return a

    def xyz(self, values) -> np.ndarray:
        """Channel values (..., C) -> CIE XYZ (..., 3), Y of white = 1."""
        return self._values(values) @ self.matrix.T

    def lab(self, values) -> np.ndarray:
        """Channel values (..., C) -> CIELAB (..., 3) relative to :attr:`white`."""
        return _f(self.xyz(values) / self.white) @ _LAB_D.T + _LAB_OFFSET

    def lab_jacobian(self, values) -> np.ndarray:
        """d lab / d values, shape (..., 3, C): element [..., k, j] = d lab_k / d value_j."""
        t = self.xyz(values) / self.white
        a = (_fprime(t) / self.white)[..., :, None] * self.matrix  # d f(t_m) / d value_j
        return np.matmul(_LAB_D, a)

    def lab_vjp(self, values, g_lab) -> np.ndarray:
        """Vector-Jacobian product: g[..., j] = sum_k g_lab[..., k] * d lab_k / d value_j, shape (..., C)."""
        t = self.xyz(values) / self.white
        return ((_rgb(g_lab, "g_lab") @ _LAB_D) * _fprime(t) / self.white) @ self.matrix

    def lab_stderr(self, values, var_mean) -> np.ndarray:
        """Standard error (ΔE76) of the CIELAB colour of means ``values`` (..., C) with variances ``var_mean``
        (channels independent): sqrt(trace(J diag(var) J^T)), J = d lab / d values."""
        jac = self.lab_jacobian(values)
        return np.sqrt(np.einsum("...kj,...j->...", jac * jac, var_mean))


#: linear sRGB (D65): the renderer's RGB channels; its white is WHITE_XYZ
RGB = ColourMap(RGB_TO_XYZ, "sRGB")


def xyz_to_lab(xyz) -> np.ndarray:
    """CIE XYZ (..., 3) -> CIELAB (..., 3) relative to WHITE_XYZ (linear segment below (6/29)^3; no NaN)."""
    t = _rgb(xyz, "xyz") / WHITE_XYZ
    return _f(t) @ _LAB_D.T + _LAB_OFFSET


def linear_to_lab(rgb) -> np.ndarray:
    """Linear RGB (..., 3) -> CIELAB (..., 3) float64."""
    return xyz_to_lab(linear_to_xyz(rgb))


def linear_to_lab_jacobian(rgb) -> np.ndarray:
    """d lab / d rgb, shape (..., 3, 3): element [..., k, j] = d lab_k / d rgb_j."""
    return RGB.lab_jacobian(_rgb(rgb))


def linear_to_lab_vjp(rgb, g_lab) -> np.ndarray:
    """Vector-Jacobian product: g_rgb[..., j] = sum_k g_lab[..., k] * d lab_k / d rgb_j, shape (..., 3)."""
    return RGB.lab_vjp(_rgb(rgb), g_lab)


def normalise_lab(lab) -> np.ndarray:
    """CIELAB (..., 3) -> normalised L*a*b*: L*/100, (a*+128)/255, (b*+128)/255. Derivative: LAB_NORM_SCALE."""
    return _rgb(lab, "lab") * LAB_NORM_SCALE + _LAB_NORM_OFFSET


def delta_e76(lab1, lab2) -> np.ndarray:
    """CIE76 colour difference (...,) between two CIELAB arrays (..., 3)."""
    return np.sqrt(np.sum((_rgb(lab1, "lab1") - _rgb(lab2, "lab2")) ** 2, axis=-1))


def delta_e2000(lab1, lab2) -> np.ndarray:
    """CIEDE2000 colour difference (...,) between two CIELAB arrays (..., 3) (scikit-image)."""
    from skimage.color import deltaE_ciede2000

    return deltaE_ciede2000(_rgb(lab1, "lab1"), _rgb(lab2, "lab2"), channel_axis=-1)


def lab_stderr(rgb, var_mean) -> np.ndarray:
    """Standard error (ΔE76) of the CIELAB colour of means rgb (..., 3) with variances var_mean (channels
    independent): sqrt(trace(J diag(var) J^T)), J = d lab / d rgb."""
    return RGB.lab_stderr(_rgb(rgb), var_mean)


# ----------------------------------------------------------------------------- 8-bit files
def to_srgb8(rgb) -> np.ndarray:
    """Linear RGB (..., 3) -> uint8 sRGB for pictures and colour files (clipped to [0, 1], rounded)."""
    return np.round(np.clip(linear_to_srgb(np.clip(rgb, 0.0, None)), 0.0, 1.0) * 255).astype(np.uint8)


def from_srgb8(srgb, dtype=np.float32) -> np.ndarray:
    """sRGB-encoded values in [0, 1] (..., 3) (e.g. a texture / 255) -> linear RGB clipped to [0, 1]."""
    return np.clip(srgb_to_linear(np.clip(srgb, 0.0, 1.0)), 0.0, 1.0).astype(dtype)
