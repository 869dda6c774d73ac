"""The members of a zip package (GCVF, 3MF): the names a package may hold, and each member read within a bound.

A printer's software unpacks a package into a folder. A member named ``../../x`` (a ``..`` component), ``/x`` or
``\\x`` (absolute), ``C:x`` (a drive), ``a\\b`` (a backslash, a separator on Windows) or holding a NUL or another
control character would be written outside that folder or under another name than the one read here; two members
of one name, or of names differing only in case, make the package mean two things. ``check_names`` refuses such
a package in one line naming the member; it reads the raw names of the zip's directory (``ZipInfo.orig_filename``:
Python's ``zipfile`` cuts a name at a NUL byte). The writers check their own names the same way before a package
is put in place.

``read_member`` reads one member whole after checking its declared (uncompressed) size against a bound, and
``reading`` turns what reading a member can raise (a bad CRC, corrupt compressed data, an unsupported compression
method, encryption, a truncated file, memory running out) into a one-line ``PackageError`` naming the member and
its size.
"""

from __future__ import annotations

import re
import struct
import zipfile
import zlib
from collections.abc import Iterable, Iterator
from contextlib import contextmanager

from ...io import ZIP_READ_ERRORS
from .inspection import PackageError, read_image

_DRIVE = re.compile(r"[A-Za-z]:")


def name_problem(name: str) -> str | None:
    """What makes ``name`` unsafe to unpack (a phrase), or None for a plain relative name."""
    if not name:
        return "has an empty name"
    if any(ord(c) < 32 or ord(c) == 127 for c in name):
        return "holds a control character"
    if name.startswith(("/", "\\")):
        return "is an absolute path"
    if _DRIVE.match(name):
        return "names a drive"
    if "\\" in name:
        return "uses a backslash as a separator"
    if ".." in name.split("/"):
        return "has a '..' component"
    return None


def check_names(names: Iterable[str]) -> None:
    """One-line PackageError for the first unsafe name (``name_problem``) or repeated name (case-insensitive)."""
    seen: dict[str, str] = {}
    for name in names:
        problem = name_problem(name)
        if problem:
            raise PackageError(f"member {name!r} {problem}; a package must not unpack outside its folder")
        key = name.casefold()
        if key in seen:
            also = "" if seen[key] == name else f" (as {seen[key]!r})"
            raise PackageError(f"member {name!r} appears twice{also}; a package names each member once")
        seen[key] = name


def raw_names(zf: zipfile.ZipFile) -> list[str]:
    """The member names as the zip's directory holds them (NUL bytes included)."""
    return [info.orig_filename for info in zf.infolist()]


def size_text(n: int) -> str:
    """A byte count for a message: "4.0 GiB (4294967296 bytes)"."""
    for unit, scale in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= scale:
            return f"{n / scale:.1f} {unit} ({n} bytes)"
    return f"{n} bytes"


@contextmanager
def reading(name: str, size: int | None = None) -> Iterator[None]:
    """Errors of reading member ``name`` (``ZIP_READ_ERRORS``, MemoryError) as one-line PackageErrors naming it and its
    declared uncompressed ``size``."""
    what = name if size is None else f"{name} ({size_text(size)} uncompressed)"
    try:
        yield
    except MemoryError:
        raise PackageError(f"{what} does not fit in memory") from None
    except ZIP_READ_ERRORS as exc:
        if isinstance(exc, PackageError):
            raise
        raise PackageError(f"{what} cannot be read ({type(exc).__name__}: {' '.join(str(exc).split())})") from None


@contextmanager
def open_zip(path) -> Iterator[zipfile.ZipFile]:
    """The zip ``path``, open, once its member names are checked (``check_names``); a file that is no readable zip
    is a one-line PackageError."""
    try:
        zf = zipfile.ZipFile(path)
    except (*ZIP_READ_ERRORS, MemoryError) as exc:
        raise PackageError(f"not a readable zip ({type(exc).__name__}: {' '.join(str(exc).split())})") from None
    with zf:
        check_names(raw_names(zf))
        yield zf


def member_info(zf: zipfile.ZipFile, name: str) -> zipfile.ZipInfo:
    try:
        return zf.getinfo(name)
    except KeyError:
        raise PackageError(f"the package has no {name}") from None


def read_member(zf: zipfile.ZipFile, name: str, limit: int) -> bytes:
    """Member ``name`` whole; a declared size above ``limit`` bytes (the most such a member holds) is refused
    before anything is read."""
    info = member_info(zf, name)
    if info.file_size > limit:
        raise PackageError(
            f"{name} is {size_text(info.file_size)} uncompressed, more than such a member holds ({size_text(limit)})"
        )
    with reading(name, info.file_size):
        return zf.read(info)


def png_limit(width: int, height: int) -> int:
    """The most bytes a PNG of ``width`` x ``height`` pixels holds: 16-bit RGBA stored without compression (8
    bytes per pixel and a filter byte per row), twice over for chunking, plus 1 MiB of other chunks."""
    return 2 * (8 * width * height + height) + 2**20


def png_size(head: bytes) -> tuple[int, int] | None:
    """(width, height) of a PNG from its first 24 bytes (the IHDR chunk), None if they are not a PNG's."""
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def check_png_size(zf, name: str, size) -> None:
    """The zip member ``name`` is a PNG of ``size`` (W, H) pixels by its header: checked before a package's
    declared size is trusted to allocate per-pixel arrays."""
    with reading(name), zf.open(name) as fh:
        got = png_size(fh.read(24))
    if got is None:
        raise PackageError(f"{name} is not a PNG")
    if got != tuple(size):
        raise PackageError(f"{name} is {got[0]} x {got[1]} px; the package declares {size[0]} x {size[1]}")


def decode_png(source, name: str, size, mode="RGBA"):
    """``inspection.read_image`` of ``source`` (bytes or a path), with what an image decoder raises on a corrupt
    PNG besides OSError (a broken chunk, a truncated stream, a decompression bomb) as a one-line PackageError
    naming ``name``."""
    from PIL import Image

    broken = (SyntaxError, EOFError, struct.error, IndexError, TypeError, zlib.error, Image.DecompressionBombError)
    try:
        return read_image(source, name, size, mode)
    except broken as exc:
        raise PackageError(f"{name}: not a readable PNG ({type(exc).__name__}: {' '.join(str(exc).split())})") from None


def read_png(zf: zipfile.ZipFile, name: str, size, mode="RGBA", label: str | None = None):
    """The PNG member ``name`` of ``size`` (W, H) pixels as an array (``decode_png``), read within ``png_limit``;
    ``label`` names it in errors (default ``name``)."""
    return decode_png(read_member(zf, name, png_limit(*size)), label or name, size, mode)
