"""Scenes: what the user gives (pictures and a size, or a textured mesh) turned into what the optimiser needs.

A scene (``Scene`` protocol) holds the base ``volume`` (a mixture or label Volume: grid geometry and ink table;
its medium is not the optimiser's), the ``texels`` (the sensor), ``target_rgb`` (I, 3) float32 linear, and
``fixed_share`` (the (z, y, x, N) ink shares the optimiser may not change, a ``model.FixedShares``, or None).
It knows how to store itself (``record()`` -> the run directory's ``SceneRecord``), what to tell the user and
the report, and which pictures show a prediction of it. The run driver (``inkopt.run``) needs nothing else, so a
new kind of scene is a new module here plus its settings in ``optim.config.SCENE_DEFAULTS`` (the optimiser
settings it leaves to the kind).
A scene is made from the user's inputs through its spec (``spec.SlabSpec``, ``spec.MeshSpec``):
``build_scene(spec, inks)``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

import numpy as np

from ..model import FixedShares, InkTable, Texels, Volume
from ..rundir import RunDir, SceneRecord
from .spec import SceneSpec


class Scene(Protocol):
    kind: str
    volume: Volume
    texels: Texels
    target_rgb: np.ndarray
    fixed_share: FixedShares | None

    def record(self) -> SceneRecord:
        """What scene.npz stores: enough for evaluation and baselines to see the same constraints."""

    def describe(self) -> str:
        """One line for the log: where the target colour comes from, grid, voxel size, texels."""

    @property
    def warnings(self) -> list[str]:
        """One-line notes about the inputs that the run logs after ``describe()`` (e.g. a mesh's small holes)."""

    def report_fields(self) -> dict:
        """The scene's own entries of report.json (sizes, paths)."""

    def write_pictures(self, out: RunDir, pred_rgb: np.ndarray, delta_e: np.ndarray) -> list[Path]:
        """Pictures of a prediction (I, 3) linear with per-texel ΔE76 (I,) in run directory ``out``."""


def build_scene(spec: SceneSpec, inks: InkTable) -> Scene:
    """The scene of ``spec``'s inputs for ink set ``inks``: the spec is checked first (``spec.validate(inks)``:
    one-line errors before anything slow), then built by its kind's builder (a mesh is loaded and voxelized)."""
    spec.validate(inks)
    if spec.kind == "mesh":
        from .mesh import build_mesh_scene  # the mesh modules only when a mesh is given

        return build_mesh_scene(spec, inks)
    from .slab import build_slab_scene

    return build_slab_scene(spec, inks)
