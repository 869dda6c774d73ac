"""Display lighting: the light around a print while it is looked at, for renders, optimisation and evaluation.

``load_lighting("uniform" | FILE, rotate_deg=0)`` gives a :class:`Lighting`: the uniform white environment of
radiance 1 (the default everywhere), or an equirectangular environment map of linear radiance read from a
Radiance ``.hdr`` or OpenEXR ``.exr`` file (through OpenCV, ``opencv-python-headless``) or a ``.npy`` array of
shape (H, W, 3), RGB. The renderer (``crates/core/src/transport/light.rs``, ``EnvMap``) looks every path that leaves the
object up in the map, bilinearly and per channel.

World frame (docs/conventions.md, z up): the map has W = 2H columns; row 0 looks straight up (+z), the middle of
the map is the horizon, the last row looks straight down; column 0 starts at +x and longitude grows towards +y
(pixel (i, j) covers colatitude [i, i + 1] pi / H and longitude [j, j + 1] 2 pi / W). ``rotate_deg`` turns the map
about z, from +x towards +y. Maps are not normalised: radiance 1 everywhere is exactly the uniform light.
"""

from __future__ import annotations

import hashlib
import io
import os
import re
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import ParameterError
from .images import MAX_IMAGE_PIXELS, check_pixels
from .io import load_array

UNIFORM = "uniform"
MAP_SUFFIXES = (".hdr", ".pic", ".exr", ".npy")


@dataclass(frozen=True)
class Lighting:
    """The display lighting: ``map`` (H, 2H, 3) float32 linear radiance, or None for the uniform light of
    radiance 1; ``rotate_deg`` about z; ``source``: "uniform" or the map's file name."""

    map: np.ndarray | None = field(default=None, repr=False)
    rotate_deg: float = 0.0
    source: str = UNIFORM

    @property
    def uniform(self) -> bool:
        return self.map is None

    def key(self) -> str:
        """What identifies this lighting (for checkpoints): "uniform", or the map's digest and rotation."""
        if self.map is None:
            return UNIFORM
        digest = hashlib.sha1(np.ascontiguousarray(self.map).tobytes()).hexdigest()[:16]
        return f"map:{digest}:{self.rotate_deg:g}"

    def describe(self) -> dict:
        """Report fields: the source, rotation, map size and solid-angle mean radiance."""
        d = {"lighting": self.source, "lighting_rotate_deg": float(self.rotate_deg)}
        if self.map is not None:
            d["lighting_map_shape"] = list(self.map.shape)
            d["lighting_mean_radiance"] = [float(x) for x in mean_radiance(self.map)]
        return d


def mean_radiance(env: np.ndarray) -> np.ndarray:
    """The solid-angle average of a map's radiance (3,) (rows weighted by the solid angle of their band)."""
    h = env.shape[0]
    edges = np.linspace(0.0, np.pi, h + 1)
    w = np.cos(edges[:-1]) - np.cos(edges[1:])  # band solid angle / 2 pi
    return np.einsum("i,ijc->c", w / w.sum(), env.astype(np.float64)) / env.shape[1]


def check_map(env, name: str = "map") -> np.ndarray:
    """``env`` as a C-contiguous float32 (H, 2H, 3) array; ValueError (one line) for another shape, NaN,
    infinite or negative radiance."""
    a = np.asarray(env)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"{name}: an environment map must be an (H, W, 3) RGB image, got shape {a.shape}")
    h, w = a.shape[:2]
    if h < 1 or w != 2 * h:
        raise ValueError(
            f"{name}: not an equirectangular map: {w} x {h} pixels (W x H); the width must be twice the height"
        )
    if not np.issubdtype(a.dtype, np.floating) and not np.issubdtype(a.dtype, np.integer):
        raise ValueError(f"{name}: map values must be numbers, got dtype {a.dtype}")
    a = np.ascontiguousarray(a, np.float32)
    bad = ~np.isfinite(a)
    if bad.any():
        i, j, c = np.argwhere(bad)[0]
        raise ValueError(f"{name}: radiance is NaN or infinite at row {i}, column {j} ({int(bad.sum())} values)")
    if (a < 0).any():
        i, j, c = np.argwhere(a < 0)[0]
        raise ValueError(
            f"{name}: negative radiance {a[i, j, c]:g} at row {i}, column {j}; linear radiance must be >= 0"
        )
    return a


def _cv2():
    os.environ.setdefault("OPENCV_IO_ENABLE_OPENEXR", "1")  # read before cv2 is first imported
    os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")
    # OpenCV's own pixel limit (2**30 by default) set to inkopt's, for a header _map_size cannot read
    os.environ.setdefault("OPENCV_IO_MAX_IMAGE_PIXELS", str(MAX_IMAGE_PIXELS))
    import cv2

    return cv2


_EXR_MAGIC = b"\x76\x2f\x31\x01"
_EXR_WINDOW = b"dataWindow\0box2i\0"


def _map_size(path: Path) -> tuple[int, int] | None:
    """(W, H) px of a Radiance .hdr/.pic or OpenEXR file as its header declares it, or None where the first 64 KiB
    do not say. Radiance: text lines, a blank line, then the resolution line (``-Y H +X W``); OpenEXR: the
    ``dataWindow`` attribute (name, type ``box2i``, a 4-byte size, then xmin, ymin, xmax, ymax as int32)."""
    with open(path, "rb") as f:
        head = f.read(1 << 16)
    if head.startswith(b"#?"):
        m = re.search(rb"\n\n([-+])([XY]) +(\d+) +([-+])([XY]) +(\d+)", head.replace(b"\r\n", b"\n"))
        if m:
            first, second = int(m.group(3)), int(m.group(6))
            return (second, first) if m.group(2) == b"Y" else (first, second)
    elif head.startswith(_EXR_MAGIC) and _EXR_WINDOW in head:
        try:
            x0, y0, x1, y1 = struct.unpack_from("<4i", head, head.index(_EXR_WINDOW) + len(_EXR_WINDOW) + 4)
        except struct.error:
            return None
        return max(0, x1 - x0 + 1), max(0, y1 - y0 + 1)
    return None


def read_map(path) -> np.ndarray:
    """Read and check an environment map file (.hdr/.pic, .exr or .npy); (H, 2H, 3) float32 RGB."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in MAP_SUFFIXES:
        raise ValueError(f"cannot read lighting '{path}': use 'uniform' or a map file ({', '.join(MAP_SUFFIXES)})")
    if not p.is_file():
        raise ValueError(f"cannot read lighting '{path}': no such file")
    if suffix == ".npy":
        a = load_array(p, "lighting map")
    else:
        size = _map_size(p)
        if size is not None:
            check_pixels(size, f"lighting '{path}'")  # before OpenCV decodes it
        cv2 = _cv2()
        a = cv2.imread(str(p), cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR)
        if a is None:
            raise ValueError(f"cannot read lighting '{path}': not a readable {suffix} image")
        if a.ndim == 3 and a.shape[2] == 4:
            a = a[..., :3]  # drop alpha
        if a.ndim == 3 and a.shape[2] == 3:
            a = a[..., ::-1]  # OpenCV's BGR -> RGB
    return check_map(a, f"lighting '{path}'")


def write_map(path, env) -> Path:
    """Write a map (H, 2H, 3) linear RGB as .npy, .hdr or .exr (float32), atomically; returns the path."""
    from .io import atomic_write_bytes

    p = Path(path)
    env = check_map(env, str(p))
    suffix = p.suffix.lower()
    if suffix == ".npy":
        buf = io.BytesIO()
        np.save(buf, env)
        data = buf.getvalue()
    elif suffix in MAP_SUFFIXES:
        ok, enc = _cv2().imencode(suffix, np.ascontiguousarray(env[..., ::-1]))
        if not ok:
            raise ValueError(f"cannot encode {p} as {suffix}")
        data = enc.tobytes()
    else:
        raise ValueError(f"cannot write {p}: use one of {', '.join(MAP_SUFFIXES)}")
    atomic_write_bytes(p, data)
    return p


def load_lighting(spec=None, rotate_deg: float = 0.0) -> Lighting:
    """``spec``: None or "uniform" (the uniform light of radiance 1), a map file (see :func:`read_map`) or a
    :class:`Lighting` (returned, rotated by ``rotate_deg`` more)."""
    rotate_deg = float(rotate_deg)
    if not np.isfinite(rotate_deg):
        raise ParameterError(f"`lighting_rotate` must be a finite angle in degrees, got {rotate_deg}")
    if isinstance(spec, Lighting):
        env = None if spec.map is None else check_map(spec.map, f"lighting '{spec.source}'")
        return Lighting(env, spec.rotate_deg + rotate_deg, spec.source)
    if spec is None or str(spec) == UNIFORM:
        if rotate_deg != 0.0:
            raise ParameterError("`lighting_rotate` turns a map; it has no meaning with uniform lighting")
        return Lighting()
    return Lighting(read_map(spec), rotate_deg, Path(spec).name)
