"""ICC v2 matrix/TRC display profiles built from a colour space's published primaries (colour-science), for
tests of pictures with embedded profiles: the profiles are made here from the standards' numbers, not taken from
files, and LittleCMS (which inkopt uses) and colour-science (which the tests compare against) are independent."""

from __future__ import annotations

import struct

import colour
import numpy as np

D50 = np.array([0.9642, 1.0, 0.8249])
# the sRGB transfer function as ICC parametric curve type 3: Y = (aX + b)^g for X >= d, else cX
SRGB_CURVE = (2.4, 1 / 1.055, 0.055 / 1.055, 1 / 12.92, 0.04045)


def _s15(v: float) -> bytes:
    return struct.pack(">i", round(v * 65536))


def _xyz(v) -> bytes:
    return b"XYZ " + b"\0" * 4 + b"".join(_s15(x) for x in v)


def _curve(curve) -> bytes:
    if isinstance(curve, float):  # a pure gamma: curv with one u8Fixed8 entry
        return b"curv" + b"\0" * 4 + struct.pack(">IH", 1, round(curve * 256)) + b"\0\0"
    return b"para" + b"\0" * 4 + struct.pack(">HH", 3, 0) + b"".join(_s15(x) for x in curve)


def _desc(text: str) -> bytes:
    ascii_ = text.encode("ascii") + b"\0"
    return b"desc" + b"\0" * 4 + struct.pack(">I", len(ascii_)) + ascii_ + struct.pack(">II", 0, 0) + b"\0" * 70


def _pad(b: bytes) -> bytes:
    return b + b"\0" * (-len(b) % 4)


def rgb_profile(space: str, description: str | None = None, curve=None) -> bytes:
    """The bytes of an ICC v2 display profile of colour-science's RGB colour space ``space`` ("Display P3",
    "Adobe RGB (1998)", "sRGB"): colorants adapted to D50 (Bradford), the transfer ``curve`` (a gamma, or the
    parametric sRGB curve by default)."""
    cs = colour.RGB_COLOURSPACES[space]
    white = colour.xy_to_XYZ(cs.whitepoint)
    adapt = colour.adaptation.matrix_chromatic_adaptation_VonKries(white, D50, transform="Bradford")
    colorants = adapt @ cs.matrix_RGB_to_XYZ
    trc = _curve(SRGB_CURVE if curve is None else curve)
    tags = [
        (b"desc", _desc(description or space)),
        (b"wtpt", _xyz(D50)),
        (b"rXYZ", _xyz(colorants[:, 0])),
        (b"gXYZ", _xyz(colorants[:, 1])),
        (b"bXYZ", _xyz(colorants[:, 2])),
        (b"rTRC", trc),
        (b"gTRC", trc),
        (b"bTRC", trc),
        (b"cprt", b"text" + b"\0" * 4 + b"public domain\0"),
    ]
    offset = 128 + 4 + 12 * len(tags)
    table, data = b"", b""
    for sig, body in tags:
        table += sig + struct.pack(">II", offset + len(data), len(body))
        data += _pad(body)
    size = offset + len(data)
    header = struct.pack(">I", size) + b"\0" * 4 + struct.pack(">I", 0x02100000) + b"mntrRGB XYZ "
    header += struct.pack(">6H", 2026, 1, 1, 0, 0, 0) + b"acsp" + b"\0" * 24 + struct.pack(">I", 0)
    header += b"".join(_s15(x) for x in D50)
    header += b"\0" * (128 - len(header))
    return header + struct.pack(">I", len(tags)) + table + data
