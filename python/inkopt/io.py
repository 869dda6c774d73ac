"""Atomic file output: every file inkopt writes appears whole or not at all (temporary file in the same folder,
then an atomic rename), so an interrupted run never leaves a half-written result behind.

Around it: the temporary files' one naming scheme (``temporary_file``, ``is_temporary``; ``remove_temporaries``
clears those a killed process left), the check that an output replaces only a file of its own kind
(``check_output``), and a damaged file told from a stale one (``DamagedFileError``, ``damage_of``)."""

from __future__ import annotations

import hashlib
import io
import json
import lzma
import os
import re
import shutil
import tempfile
import zipfile
import zlib
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import ParameterError


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def publish(tmp: str | Path, path: str | Path, directory: bool = False) -> None:
    """Move a finished temporary file (or folder) into place atomically, with the permissions a newly created
    file (folder) of this user gets (``mkstemp``/``mkdtemp`` create them private: 0600 / 0700)."""
    os.chmod(tmp, (0o777 if directory else 0o666) & ~_umask())
    os.replace(tmp, path)


#: the names of inkopt's temporary files and folders: ``NAME.XXXXXXXX.tmp`` plus an optional extension (``.npz``,
#: ``.npy``: ``temporary_file``), and ``.NAME.XXXXXXXX.tmp`` / ``.old`` folders (a slice folder being replaced); the
#: eight characters are ``tempfile``'s random ones
TEMPORARY_NAME = re.compile(r"^.+\.[a-z0-9_]{8}\.(?:tmp(?:\.[a-z]+)?|old)$")


def temporary_file(path: str | Path, suffix: str = ".tmp") -> tuple[int, Path]:
    """A new private temporary file beside ``path`` for its next content: (an open descriptor, its path), named
    ``NAME.XXXXXXXX`` + ``suffix`` (".tmp", ".tmp.npz", ...: a name ``is_temporary`` knows). Creates the folder."""
    if not suffix.startswith(".tmp"):
        raise ValueError(f"a temporary file's suffix starts with .tmp, got {suffix!r}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=suffix, dir=path.parent)
    return fd, Path(tmp)


def is_temporary(path: str | Path) -> bool:
    """Whether ``path`` is named as inkopt's temporary files and folders are (``TEMPORARY_NAME``)."""
    return TEMPORARY_NAME.match(Path(path).name) is not None


def remove_temporaries(folder: str | Path, skip: Callable[[Path], bool] = lambda p: False) -> tuple[int, int]:
    """Remove the temporary files and folders (``is_temporary``) in ``folder`` and its subfolders but those
    ``skip`` names, left by a process killed while writing; returns (how many, their bytes). Only for a folder no
    other process writes into at the time (a run folder under its lock)."""
    count = size = 0
    with os.scandir(folder) as entries:
        for e in entries:
            path = Path(e.path)
            if is_temporary(path):
                is_dir = e.is_dir(follow_symlinks=False)
                size += sum(f.stat().st_size for f in path.rglob("*") if f.is_file()) if is_dir else e.stat().st_size
                shutil.rmtree(path, ignore_errors=True) if is_dir else path.unlink(missing_ok=True)
                count += 1
            elif e.is_dir(follow_symlinks=False) and not skip(path):
                n, b = remove_temporaries(path, skip)
                count, size = count + n, size + b
    return count, size


@contextmanager
def atomic_file(path: str | Path, suffix: str = ".tmp") -> Iterator:
    """A binary file to write ``path``'s new content to: a temporary file (``temporary_file``, ``suffix``) in the
    same folder that replaces ``path`` when the block ends (``publish``); if the block raises or is interrupted,
    the temporary file is removed and ``path`` stays as it was. Creates the folder."""
    fd, tmp = temporary_file(path, suffix)
    try:
        with os.fdopen(fd, "wb") as fh:
            yield fh
        publish(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (``atomic_file``)."""
    with atomic_file(path) as fh:
        fh.write(data)


@dataclass
class Streamed:
    """An array written to an .npz piece by piece (``save_npz``), never whole in memory: ``shape`` and ``dtype``
    of the whole, and ``parts``, an iterable of C-contiguous blocks along axis 0 that together make it, in order
    (e.g. slabs of layers of a grid-sized array)."""

    shape: tuple
    dtype: np.dtype
    parts: Iterable[np.ndarray]


def _write_streamed(fh, a: Streamed) -> None:
    dtype = np.dtype(a.dtype)
    np.lib.format.write_array_header_2_0(
        fh, {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False, "shape": tuple(a.shape)}
    )
    rows, inner = 0, tuple(a.shape[1:])
    for part in a.parts:
        part = np.ascontiguousarray(part, dtype)
        if part.shape[1:] != inner:
            raise ValueError(f"a streamed part has shape {part.shape}, expected (k,) + {inner}")
        fh.write(part.data)
        rows += len(part)
    if rows != a.shape[0]:
        raise ValueError(f"the streamed parts hold {rows} rows, expected {a.shape[0]}")


def save_npz(path: str | Path, arrays: dict, compressed: bool = True) -> None:
    """Write an .npz atomically. Values may be ``Streamed`` (written piece by piece; the file reads back as if
    the whole array had been given)."""
    with atomic_file(path, ".tmp.npz") as fh:
        if not any(isinstance(v, Streamed) for v in arrays.values()):
            (np.savez_compressed if compressed else np.savez)(fh, **arrays)
        else:  # what np.savez does, member by member, with the streamed ones written in parts
            mode = zipfile.ZIP_DEFLATED if compressed else zipfile.ZIP_STORED
            with zipfile.ZipFile(fh, "w", compression=mode, allowZip64=True) as zf:
                for name, v in arrays.items():
                    with zf.open(name + ".npy", "w", force_zip64=True) as member:
                        if isinstance(v, Streamed):
                            _write_streamed(member, v)
                        else:
                            np.lib.format.write_array(member, np.asanyarray(v), allow_pickle=False)


def _no_pickles(what: str, path) -> str:
    """The one-line refusal of a file holding pickled Python objects (numpy's own advice, ``allow_pickle=True``,
    would run code from the file)."""
    return (
        f"{what} {path} holds Python objects (pickled data), not a numeric array; save a number array with numpy.save"
    )


def load_array(path: str | Path, what: str = "array") -> np.ndarray:
    """The array of a .npy file; a missing, unreadable or pickled file is a one-line ValueError naming ``what``."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{what} {path} does not exist")
    try:
        a = np.load(path, allow_pickle=False)
    except ValueError as exc:
        if "allow_pickle" in str(exc):
            raise ValueError(_no_pickles(what, path)) from None
        raise ValueError(f"cannot read {what} {path}: {exc}") from None
    except Exception as exc:
        raise ValueError(f"cannot read {what} {path} ({type(exc).__name__}: {exc})") from None
    if not isinstance(a, np.ndarray):
        raise ValueError(f"{what} {path} is an .npz archive, not one .npy array")
    return a


#: what reading a zip (an .npz, a printer package) or one of its members may raise besides MemoryError: a bad
#: CRC, corrupt compressed data, an unsupported compression method or zip version, encryption, a truncated file
ZIP_READ_ERRORS = (
    OSError,
    EOFError,
    ValueError,
    RuntimeError,
    NotImplementedError,
    zipfile.BadZipFile,
    zlib.error,
    lzma.LZMAError,
)


def load_npz(path: str | Path, what: str = "file") -> dict:
    """All arrays of an .npz as a dict; a missing, unreadable or pickled file is a one-line ValueError."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{what} {path} does not exist")
    try:
        with np.load(path, allow_pickle=False) as z:
            return dict(z)
    except ValueError as exc:
        if "allow_pickle" in str(exc):
            raise ValueError(_no_pickles(what, path)) from None
        raise ValueError(f"{path} is not a readable .npz {what} ({type(exc).__name__}: {exc})") from None
    except Exception as exc:  # zipfile/format errors: one line
        raise ValueError(f"{path} is not a readable .npz {what} ({type(exc).__name__}: {exc})") from None


def write_json(path: str | Path, data, indent: int | None = 2) -> Path:
    atomic_write_bytes(path, (json.dumps(data, indent=indent) + "\n").encode())
    return Path(path)


def write_png(path: str | Path, image) -> Path:
    """A PIL image or a (H, W, 3|4) uint8 array as PNG."""
    from PIL import Image

    if isinstance(image, np.ndarray):
        image = Image.fromarray(image)
    buf = io.BytesIO()
    image.save(buf, format="PNG")
    atomic_write_bytes(path, buf.getvalue())
    return Path(path)


def save_figure(path: str | Path, fig, dpi: int = 110) -> Path:
    """A matplotlib figure as PNG."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    atomic_write_bytes(path, buf.getvalue())
    return Path(path)


FORMAT_KEY = "format_version"


class FormatError(ParameterError):
    """A file of a format version this inkopt cannot read (one line: the file, its version, what to do; parameters
    it names are in backticks, ``errors.ParameterError``)."""


def format_version_of(data) -> int:
    """The ``format_version`` of a loaded file (a JSON object, or the arrays of an .npz, where it is a 0-d
    array); 0 for a file written before files carried one."""
    v = data.get(FORMAT_KEY, 0)
    return int(np.asarray(v).item()) if not isinstance(v, int) else v


def upgrade_format(data: dict, *, kind: str, where, current: int, upgrades: dict) -> dict:
    """Bring a loaded file to format version ``current``.

    ``data``: a JSON object or the dict of an .npz's arrays. ``upgrades[v]`` turns version ``v`` into ``v + 1``
    (a function of the dict, returning the new dict): one per older version users may hold. A newer version, or an
    older one without an upgrade, is a one-line ``FormatError`` naming ``where`` and the ``kind`` of file. The
    result carries ``format_version = current``.
    """
    try:
        v = format_version_of(data)
    except (TypeError, ValueError, OverflowError):
        raise FormatError(f"{where}: its {FORMAT_KEY} is not a whole number (a damaged {kind})") from None
    if v > current:
        raise FormatError(
            f"{where} is a {kind} of format version {v}; this inkopt reads versions up to {current} (update inkopt)"
        )
    data = dict(data)
    while v < current:
        if v not in upgrades:
            oldest = min(upgrades, default=current)
            raise FormatError(
                f"{where} is a {kind} of format version {v}, which this inkopt no longer reads "
                f"(it reads versions {oldest} to {current}); write it again with this inkopt"
            )
        data = dict(upgrades[v](data))
        v += 1
    data[FORMAT_KEY] = current
    return data


def file_digest(path: str | Path, chunk: int = 1 << 24) -> str:
    """``"sha256:<hex>"`` of a file's bytes, read in chunks (a GB-sized labels file never whole in memory). Outputs
    record the digest of the file they were made from, so that a stale output can be told from a current one."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return "sha256:" + h.hexdigest()


def source_comment(source: str | None, digest: str | None) -> bytes:
    """The zip archive comment of a printer package (GCVF, 3MF) recording the file it was made from:
    ``{"inkopt": {"source": NAME, "digest": "sha256:..."}}`` (empty without a digest). Printer software ignores
    archive comments."""
    if digest is None:
        return b""
    return json.dumps({"inkopt": {"source": source, "digest": digest}}, separators=(",", ":")).encode()


def read_source_comment(comment: bytes) -> dict | None:
    """{"source", "digest"} from an archive comment written by ``source_comment``, else None."""
    try:
        rec = json.loads(comment.decode())["inkopt"]
        return {"source": rec.get("source"), "digest": str(rec["digest"])}
    except (ValueError, KeyError, TypeError, AttributeError):
        return None


def package_source(path: str | Path) -> dict | None:
    """The source record of a printer package (a zip) at ``path``: ``read_source_comment`` of its archive comment,
    None if it is not a readable zip or records none."""
    try:
        with zipfile.ZipFile(path) as zf:
            return read_source_comment(zf.comment)
    except ZIP_READ_ERRORS:
        return None


# ------------------------------------------------------------------ outputs and the files they replace
def check_output(path: str | Path, ours: Callable[[Path], bool], what: str, folder: bool = False) -> Path:
    """``path`` as a ``Path`` if an output may be written there, else a one-line ValueError naming it. An output
    never replaces what its command did not write: ``path`` must be absent, or a file (``folder``: a folder) that
    ``ours(path)`` recognises by its content as ``what``, the command's own earlier output, which is replaced."""
    path = Path(path)
    if not path.exists():
        return path
    if path.is_dir() != folder:
        kind, name = ("a folder", "file") if path.is_dir() else ("a file", "folder")
        raise ValueError(f"{path} is {kind}, not {what}; give a {name} name")
    if not ours(path):
        raise ValueError(f"{path} exists and is not {what}; refusing to replace it")
    return path


def read_head(path: str | Path, size: int = 1 << 16) -> bytes:
    """The first ``size`` bytes of a file (b"" if it cannot be read): enough to recognise a file by its content."""
    try:
        with open(path, "rb") as fh:
            return fh.read(size)
    except OSError:
        return b""


def read_json_object(path: str | Path, limit: int = 1 << 24) -> dict | None:
    """The JSON object in a file of at most ``limit`` bytes, None if it is not one (missing, larger, unreadable)."""
    try:
        if Path(path).stat().st_size > limit:
            return None
        data = json.loads(Path(path).read_bytes())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


# ------------------------------------------------------------------ damaged files
class DamagedFileError(ValueError):
    """A file that cannot be read any more (truncated, partly overwritten, changed since it was written): one line
    naming it, what is wrong and what to run again."""


def damaged(path, reason: str, remedy: str = "rerun the command that wrote it") -> DamagedFileError:
    """The one-line error of a damaged file: ``PATH is damaged (cannot be read: REASON); REMEDY``."""
    return DamagedFileError(f"{path} is damaged (cannot be read: {reason}); {remedy}")


def damage_of(path: str | Path, thorough: bool = True) -> str | None:
    """Why the file ``path`` cannot be read as its suffix says, or None if it can. .npz: a zip archive (its table
    of contents, at its end: a truncated file fails) whose every member reads back with its checksum (``thorough``:
    the whole file is read, one member at a time); .npy: a header and as many bytes as it declares; .json: one JSON
    value; other files: only that they can be opened."""
    path = Path(path)
    try:
        if path.suffix == ".npz":
            with zipfile.ZipFile(path) as zf:
                bad = zf.testzip() if thorough else None
            return None if bad is None else f"member {bad} fails its checksum"
        if path.suffix == ".npy":
            np.load(path, mmap_mode="r", allow_pickle=False)
        elif path.suffix == ".json":
            json.loads(path.read_bytes())
        else:
            path.open("rb").close()
    except Exception as exc:  # zip, zlib, format and decoding errors alike: the reason in one line
        return " ".join(f"{type(exc).__name__}: {exc}".split())
    return None
