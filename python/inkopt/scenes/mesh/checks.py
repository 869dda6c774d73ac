"""Checks of a mesh scene's inputs that need no mesh loaded: its placement (height or scale, up axis), its shell and
its ink set. ``scenes.spec.MeshSpec.validate`` runs them before anything slow; the loader and the scene builder run
them again on what they are given."""

from __future__ import annotations

import numpy as np

from ...errors import ParameterError
from ...model import InkTable, white_fixed_shares

UP_AXES = ("y", "z")  # the up axes a mesh file may have


def check_placement(height_mm: float | None, scale: float | None, up: str = "y") -> None:
    """One-line ParameterError unless exactly one of ``height_mm`` and ``scale`` is given, it is positive, and
    ``up`` is one of ``UP_AXES``."""
    if (height_mm is None) == (scale is None):
        raise ParameterError(
            "give exactly one of `height_mm` H (the object's height in mm) and `scale` S (mm per model unit)"
        )
    for name, v in (("height_mm", height_mm), ("scale", scale)):
        if v is not None and not (np.isfinite(v) and v > 0):
            raise ParameterError(f"`{name}` must be positive, got {v}")
    if up not in UP_AXES:
        raise ParameterError(f"`up` must be one of {list(UP_AXES)}, got {up!r}")


def check_mesh_inputs(shell_mm: float | None, inks: InkTable | None = None) -> None:
    """One-line errors for a shell that is not a positive thickness (mm) and (with ``inks``) an ink set without
    white for the core, before the slow part."""
    if inks is not None and "white" not in inks.names:
        white_fixed_shares(np.ones((1, 1, 1), bool), inks)  # its one-line error
    if shell_mm is not None and not (np.isfinite(shell_mm) and shell_mm > 0):
        raise ParameterError(f"`shell_mm` must be a positive thickness in mm, got {shell_mm}")
