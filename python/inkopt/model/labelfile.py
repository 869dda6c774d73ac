"""Printer label stacks too big to hold twice, written one layer at a time (docs/run-dir.md, "Printer labels").

Two forms:

- version 1, ``quantized_labels.npy``: an uncompressed ``.npy`` file (uint8 (Z, Y, X), C order), 1 byte per
  printer voxel on disk, read back memory-mapped (``numpy.load(mmap_mode="r")``: pages are read when touched);
- version 2, ``quantized_labels.layers`` (``LabelLayers``): each layer deflated on its own, so the disk
  holds about what the labels' variety needs: an object's homogeneous core and the empty space around it cost a
  few bytes per layer, the dithered band under the surface about 2-4 bits per voxel. It is read a layer at a time.

``LabelFileWriter`` (version 1) and ``LabelLayersWriter`` (version 2) take the layers in order
(``w[k] = layer``) into a temporary sibling file (``io.temporary_file``; written with an ordinary sequential
``write``, so the pages stay in the page cache, not in the process's memory), counting the labels and hashing the
file's bytes on the way (``digest``, equal to ``io.file_digest`` of the file, without reading it back); ``commit``
renames it into place atomically. ``load_label_file`` reads either form, told by its first bytes.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import struct
import threading
import zlib
from pathlib import Path

import numpy as np

from ..io import publish, temporary_file

__all__ = ["LabelFileWriter", "LabelLayers", "LabelLayersWriter", "is_layers_file", "load_label_file"]


class LabelFileWriter:
    """``w = LabelFileWriter(path, (Z, Y, X)); w[0] = layer0; w[1] = ...; w.commit()`` (or ``w.abort()``).

    Layers must come in order 0, 1, ..., Z - 1; ``counts`` (256,) int64 counts every label value written;
    ``digest``: ``"sha256:<hex>"`` of the file's bytes (header and every layer written so far)."""

    def __init__(self, path, shape):
        self.path = Path(path)
        self.shape = tuple(int(s) for s in shape)
        if len(self.shape) != 3 or min(self.shape) < 1:
            raise ValueError(f"a label stack needs 3 positive sizes (Z, Y, X), got {self.shape}")
        fd, self._tmp = temporary_file(self.path, ".tmp" + self.path.suffix)
        self._fh = os.fdopen(fd, "wb")
        self._hash = hashlib.sha256()
        self.written, self.offsets = 0, []
        self._write(self._header())
        self.next = 0
        self.counts = np.zeros(256, np.int64)

    def _header(self) -> bytes:
        header = io.BytesIO()
        np.lib.format.write_array_header_1_0(header, {"descr": "|u1", "fortran_order": False, "shape": self.shape})
        return header.getvalue()

    def _layer(self, lay: np.ndarray) -> None:
        self._write(memoryview(lay).cast("B"))

    def _finish(self) -> None:
        """What follows the last layer (nothing in a .npy file)."""

    def __setitem__(self, k: int, layer) -> None:
        if int(k) != self.next or self.next >= self.shape[0]:
            raise ValueError(f"label layers must be written in order: expected layer {self.next}, got {k}")
        lay = np.ascontiguousarray(layer, np.uint8)
        if lay.shape != self.shape[1:]:
            raise ValueError(f"label layer {k} has shape {lay.shape}, expected {self.shape[1:]}")
        self._layer(lay)
        self.counts += np.bincount(lay.ravel(), minlength=256)
        self.next += 1

    def _write(self, data) -> None:
        self._fh.write(data)
        self._hash.update(data)
        self.written += len(data) if isinstance(data, bytes) else data.nbytes

    @property
    def digest(self) -> str:
        return "sha256:" + self._hash.hexdigest()

    def commit(self) -> Path:
        if self.next != self.shape[0]:
            self.abort()
            raise ValueError(f"label stack incomplete: {self.next} of {self.shape[0]} layers written")
        self._finish()
        self._fh.close()
        publish(self._tmp, self.path)
        return self.path

    def abort(self) -> None:
        self._fh.close()
        self._tmp.unlink(missing_ok=True)


def load_label_file(path, shape=None, layered: bool = False):
    """The labels of a label stack file (uint8 (Z, Y, X)); ``shape`` checks it. Version 1 is memory-mapped
    read-only; version 2 (``LabelLayers``) is decoded into a read-only array, or with ``layered`` kept as
    the layer source (``[k]`` decodes layer k; 1 byte per voxel of a layer or two in memory). A missing or
    malformed file is a one-line ValueError."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"label file {path} does not exist (a quantized.npz needs its labels file beside it)")
    if is_layers_file(path):
        lab = LabelLayers(path, shape)
        return lab if layered else lab.dense()
    try:
        lab = np.load(path, mmap_mode="r", allow_pickle=False)
    except Exception as exc:  # format errors: one line
        raise ValueError(f"{path} is not a readable .npy label file ({type(exc).__name__}: {exc})") from None
    if lab.dtype != np.uint8 or lab.ndim != 3 or (shape is not None and lab.shape != tuple(int(s) for s in shape)):
        raise ValueError(
            f"{path} holds {lab.dtype} {lab.shape}, expected uint8 labels of shape "
            f"{tuple(shape) if shape is not None else '(Z, Y, X)'}"
        )
    return lab


# ---------------------------------------------------------------------------------------------- version 2
#: the first bytes of a version-2 label file; then a uint32 (little-endian) length and that many bytes of JSON
#: ({"version": 2, "shape": [Z, Y, X], "codec": "zlib"}), the Z deflated layers one after the other, their
#: (Z + 1,) uint64 start offsets (the last: where the index begins), and a trailer: the index's offset (uint64)
#: and ``LAYERS_END``
LAYERS_MAGIC, LAYERS_END, LAYERS_VERSION = b"INKOPT LABEL LAYERS\n", b"LAYERS\x00\x02", 2
_U64 = np.dtype("<u8")


def is_layers_file(path) -> bool:
    """Whether the file at ``path`` starts as a version-2 label file does."""
    with open(path, "rb") as fh:
        return fh.read(len(LAYERS_MAGIC)) == LAYERS_MAGIC


class LabelLayersWriter(LabelFileWriter):
    """``LabelFileWriter``'s interface for the version-2 form: each layer deflated (zlib ``level``; 1 is fast and
    already makes a homogeneous layer a few hundred bytes) and written as it comes; the offsets and trailer are
    written by ``commit``."""

    def __init__(self, path, shape, level: int = 1):
        self.level = int(level)
        super().__init__(path, shape)

    def _header(self) -> bytes:
        head = json.dumps({"version": LAYERS_VERSION, "shape": list(self.shape), "codec": "zlib"}).encode()
        return LAYERS_MAGIC + struct.pack("<I", len(head)) + head

    def _layer(self, lay: np.ndarray) -> None:
        self.offsets.append(self.written)
        self._write(zlib.compress(memoryview(lay).cast("B"), self.level))

    def _finish(self) -> None:
        index = self.written
        self._write(np.asarray([*self.offsets, index], _U64).tobytes())
        self._write(struct.pack("<Q", index) + LAYERS_END)


class LabelLayers:
    """A version-2 label file read a layer at a time: ``shape`` (Z, Y, X), ``dtype`` uint8, ``ndim`` 3;
    ``labels[k]`` layer k (Y, X) (read-only; the last two decoded are kept), ``labels[a:b]`` a stack of layers,
    ``dense()`` every layer in one read-only array. The file stays open until ``close()`` (or the object is
    dropped), and every layer is read from it with ``os.pread``: a file replaced under the same name meanwhile (an
    atomic rewrite) or removed is still read as it was opened, never a mixture of two files; threads may read
    layers at once. A file that is not one, or whose parts disagree, is a one-line ValueError when opened; a layer
    that does not inflate to its size is one when read."""

    dtype, ndim = np.dtype(np.uint8), 3

    def __init__(self, path, shape=None):
        self.path = Path(path)
        self._fh = open(self.path, "rb")  # noqa: SIM115 (held for the reads; closed by close())
        try:
            self.shape, self.offsets = self._read_layout(self._fh, os.fstat(self._fh.fileno()).st_size)
            if shape is not None and self.shape != tuple(int(s) for s in shape):
                raise ValueError(f"{self.path} holds labels of shape {self.shape}, expected {tuple(shape)}")
        except BaseException:
            self._fh.close()
            raise
        self._cache: dict[int, np.ndarray] = {}
        self._lock = threading.Lock()  # the cache, for threads reading layers at once

    def close(self) -> None:
        """Close the file and drop the decoded layers kept (a later layer read is a ValueError)."""
        self._fh.close()
        with self._lock:
            self._cache.clear()

    def __del__(self) -> None:
        fh = getattr(self, "_fh", None)
        if fh is not None:
            fh.close()

    def __enter__(self) -> LabelLayers:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __getstate__(self) -> dict:  # pickled (a process pool, Ray) by its path, opened again where it is read
        return {"path": self.path, "shape": self.shape, "offsets": self.offsets}

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["path"], state["shape"])
        if not np.array_equal(self.offsets, state["offsets"]):
            raise ValueError(f"{self.path} changed since its label layers were opened")

    def _read_layout(self, fh, size: int):
        """(shape, (Z + 1,) int64 layer offsets) from the header and the index, checked against each other."""
        bad = f"{self.path} is not a readable label layers file"
        head = fh.read(len(LAYERS_MAGIC) + 4)
        if len(head) < len(LAYERS_MAGIC) + 4 or not head.startswith(LAYERS_MAGIC):
            raise ValueError(f"{bad} (it does not start as one)")
        (n,) = struct.unpack("<I", head[len(LAYERS_MAGIC) :])
        try:
            meta = json.loads(fh.read(n))
            shape = tuple(int(s) for s in meta["shape"])
            ok = meta["version"] == LAYERS_VERSION and meta["codec"] == "zlib" and len(shape) == 3
        except (ValueError, KeyError, TypeError):
            raise ValueError(f"{bad} (its header is damaged)") from None
        if not ok or min(shape) < 1:
            raise ValueError(f"{bad} (version {meta.get('version')}, codec {meta.get('codec')}, shape {shape})")
        fh.seek(max(0, size - 16))
        tail = fh.read(16)
        index = struct.unpack("<Q", tail[:8])[0] if len(tail) == 16 else -1
        count = shape[0] + 1
        if tail[8:] != LAYERS_END or not 0 < index <= size - 16 - count * 8:
            raise ValueError(f"{bad} (its end is missing: a truncated file)")
        fh.seek(index)
        offsets = np.frombuffer(fh.read(count * 8), _U64).astype(np.int64)
        if offsets[-1] != index or np.any(np.diff(offsets) <= 0) or offsets[0] != len(head) + n:
            raise ValueError(f"{bad} (its index is damaged)")
        return shape, offsets

    def __len__(self) -> int:
        return self.shape[0]

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    def layer(self, k: int) -> np.ndarray:
        """Layer ``k`` (Y, X) uint8, read-only."""
        k = int(k) + (self.shape[0] if int(k) < 0 else 0)
        if not 0 <= k < self.shape[0]:
            raise IndexError(f"layer {k} of {self.shape[0]}")
        with self._lock:
            hit = self._cache.get(k)
        if hit is not None:
            return hit
        start, end = int(self.offsets[k]), int(self.offsets[k + 1])
        if self._fh.closed:
            raise ValueError(f"{self.path}: its label layers were closed")
        data = os.pread(self._fh.fileno(), end - start, start)
        size = self.shape[1] * self.shape[2]
        inflate = zlib.decompressobj()
        try:  # inflated at most one byte past the layer's size: a damaged layer never fills the memory
            raw = inflate.decompress(data, size + 1)
        except zlib.error as exc:
            raise ValueError(f"{self.path}: layer {k} is damaged ({exc})") from None
        if len(raw) != size or not inflate.eof:
            raise ValueError(f"{self.path}: layer {k} is damaged (it does not inflate to {size} bytes)")
        lay = np.frombuffer(raw, np.uint8).reshape(self.shape[1:])
        with self._lock:
            if len(self._cache) >= 2:
                self._cache.pop(next(iter(self._cache)))
            self._cache[k] = lay
        return lay

    def __getitem__(self, key):
        if isinstance(key, (int, np.integer)):
            return self.layer(key)
        if isinstance(key, slice):
            ks = range(*key.indices(self.shape[0]))
            out = np.empty((len(ks), *self.shape[1:]), np.uint8)
            for i, k in enumerate(ks):
                out[i] = self.layer(k)
            return out
        if isinstance(key, tuple) and key and isinstance(key[0], (int, np.integer)):
            return self.layer(key[0])[key[1:]]
        raise TypeError(f"label layers are read by layer index or slice of layers, not {key!r}")

    def dense(self) -> np.ndarray:
        """Every layer in one read-only uint8 (Z, Y, X) array (1 byte per voxel)."""
        out = self[:]
        out.flags.writeable = False
        return out

    def __array__(self, dtype=None, copy=None):
        out = self[:]
        return out if dtype is None else out.astype(dtype, copy=False)
