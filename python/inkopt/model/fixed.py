"""Fixed ink shares of a big object without the dense (z, y, x, N) array.

A mesh run fixes 100 % white in every voxel that is not a variable (outside the object, the core below
``--shell-mm``) and, with a translucency constraint, a share of transparent ink in some voxels. As a dense float32
array that is 20 bytes per grid voxel (1.2 GB for a 40 mm figurine), almost all of it one repeated row.
:class:`FixedShares` keeps the same shares as a ``free`` mask (the voxels without a fixed share; a bit per voxel,
:class:`PackedMask`), the one row the others hold, and the rows of the few voxels that differ (``index``,
``rows``). It behaves as the dense array where one is needed (``np.asarray(fixed)``, ``.shape``), and gives rows
(:meth:`at`), planes and the dense bytes' hash without making it. It is the one form of fixed shares: scenes build
it, ``optim.param`` takes it, and a dense array converts with :meth:`from_dense`.
"""

from __future__ import annotations

import numpy as np

from .mask import PackedMask


class FixedShares:
    """Fixed ink shares (z, y, x, N) float32: voxels where the ``free`` mask ((z, y, x) bool, or a ``PackedMask``;
    kept as ``mask``, a bit per voxel) is False hold ``held`` ((N,) float32), those where it is True none, except
    the voxels ``index`` ((K,) int64, strictly increasing flat (z, y, x) indices), which hold ``rows`` ((K, N)
    float32). ``free`` makes the dense mask when asked (1 byte per voxel, a new array)."""

    ndim = 4
    dtype = np.dtype(np.float32)

    def __init__(self, free, held: np.ndarray, index: np.ndarray | None = None, rows: np.ndarray | None = None):
        self.mask = free if isinstance(free, PackedMask) else PackedMask(free)
        self.held = np.asarray(held, np.float32).reshape(-1)
        n = len(self.held)
        self.index = np.zeros(0, np.int64) if index is None else np.asarray(index, np.int64).reshape(-1)
        self.rows = np.zeros((0, n), np.float32) if rows is None else np.asarray(rows, np.float32).reshape(-1, n)
        if len(self.rows) != len(self.index):
            raise ValueError(f"{len(self.index)} indexed voxels but {len(self.rows)} rows")
        if len(self.index) and (
            np.any(np.diff(self.index) <= 0) or self.index[0] < 0 or self.index[-1] >= self.mask.size
        ):
            raise ValueError("fixed-share index must be strictly increasing voxel indices inside the grid")

    @property
    def free(self) -> np.ndarray:
        """(z, y, x) bool: the voxels without a fixed share (unpacked from ``mask``: a new array)."""
        return self.mask.dense()

    @classmethod
    def none(cls, shape, n_inks: int) -> FixedShares:
        """No fixed share anywhere: every voxel of the (z, y, x) grid ``shape`` free, for ``n_inks`` inks."""
        return cls(np.ones(tuple(shape), bool), np.zeros(n_inks, np.float32))

    @classmethod
    def from_dense(cls, dense: np.ndarray) -> FixedShares:
        """The compact form of a dense (z, y, x, N) array (its ``dense()`` equals it bit for bit): voxels whose
        row is all zero are free, the first other voxel's row is ``held`` and the rows that differ from it are
        indexed."""
        dense = np.asarray(dense, np.float32)
        if dense.ndim != 4:
            raise ValueError(f"fixed shares must have shape (z, y, x, N), got {dense.shape}")
        flat = dense.reshape(-1, dense.shape[-1])
        fixed = np.flatnonzero(np.any(flat != 0, axis=1))
        held = flat[fixed[0]] if len(fixed) else np.zeros(dense.shape[-1], np.float32)
        index = fixed[np.any(flat[fixed] != held, axis=1)]
        return cls(np.all(dense == 0, axis=-1), held, index, flat[index])

    @property
    def shape(self) -> tuple:
        return self.mask.shape + (len(self.held),)

    def at(self, index: np.ndarray) -> np.ndarray:
        """(K, N) float32: the shares of the voxels ``index`` ((K,) flat indices), as the dense array holds them."""
        index = np.asarray(index, np.int64)
        out = np.where(self.mask.at(index)[:, None], np.float32(0), self.held[None, :]).astype(np.float32)
        if len(self.index):
            pos = np.searchsorted(self.index, index).clip(0, len(self.index) - 1)
            hit = self.index[pos] == index
            out[hit] = self.rows[pos[hit]]
        return out

    def plane(self, z: int) -> np.ndarray:
        """(y, x, N) float32: layer z of the dense array."""
        ny, nx = self.mask.shape[1:]
        return self.at(np.arange(z * ny * nx, (z + 1) * ny * nx, dtype=np.int64)).reshape(ny, nx, -1)

    def dense(self) -> np.ndarray:
        """The dense (z, y, x, N) float32 array (20 bytes per voxel for 5 inks: for small objects and outputs)."""
        out = np.zeros(self.shape, np.float32)
        out[~self.free] = self.held
        out.reshape(-1, self.shape[-1])[self.index] = self.rows
        return out

    def __array__(self, dtype=None, copy=None):
        out = self.dense()
        return out if dtype is None else out.astype(dtype, copy=False)

    def digest(self, h) -> None:
        """Feed the dense array's bytes (C order) to the hash ``h``, one layer at a time."""
        for z in range(self.mask.shape[0]):
            h.update(np.ascontiguousarray(self.plane(z)).data)


#: the named core mixtures of a mesh below its band of free voxels (``core_shares``): "white" 100 % white; "start"
#: the optimiser's white start (``START_WHITE`` white, the rest split evenly over the other inks)
CORE_NAMES = ("white", "start")
#: a mesh's core when none is given
DEFAULT_CORE = "white"
#: the white share of the optimiser's white start (``init`` white) and of the "start" core
START_WHITE = 0.97


def parse_core(core: str) -> dict[str, float] | None:
    """The explicit shares {ink name: share} of a core "ink=share,ink=share,..." (each ink once, shares >= 0
    summing to 1 within 1e-3, renormalised), or None for a name of ``CORE_NAMES``. One-line ParameterError naming
    `core` otherwise. The names are checked against an ink set by ``core_shares``."""
    from ..errors import ParameterError

    if core in CORE_NAMES:
        return None
    shares: dict[str, float] = {}
    for item in str(core).split(","):
        name, eq, value = (v.strip() for v in item.partition("="))
        try:
            share = float(value) if eq else float("nan")
        except ValueError:
            share = float("nan")
        if not name or name in shares or not (np.isfinite(share) and share >= 0):
            raise ParameterError(
                f"`core` must be one of {list(CORE_NAMES)} or ink shares like white=0.9,black=0.1 (each ink once, "
                f"shares >= 0), got {core!r}"
            )
        shares[name] = share
    total = sum(shares.values())
    if abs(total - 1.0) > 1e-3:
        raise ParameterError(f"`core` shares must sum to 1, got {total:.6g} in {core!r}")
    return {k: v / total for k, v in shares.items()}


def core_shares(core: str, inks) -> np.ndarray:
    """(N,) float32: the ink shares of the core ``core`` (``parse_core``) for the ink set ``inks`` (an
    ``InkTable``): "white" 100 % white, "start" the optimiser's white start, or the explicit shares (unnamed inks
    0). One-line ParameterError naming `core` for an ink the set does not hold (or no white for a named core)."""
    from ..errors import ParameterError

    names = list(inks.names)
    shares = parse_core(core)
    out = np.zeros(len(names), np.float64)
    if shares is None:
        if "white" not in names:
            raise ParameterError(f"`core` {core} needs a 'white' ink, but the ink set {names} has none")
        if core == "start" and len(names) > 1:
            out[:] = (1.0 - START_WHITE) / (len(names) - 1)
        out[names.index("white")] = START_WHITE if core == "start" and len(names) > 1 else 1.0
        return out.astype(np.float32)
    for name, share in shares.items():
        if name not in names:
            raise ParameterError(f"`core` names ink {name!r}, not in the ink set {names}")
        out[names.index(name)] = share
    return out.astype(np.float32)
