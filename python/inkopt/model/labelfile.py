"""Printer label stacks too big to hold twice: an uncompressed ``.npy`` file (uint8 (Z, Y, X), C order) written
one layer at a time and read back memory-mapped (docs/run-dir.md: ``quantized_labels.npy``).

``LabelFileWriter`` writes the .npy header and then each layer with an ordinary sequential ``write`` into a
temporary sibling file (``io.temporary_file``; so the written pages stay in the page cache, not in the process's
memory, unlike a writable memory map), counting the labels and hashing the file's bytes on the way (``digest``,
equal to ``io.file_digest`` of the file, without reading it back); ``commit`` renames it into place atomically.
``load_label_file`` maps it read-only (``numpy.load(mmap_mode="r")``): pages are read when touched.
"""

from __future__ import annotations

import hashlib
import io
import os
from pathlib import Path

import numpy as np

from ..io import publish, temporary_file


class LabelFileWriter:
    """``w = LabelFileWriter(path, (Z, Y, X)); w[0] = layer0; w[1] = ...; w.commit()`` (or ``w.abort()``).

    Layers must come in order 0, 1, ..., Z - 1; ``counts`` (256,) int64 counts every label value written;
    ``digest``: ``"sha256:<hex>"`` of the file's bytes (header and every layer written so far)."""

    def __init__(self, path, shape):
        self.path = Path(path)
        self.shape = tuple(int(s) for s in shape)
        if len(self.shape) != 3 or min(self.shape) < 1:
            raise ValueError(f"a label stack needs 3 positive sizes (Z, Y, X), got {self.shape}")
        fd, self._tmp = temporary_file(self.path, ".tmp.npy")
        self._fh = os.fdopen(fd, "wb")
        self._hash = hashlib.sha256()
        header = io.BytesIO()
        np.lib.format.write_array_header_1_0(header, {"descr": "|u1", "fortran_order": False, "shape": self.shape})
        self._write(header.getvalue())
        self.next = 0
        self.counts = np.zeros(256, np.int64)

    def __setitem__(self, k: int, layer) -> None:
        if int(k) != self.next or self.next >= self.shape[0]:
            raise ValueError(f"label layers must be written in order: expected layer {self.next}, got {k}")
        lay = np.ascontiguousarray(layer, np.uint8)
        if lay.shape != self.shape[1:]:
            raise ValueError(f"label layer {k} has shape {lay.shape}, expected {self.shape[1:]}")
        self._write(memoryview(lay).cast("B"))
        self.counts += np.bincount(lay.ravel(), minlength=256)
        self.next += 1

    def _write(self, data) -> None:
        self._fh.write(data)
        self._hash.update(data)

    @property
    def digest(self) -> str:
        return "sha256:" + self._hash.hexdigest()

    def commit(self) -> Path:
        if self.next != self.shape[0]:
            self.abort()
            raise ValueError(f"label stack incomplete: {self.next} of {self.shape[0]} layers written")
        self._fh.close()
        publish(self._tmp, self.path)
        return self.path

    def abort(self) -> None:
        self._fh.close()
        self._tmp.unlink(missing_ok=True)


def load_label_file(path, shape=None) -> np.ndarray:
    """The labels of a label stack file, memory-mapped read-only (uint8 (Z, Y, X)); ``shape`` checks it.
    A missing or malformed file is a one-line ValueError."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"label file {path} does not exist (a quantized.npz needs its labels file beside it)")
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
