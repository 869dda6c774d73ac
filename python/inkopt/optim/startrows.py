"""A run's start given as the whole mixture rows of its free voxels only (a coarse-to-fine job's
``coarse/fine_start.npz``, ``coarse.run_coarse_to_fine``): 8 B of index and 4N B of mixture per free voxel, where a
mixture volume file holds 4N B per grid voxel (Spot 100 mm's 300-DPI grid: 0.9 GB against 19.8 GB).

The file is an .npz (stored, not compressed) of ``format_version`` int64 (``START_FORMAT``), ``grid_shape`` (3,)
int64 (z, y, x), the ink table (``ink_names``, ``ink_sigma_s``, ``ink_sigma_a``), ``free_index`` (F,) int64, the
run's free voxels (strictly increasing flat (z, y, x) indices, ``Parameterization.free_index``), and ``free_rows``
(F, N) float32, their whole mixtures (fixed shares included; finite, non-negative). A run takes it as its start
with ``OptimizeConfig(init=PATH)`` (``param.file_free_mixture``) when its free voxels are exactly the file's, and
reads the rows a block at a time (``start_rows_blocks``), so that only a block of them is in memory beside the
result.
"""

from __future__ import annotations

import zipfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from ..io import FORMAT_KEY, ZIP_READ_ERRORS, Streamed, save_npz, upgrade_format
from ..model import InkTable, VolumeError

#: the format version start-rows files are written in
START_FORMAT = 1
#: the member that makes an .npz a start-rows file
ROWS = "free_rows"
SMALL = (FORMAT_KEY, "grid_shape", "ink_names", "ink_sigma_s", "ink_sigma_a", "g")


def save_start_rows(path, shape, inks: InkTable, index: np.ndarray, rows: Iterable[np.ndarray]) -> Path:
    """Write (atomically) the start-rows file ``path`` of a grid of ``shape`` (z, y, x) with ``inks``: ``index``
    (F,) int64 the free voxels, ``rows`` their (F, N) float32 mixtures as consecutive blocks (k, N) (streamed: never
    whole in memory), each checked finite and non-negative."""
    n = len(inks)

    def checked():
        for part in rows:
            if not np.all(np.isfinite(part)) or np.any(part < 0):
                raise VolumeError("mixture must be finite and non-negative")
            yield part

    arrays = {
        FORMAT_KEY: np.int64(START_FORMAT),
        "grid_shape": np.asarray(shape, np.int64),
        **inks.to_arrays(),
        "free_index": np.asarray(index, np.int64),
        ROWS: Streamed((len(index), n), np.float32, checked()),
    }
    save_npz(path, arrays, compressed=False)
    return Path(path)


def is_start_rows(path) -> bool:
    """Whether ``path`` is an .npz holding a ``free_rows`` member (a start-rows file; anything else, a readable
    zip or not, is not)."""
    try:
        with zipfile.ZipFile(path) as zf:
            return ROWS + ".npy" in zf.namelist()
    except (*ZIP_READ_ERRORS, OSError):
        return False


def start_rows_blocks(path, inks: InkTable, shape, free_index: np.ndarray, voxels: int = 1 << 20):
    """The rows of the start-rows file ``path`` for a run of ``inks`` on a grid of ``shape`` (z, y, x) whose free
    voxels are ``free_index`` (F,) (the file's must be the same): an iterator of (lo, rows), ``rows`` (k, N)
    float32 the whole mixtures of the free voxels lo:lo+k, ``voxels`` rows at a time, each block checked finite and
    non-negative. A file that does not fit (another grid, other inks, other free voxels) or is malformed is a
    one-line error naming it."""
    where = f"`init` {path}"
    try:
        with zipfile.ZipFile(path) as zf:
            small = _small(zf, where)
            if small["ink_names"].tolist() != list(inks.names):
                raise ParameterError(f"{where}: needs a start with inks {list(inks.names)}")
            got = tuple(int(v) for v in np.asarray(small["grid_shape"]).reshape(-1))
            if got != tuple(shape):
                raise ParameterError(f"{where}: a start for a grid of {got}, this run's is {tuple(shape)}")
            _same_index(zf, free_index, where)
            yield from _row_blocks(zf, len(free_index), len(inks), voxels, where)
    except ParameterError:  # a one-line error naming the file already
        raise
    except (*ZIP_READ_ERRORS, KeyError, TypeError, OverflowError) as exc:
        text = " ".join(str(exc).split())
        raise VolumeError(f"{where} is not a readable start file ({type(exc).__name__}: {text})") from None


def _small(zf: zipfile.ZipFile, where: str) -> dict:
    names = set(zf.namelist())
    missing = [k for k in (*SMALL[:4], "free_index", ROWS) if k + ".npy" not in names]
    if missing:
        raise VolumeError(f"{where}: a start file without {', '.join(missing)}")
    small = {k: _small_array(zf, k, where) for k in SMALL if k + ".npy" in names}
    small = upgrade_format(small, kind="start file", where=where, current=START_FORMAT, upgrades={})
    if small["ink_names"].dtype.kind != "U" or np.asarray(small["grid_shape"]).dtype.kind not in "iu":
        raise VolumeError(f"{where}: its ink names or grid shape are not text and integers")
    if np.asarray(small["grid_shape"]).size != 3:
        raise VolumeError(f"{where}: its grid shape is not 3 numbers (z, y, x)")
    return small


#: the most entries a small member (the format version, the grid shape, the ink table) may declare
SMALL_ENTRIES = 1 << 12


def _small_array(zf: zipfile.ZipFile, name: str, where: str) -> np.ndarray:
    """The small member ``name`` of the file, its declared size checked before it is read (a header claiming a
    huge array is refused in one line, not allocated)."""
    with zf.open(name + ".npy") as member:
        shape, _, _ = _read_header(member, where)
    if any(d < 0 for d in shape) or int(np.prod(shape, dtype=np.float64)) > SMALL_ENTRIES:
        raise VolumeError(f"{where}: its {name} declares {tuple(shape)} entries, not a start file's")
    with zf.open(name + ".npy") as member:
        return np.lib.format.read_array(member, allow_pickle=False)


def _read_header(member, where: str) -> tuple:
    """(shape, fortran_order, dtype) of the .npy header of ``member`` (versions 1.0 and 2.0, which numpy and
    inkopt write)."""
    version = np.lib.format.read_magic(member)
    if version not in ((1, 0), (2, 0)):
        raise VolumeError(f"{where}: a member of .npy format version {version}, not 1.0 or 2.0")
    read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
    return read(member)


def _header(member, where: str, dtype, shape) -> None:
    """Read the .npy header of ``member``; one-line VolumeError unless it is C-order ``dtype`` of ``shape``."""
    got_shape, fortran, got_dtype = _read_header(member, where)
    if fortran or got_dtype != np.dtype(dtype) or tuple(got_shape) != tuple(shape):
        raise VolumeError(f"{where}: holds {got_dtype} {tuple(got_shape)}, expected {np.dtype(dtype)} {tuple(shape)}")


def _read(member, n: int, where: str) -> bytes:
    data = member.read(n)
    if len(data) != n:
        raise VolumeError(f"{where}: the file ends early (a truncated file)")
    return data


def _same_index(zf: zipfile.ZipFile, free_index: np.ndarray, where: str, block: int = 1 << 20) -> None:
    """One-line ParameterError unless the file's ``free_index`` is ``free_index``, compared a block at a time."""
    with zf.open("free_index.npy") as member:
        shape, fortran, dtype = _read_header(member, where)
        if fortran or dtype != np.dtype("<i8") or len(shape) != 1:
            raise VolumeError(f"{where}: its free_index is {dtype} {tuple(shape)}, expected int64 (F,)")
        if shape[0] != len(free_index):
            raise ParameterError(
                f"{where}: a start for {shape[0]} free voxels, this run has {len(free_index)} (another scene)"
            )
        for lo in range(0, len(free_index), block):
            part = np.frombuffer(_read(member, 8 * min(block, len(free_index) - lo), where), "<i8")
            if not np.array_equal(part, free_index[lo : lo + block]):
                raise ParameterError(f"{where}: a start for other free voxels than this run's (another scene)")
        _at_end(member, where)


def _at_end(member, where: str) -> None:
    """One-line VolumeError unless ``member`` has nothing after what was read (reading to its end also checks its
    CRC)."""
    if member.read(1):
        raise VolumeError(f"{where}: a member holds more than its header declares")


def _row_blocks(zf: zipfile.ZipFile, f: int, n: int, voxels: int, where: str):
    """(lo, rows (k, N) float32) blocks of the file's ``free_rows`` (F, N), each checked finite and non-negative."""
    with zf.open(ROWS + ".npy") as member:
        _header(member, where, "<f4", (f, n))
        for lo in range(0, f, voxels):
            k = min(voxels, f - lo)
            rows = np.frombuffer(_read(member, 4 * n * k, where), "<f4").reshape(k, n)
            if not np.all(np.isfinite(rows)) or np.any(rows < 0):
                raise VolumeError(f"{where}: its mixture must be finite and non-negative")
            yield lo, rows
        _at_end(member, where)
