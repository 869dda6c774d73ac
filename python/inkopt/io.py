"""Atomic file output: every file inkopt writes appears whole or not at all (temporary file in the same folder,
then an atomic rename), so an interrupted run never leaves a half-written result behind."""
from __future__ import annotations

import io
import json
import os
import tempfile
from pathlib import Path

import numpy as np


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save_npz(path: str | Path, arrays: dict, compressed: bool = True) -> None:
    """Write an .npz atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp.npz", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            (np.savez_compressed if compressed else np.savez)(fh, **arrays)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def load_npz(path: str | Path, what: str = "file") -> dict:
    """All arrays of an .npz as a dict; a missing or unreadable file is a one-line ValueError."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{what} {path} does not exist")
    try:
        with np.load(path, allow_pickle=False) as z:
            return dict(z)
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
