"""Where a mesh run's object came from and how it sits on the optimisation grid (stored in scene.npz).

It lives in the model, beside ``Volume`` and ``Texels``, because two layers that do not see each other need it:
the mesh scene (``scenes/mesh``) fills it in and the run directory (``rundir.SceneRecord``) stores and reads it;
it is a plain record of the object (file, scale, placement on the grid), like a volume's ``origin_mm``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class MeshInfo:
    """Where a mesh run's object came from and how it sits on the grid (mm, x, y, z)."""

    mesh_path: str
    mesh_scale: float  # mm per model unit
    height_mm: float
    up: str
    origin_mm: np.ndarray  # (3,) low corner of voxel (0, 0, 0)
    voxel_mm: np.ndarray  # (3,)
    texel_closest_mm: np.ndarray  # (I, 3) closest surface point of each texel
    shell_mm: float | None
    core_share: np.ndarray | None = None  # (N,) float32 the core's ink shares (None: 100 % white)

    def arrays(self) -> dict:
        """Its arrays in scene.npz."""
        return {
            "mesh_path": np.array(self.mesh_path),
            "mesh_scale": np.float64(self.mesh_scale),
            "height_mm": np.float64(self.height_mm),
            "up": np.array(self.up),
            "origin_mm": self.origin_mm,
            "voxel_mm": self.voxel_mm,
            "texel_closest_mm": self.texel_closest_mm,
            "shell_mm": np.float64(np.nan if self.shell_mm is None else self.shell_mm),
            **({} if self.core_share is None else {"core_share": np.asarray(self.core_share, np.float32)}),
        }

    @classmethod
    def from_arrays(cls, d) -> MeshInfo:
        """From the arrays of scene.npz (all of :meth:`arrays`' keys)."""
        shell = float(d["shell_mm"])
        return cls(
            str(d["mesh_path"]),
            float(d["mesh_scale"]),
            float(d["height_mm"]),
            str(d["up"]),
            np.asarray(d["origin_mm"]),
            np.asarray(d["voxel_mm"]),
            np.asarray(d["texel_closest_mm"]),
            None if np.isnan(shell) else shell,
            np.asarray(d["core_share"], np.float32) if "core_share" in d else None,
        )
