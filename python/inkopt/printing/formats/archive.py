"""Zip packages (GCVF, 3MF): telling one by a member it must hold, and the check before one is (re)written."""

from __future__ import annotations

import zipfile
from pathlib import Path

from ...io import ZIP_READ_ERRORS, check_output


def zip_holds(path: Path, member: str) -> bool:
    """Whether ``path`` is a readable zip holding ``member``."""
    try:
        with zipfile.ZipFile(path) as zf:
            return member in zf.namelist()
    except (*ZIP_READ_ERRORS, MemoryError):
        return False


def check_target(path: Path, member: str, kind: str, suffix: str) -> None:
    """One-line ValueError unless ``path`` may be written (``io.check_output``): not a folder, and if it exists a
    package of this ``kind`` (a zip holding ``member``), which is replaced; any other file is refused, never
    overwritten."""
    check_output(path, lambda p: zip_holds(p, member), f"a {kind} ({suffix})")
