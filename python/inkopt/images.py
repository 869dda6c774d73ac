"""Opening image files: the one function every image read goes through (slab pictures, mesh textures, translucency
masks, printer packages' layers), with a pixel limit against decompression bombs.

A PNG of one colour compresses about 1000:1, so a 1.2 MB file can declare 20000 x 20000 pixels: 1.6 GB decoded as
8-bit RGBA and 6.4 GB as the float32 RGBA the scenes work in. :func:`open_image` reads the header first and refuses
an image of more than ``MAX_IMAGE_PIXELS`` pixels before anything is decoded, in one line naming the file, its pixel
count and the limit. Pillow's own guard (a ``DecompressionBombWarning`` above its ``Image.MAX_IMAGE_PIXELS``,
89 478 485 pixels, and a ``DecompressionBombError`` above twice that, both with no file name) never fires for an
image within this limit, which lies below Pillow's; its error for a larger one is turned into this module's.
"""

from __future__ import annotations

import io
import re
import struct
import warnings
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from PIL import Image

__all__ = ["MAX_IMAGE_PIXELS", "ImageError", "ImageTooLargeError", "check_pixels", "decode_pixels", "open_image"]

# 2**26 = 67 108 864 pixels: an 8192 x 8192 texture, 1 GiB as float32 RGBA (16 bytes a pixel, the form pictures and
# textures are decoded to). Every input inkopt needs fits: a slab picture is resampled to the 300 DPI grid (a 50 cm
# face is 5906 px wide), a mesh texture is rarely more than 8192 px square, and a printer layer of a whole J750 tray
# (49 x 39 cm at 600 x 300 DPI) is 11575 x 4606 = 53.3 million pixels.
MAX_IMAGE_PIXELS = 1 << 26

# What Pillow raises for a damaged file, while reading its header or decoding its pixels.
_READ_ERRORS = (OSError, SyntaxError, EOFError, struct.error, zlib.error, IndexError, TypeError, ValueError)


class ImageError(ValueError):
    """An image file that does not exist, cannot be read, or has more than ``MAX_IMAGE_PIXELS`` pixels (one line
    naming the file)."""


class ImageTooLargeError(ImageError):
    """An image of more than ``MAX_IMAGE_PIXELS`` pixels; the message ends with what to do ("scale it down")."""


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def check_pixels(size: tuple[int, int], name: str) -> None:
    """ImageError unless an image of ``size`` (W, H) px has at most ``MAX_IMAGE_PIXELS`` pixels; ``name`` names
    the file in the message (e.g. "texture /data/spot.png")."""
    w, h = (int(v) for v in size)
    if w * h > MAX_IMAGE_PIXELS:
        raise ImageTooLargeError(_too_large(name, w * h, f"{w} x {h} px, "))


def _too_large(name: str, pixels: int, dims: str = "") -> str:
    return (
        f"{name} has {dims}{pixels:,} pixels, more than the limit of {MAX_IMAGE_PIXELS:,} (8192 x 8192) that "
        "guards against decompression bombs; scale it down"
    )


def _open(source, name: str) -> Image.Image:
    """The image of ``source`` (a path or the file's bytes), header read and its size checked, pixels not read."""
    from PIL import Image, UnidentifiedImageError

    fp = io.BytesIO(source) if isinstance(source, (bytes, bytearray, memoryview)) else source
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)  # the size is checked below, with the name
        try:
            im = Image.open(fp)
        except FileNotFoundError:
            raise ImageError(f"{name} does not exist") from None
        except Image.DecompressionBombError as exc:  # above twice Pillow's limit, itself above this module's
            found = re.search(r"\((\d+) pixels\)", str(exc))
            pixels = int(found.group(1)) if found else 2 * MAX_IMAGE_PIXELS
            raise ImageTooLargeError(_too_large(name, pixels)) from None
        except UnidentifiedImageError:
            raise ImageError(f"cannot read {name}: not an image file Pillow reads") from None
        except _READ_ERRORS as exc:
            raise ImageError(f"cannot read {name}: {_one_line(exc)}") from None
    try:
        check_pixels(im.size, name)
    except ImageError:
        im.close()
        raise
    return im


@contextmanager
def open_image(source: str | Path | bytes, name: str, decode: bool = True) -> Iterator[Image.Image]:
    """A PIL image of ``source`` (a path or the file's bytes) for a ``with`` block, closed after it.

    ``name`` says what the file is, with its path, for the messages ("picture top.png", "texture /x/t.png").
    The header is read first: a missing or unreadable file, or one of more than ``MAX_IMAGE_PIXELS`` pixels, is an
    :class:`ImageError` (one line) before any pixel is decoded. With ``decode`` the pixels are read before the
    image is handed over, so a damaged file is an ImageError here too; without, only the header is (for the size
    and mode)."""
    im = _open(source, name)
    try:
        if decode:
            decode_pixels(im, name)
        yield im
    finally:
        im.close()


def decode_pixels(im: Image.Image, name: str) -> None:
    """Decode the pixels of an opened image whose size has been checked (:func:`check_pixels`), e.g. one another
    library opened; a damaged file is an :class:`ImageError` naming ``name``."""
    try:
        im.load()
    except _READ_ERRORS as exc:
        raise ImageError(f"cannot read {name}: {_one_line(exc)}") from None
