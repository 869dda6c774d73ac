"""Constraints of an optimisation as fixed ink shares (``FixedShares``): what the optimiser may not change.

- The white core: every voxel that is not a variable (outside the object, the core below ``--shell-mm``) holds
  100 % white (:func:`white_fixed_shares`).
- Translucent regions: some voxels must hold a share of the ink set's transparent ink (:func:`transparent_ink`),
  the optimiser choosing the rest of their mixture (:class:`Translucency`, stored sparsely in scene.npz).

:func:`scene_fixed_shares` combines the two from what a scene record stores (the free mask and the translucency),
so every stage that rebuilds a run's constraints (optimisation, evaluation, baselines) gets the same shares.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from .fixed import FixedShares
from .inks import InkTable
from .texels import Texels

#: ink names that count as the transparent ink, in the order they are looked for
TRANSPARENT_INKS = ("transparent", "clear")


def white_fixed_shares(free: np.ndarray, inks: InkTable) -> FixedShares:
    """Fixed ink shares (z, y, x, N): 100 % white where ``free`` ((z, y, x) bool, kept by reference) is False,
    none where True. One-line ValueError if the ink set has no white."""
    if "white" not in inks.names:
        raise ParameterError(
            f"voxels that are not optimised (outside the object, the core below `shell_mm`) are "
            f"printed white, but the ink set {list(inks.names)} has no 'white'"
        )
    held = np.zeros(len(inks), np.float32)
    held[inks.index("white")] = 1.0
    return FixedShares(free, held)


def transparent_ink(inks: InkTable) -> str:
    """The name of the ink set's transparent ink; one-line ValueError if it has none."""
    for name in TRANSPARENT_INKS:
        if name in inks.names:
            return name
    raise ParameterError(
        f"`translucency` needs a transparent ink ('transparent' or 'clear') in the ink set, but "
        f"{list(inks.names)} has none; use e.g. `inks` vero-cmykwt"
    )


@dataclass
class Translucency:
    """A translucency constraint: the voxels ``index`` ((K,) int64, flat C-order indices of the (z, y, x) grid
    ``shape``) must hold the share ``share`` ((K,) float32 in (0, 1]) of ink ``ink`` (the transparent ink); the
    optimiser chooses the rest of their mixture. ``depth_mm``: how deep below the surface it reaches (None: the
    whole object); ``source``: the mask file or "alpha" (a mesh texture's alpha channel)."""

    ink: str
    shape: tuple
    index: np.ndarray
    share: np.ndarray
    depth_mm: float | None = None
    source: str = ""

    def __post_init__(self):
        self.shape = tuple(int(v) for v in self.shape)
        self.index = np.asarray(self.index, np.int64).reshape(-1)
        self.share = np.asarray(self.share, np.float32).reshape(-1)

    def grid(self) -> np.ndarray:
        """(z, y, x) float32: the required transparent share of every voxel (0: unconstrained)."""
        out = np.zeros(self.shape, np.float32)
        out.reshape(-1)[self.index] = self.share
        return out

    def texel_share(self, texels: Texels) -> np.ndarray:
        """(I,) float32: the required share at each texel's voxel."""
        return self.grid()[tuple(np.asarray(texels.voxel).T)]

    def applied(self, fixed: FixedShares, inks: InkTable) -> FixedShares:
        """New fixed shares: ``fixed`` with the constrained voxels' transparent share set. Their other fixed
        shares (the white of a core or outside voxel) shrink to make room: a voxel that was 100 % white becomes
        ``share`` transparent + (1 - ``share``) white; free voxels keep no other fixed share. Idempotent."""
        if tuple(fixed.shape[:3]) != self.shape:
            raise ValueError(f"translucency constraint is for a {self.shape} grid, not {tuple(fixed.shape[:3])}")
        if self.ink not in inks.names:
            raise ValueError(f"the translucency constraint needs ink '{self.ink}', not in {list(inks.names)}")
        index = np.union1d(fixed.index, self.index)
        rows = fixed.at(index)
        pos = np.searchsorted(index, self.index)
        rows[pos] = self._constrain(rows[pos], inks)
        return FixedShares(fixed.mask, fixed.held, index, rows)

    def _constrain(self, rows: np.ndarray, inks: InkTable) -> np.ndarray:
        """The constrained voxels' fixed shares (K, N) float32 from their unconstrained ones (changed in place)."""
        t = inks.index(self.ink)
        rows[:, t] = 0.0
        other = rows.sum(1)
        room = 1.0 - self.share
        rows *= np.where(other > room, room / np.maximum(other, 1e-12), 1.0)[:, None]
        rows[:, t] = self.share
        return rows

    def arrays(self) -> dict:
        """Its arrays in scene.npz (``translucency_*``)."""
        return {
            "translucency_ink": np.array(self.ink),
            "translucency_shape": np.array(self.shape, np.int64),
            "translucency_index": self.index,
            "translucency_share": self.share,
            "translucency_depth_mm": np.float64(np.nan if self.depth_mm is None else self.depth_mm),
            "translucency_source": np.array(self.source),
        }

    @classmethod
    def from_arrays(cls, d) -> Translucency | None:
        """The constraint stored in ``d`` (the arrays of scene.npz), or None if it stores none."""
        if "translucency_index" not in d:
            return None
        depth = float(d["translucency_depth_mm"])
        return cls(
            str(d["translucency_ink"]),
            tuple(np.asarray(d["translucency_shape"])),
            d["translucency_index"],
            d["translucency_share"],
            None if np.isnan(depth) else depth,
            str(d["translucency_source"]),
        )


def scene_fixed_shares(
    inks: InkTable,
    free: np.ndarray | None = None,
    translucency: Translucency | None = None,
    core: np.ndarray | None = None,
) -> FixedShares | None:
    """A scene's fixed shares from its free mask ((z, y, x) bool: the core's shares ``core`` ((N,) float32; None:
    100 % white) wherever it is False; None: no core) and its translucency constraint (or None); None if it has
    neither."""
    if free is not None:
        fixed = white_fixed_shares(free, inks) if core is None else FixedShares(free, core)
    elif translucency is not None:
        fixed = FixedShares.none(translucency.shape, len(inks))
    else:
        return None
    return fixed if translucency is None else translucency.applied(fixed, inks)
