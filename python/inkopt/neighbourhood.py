"""Neighbourhood operators over texels for the loss's SSIM and edge terms (docs/method.md §5): the Gaussian window
restricted to texels (``gaussian_window``, a ``WindowOperator`` whose weights are coded by squared distance), the 3D
Sobel operators (``sobel_operators``), and both applied a block of texel rows at a time without being held
(``TexelNeighbours``). Positions are texel centres in voxel units, (I, 3) float."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

#: texel rows of the window built or applied at a time (``gaussian_window``, ``WindowOperator``: transient memory)
WINDOW_CHUNK_ROWS = 1 << 13
#: texel rows whose neighbours are found and applied at a time (``TexelNeighbours``, ``sobel_operators``): ~20 MiB of
#: transient pairs at 2048 rows (~73 MiB at 8192), and no slower at Spot 40 mm (5.3-5.7 against 6.0-6.1 CPU s)
NEIGHBOUR_BLOCK_ROWS = 1 << 11


class WindowOperator:
    """The texel window's weights K (I, I) float64, stored as CSR structure (``indptr`` (I + 1,), ``indices``, int32
    or int64, columns sorted in each row) and per entry a ``code`` (uint8 or uint16) into ``values`` (float64): a
    window weight depends only on the squared distance, which takes few distinct values on the voxel lattice, so K
    takes 5-6 bytes per entry instead of 12 and K squared (``squared``: the same codes into ``values`` squared)
    none of its own. ``codes`` None: ``values`` holds one weight per entry (positions off any lattice).

    ``K @ x`` (x (I,) or (I, k)) and ``row_sums`` are computed ``WINDOW_CHUNK_ROWS`` rows at a time, each row as a
    CSR matrix with these entries computes it (``csr_matvec(s)``, ``np.add.reduceat``), so results are bit-identical
    to ``tocsr()``'s."""

    def __init__(self, indptr: np.ndarray, indices: np.ndarray, codes: np.ndarray | None, values: np.ndarray):
        self.indptr, self.indices, self.codes, self.values = indptr, indices, codes, values
        n = len(indptr) - 1
        self.shape = (n, n)

    @property
    def nnz(self) -> int:
        return int(self.indptr[-1])

    @property
    def squared(self) -> WindowOperator:
        """K squared entrywise (the noise of windowed statistics): the same structure, no copy of it."""
        return WindowOperator(self.indptr, self.indices, self.codes, self.values * self.values)

    def _rows(self, s: int, e: int) -> sp.csr_matrix:
        """Rows s:e as a CSR matrix (e - s, I)."""
        a, b = int(self.indptr[s]), int(self.indptr[e])
        data = self.values[a:b] if self.codes is None else self.values[self.codes[a:b]]
        return sp.csr_matrix((data, self.indices[a:b], self.indptr[s : e + 1] - a), shape=(e - s, self.shape[1]))

    def __matmul__(self, x) -> np.ndarray:
        x = np.asarray(x)
        out = np.empty((self.shape[0], *x.shape[1:]), np.result_type(x.dtype, np.float64))
        for s in range(0, self.shape[0], WINDOW_CHUNK_ROWS):
            e = min(self.shape[0], s + WINDOW_CHUNK_ROWS)
            out[s:e] = self._rows(s, e) @ x
        return out

    def row_sums(self) -> np.ndarray:
        """(I,) float64 K @ 1, summed as ``csr_matrix.sum(axis=1)`` sums (every row has its diagonal entry)."""
        out = np.empty(self.shape[0])
        for s in range(0, self.shape[0], WINDOW_CHUNK_ROWS):
            e = min(self.shape[0], s + WINDOW_CHUNK_ROWS)
            rows = self._rows(s, e)
            out[s:e] = np.add.reduceat(rows.data, rows.indptr[:-1])
        return out

    def tocsr(self) -> sp.csr_matrix:
        """The whole of K as a CSR matrix (small problems, tests)."""
        return self._rows(0, self.shape[0])

    def toarray(self) -> np.ndarray:
        return self.tocsr().toarray()


class _Codes:
    """Codes of float64 values into a table that grows as new values come (``table``: in the order they came)."""

    def __init__(self):
        self.values = np.empty(0)  # the table
        self._keys, self._code = np.empty(0), np.empty(0, np.int64)  # the table sorted, and each key's code

    def of(self, x: np.ndarray) -> np.ndarray:
        """(len(x),) int64 codes of the values ``x`` (new ones added to the table)."""
        at = np.searchsorted(self._keys, x)
        known = at < len(self._keys)
        known[known] = self._keys[at[known]] == x[known]
        if not known.all():
            self.values = np.concatenate([self.values, np.unique(x[~known])])
            order = np.argsort(self.values, kind="stable")
            self._keys, self._code = self.values[order], order
            at = np.searchsorted(self._keys, x)
        return self._code[at]


def gaussian_window(pos_vox: np.ndarray, sigma: float):
    """Texel Gaussian window W = diag(1/n) K.

    K (I, I) (``WindowOperator``) is symmetric with K_ij = exp(-|p_i - p_j|^2 / (2 sigma^2)) for texels whose
    Chebyshev distance is <= radius = int(3.5 sigma + 0.5) (voxels), n (I,) = K @ 1 the window weight that falls on
    texels. On a flat face's interior W equals scikit-image's (truncate=3.5) Gaussian window. Returns (K, n, radius).
    K is written into its final arrays ``WINDOW_CHUNK_ROWS`` rows at a time (columns sorted within each row), so
    building it takes little more than K itself (~5 bytes per entry, ~120 entries per texel on a face, while it is
    built too).
    """
    pos = np.asarray(pos_vox, np.float64)
    radius = int(3.5 * sigma + 0.5)
    n_tex = len(pos)
    reach = radius + 1e-6
    tree = cKDTree(pos)
    pairs = tree.query_pairs(reach, p=np.inf, output_type="ndarray")  # (i < j) pairs: each row's entry count
    counts = np.bincount(pairs[:, 0], minlength=n_tex) + np.bincount(pairs[:, 1], minlength=n_tex) + 1
    del pairs
    idx = np.int32 if int(counts.sum()) < np.iinfo(np.int32).max else np.int64
    indptr = np.zeros(n_tex + 1, idx)
    np.cumsum(counts, out=indptr[1:])
    del counts
    indices = np.empty(int(indptr[-1]), idx)
    # codes in the narrowest type that holds the table so far (uint8 on the lattice: 5 B per entry while K is
    # built instead of 8), widened if the table outgrows it
    codes, table = np.empty(int(indptr[-1]), np.uint8), _Codes()
    for s in range(0, n_tex, WINDOW_CHUNK_ROWS):
        e = min(n_tex, s + WINDOW_CHUNK_ROWS)
        row, col, _ = _block_pairs(pos, tree, s, e, reach)
        if len(row) != indptr[e] - indptr[s]:
            raise RuntimeError("texel window: the neighbour search disagrees with its counts")
        d2 = _squared_distances(pos, row, col)
        indices[indptr[s] : indptr[e]] = col
        chunk = table.of(d2)
        if len(table.values) > np.iinfo(codes.dtype).max + 1:
            codes = codes.astype(np.uint16 if len(table.values) <= 1 << 16 else np.uint32)
        codes[indptr[s] : indptr[e]] = chunk
    values = np.exp(table.values * (-0.5 / (sigma * sigma)))
    if codes.dtype == np.uint32:  # positions off any lattice: one weight per entry
        codes, values = None, values[codes]
    k = WindowOperator(indptr, indices, codes, values)
    return k, k.row_sums(), radius


def sobel_operators(pos_vox: np.ndarray, tol: float = 1e-6) -> sp.csr_matrix:
    """Stacked 3D Sobel operators S = [S_x; S_y; S_z], shape (3I, I) CSR float64 (row a*I + i: axis a, texel i).

    The kernel of axis a at integer offset o in {-1,0,1}^3 is d(o_a) s(o_b) s(o_c) with d = (-1, 0, 1),
    s = (1, 2, 1). Neighbours are texels at exactly that lattice offset (within ``tol``); texels across a box
    edge (offsets of 0.5) are not neighbours. Border handling ("replicate the centre"): the kernel weight of a
    missing neighbour goes to the centre texel, so each row sums to 0 (a constant field has no edges). On a
    flat face's interior, the in-plane operators equal 2x the 2D Sobel operator (the two missing out-of-plane
    layers cancel) and the normal-axis operator is 0. Built ``WINDOW_CHUNK_ROWS`` rows at a time
    (``NEIGHBOUR_BLOCK_ROWS``; ``_sobel_block``: the rows ``TexelNeighbours`` applies), each axis's rows in
    canonical CSR form (columns sorted, no zeros), then stacked.
    """
    pos = np.asarray(pos_vox, np.float64)
    n_tex = len(pos)
    tree = cKDTree(pos)
    axes: list[list[sp.csr_matrix]] = [[], [], []]
    for s in range(0, n_tex, NEIGHBOUR_BLOCK_ROWS):
        e = min(n_tex, s + NEIGHBOUR_BLOCK_ROWS)
        for a, rows in enumerate(_sobel_block(pos, *_block_pairs(pos, tree, s, e, 1.0 + tol), s, e, tol)):
            axes[a].append(rows)
    return sp.vstack([m for a in axes for m in a], format="csr")


_DTAP = np.array([-1.0, 0.0, 1.0])  # the Sobel kernel's derivative taps at offsets -1, 0, 1
_STAP = np.array([1.0, 2.0, 1.0])  # and its smoothing taps


def _block_pairs(pos: np.ndarray, tree: cKDTree, s: int, e: int, reach: float):
    """(row, col, dist) of texel rows s:e and their neighbours within Chebyshev distance ``reach`` (each row's
    texel included), int64, int64, float64 (the k-d tree's distance), sorted by row, then column."""
    m = cKDTree(pos[s:e]).sparse_distance_matrix(tree, reach, p=np.inf, output_type="ndarray")
    order = np.argsort(m["i"] * len(pos) + m["j"])  # by row, then column
    return m["i"][order] + s, m["j"][order], m["v"][order]


def _squared_distances(pos: np.ndarray, row: np.ndarray, col: np.ndarray) -> np.ndarray:
    """(len(row),) float64 |pos[col] - pos[row]|^2, summed over x, y, z in that order."""
    d2 = np.zeros(len(row))
    for a in range(3):
        d = pos[col, a] - pos[row, a]
        d2 += d * d
    return d2


def _sobel_block(pos, row, col, dist, s: int, e: int, tol: float) -> list[sp.csr_matrix]:
    """Rows s:e of the three axes' Sobel operators (``sobel_operators``), each (e - s, I) CSR float64 in canonical
    form, from the rows' neighbour pairs (``_block_pairs`` within any reach >= 1 + ``tol``). The weights are small
    integers (products of -1, 0, 1 and 1, 2, 1) and so is the centre's (minus the row's other weights): exact in
    any order of summation."""
    n_tex = len(pos)
    near = dist <= 1.0 + tol
    i, j = row[near], col[near]
    off = pos[j] - pos[i]
    r = np.rint(off)
    keep = np.all(np.abs(off - r) <= tol, axis=1) & np.any(r != 0, axis=1)
    del off
    i, j, r = i[keep] - s, j[keep], r[keep].astype(np.int8)  # lattice offsets in {-1, 0, 1}
    out = []
    for a in range(3):
        b, c = [x for x in range(3) if x != a]
        w = _DTAP[r[:, a] + 1] * _STAP[r[:, b] + 1] * _STAP[r[:, c] + 1]  # weight of texel j in row i
        nz = w != 0
        centre = -np.bincount(i[nz], w[nz], e - s)
        rows = np.concatenate([i[nz], np.arange(e - s)])
        cols = np.concatenate([j[nz], np.arange(s, e)])
        m = sp.coo_matrix((np.concatenate([w[nz], centre]), (rows, cols)), shape=(e - s, n_tex)).tocsr()
        m.sum_duplicates()
        m.eliminate_zeros()
        out.append(m)
    return out


class TexelNeighbours:
    """The texel window K and its square (``gaussian_window``) and the Sobel operators S (``sobel_operators``)
    applied from the built operators while they are held (``window``, ``sobel``: built and held on first use,
    ``release``), else without holding them: ``blocks`` then finds ``NEIGHBOUR_BLOCK_ROWS`` rows at a time with a
    k-d tree (``_block_pairs``, one search for both) and applies them. The rows are those of the built operators,
    entry for entry in the same order with the same weights (``gaussian_window``'s are exp(-d^2 / 2 sigma^2) of the
    same squared distances), so every product is bit-identical either way. Found, it holds the positions' k-d tree
    while it works (~50 B per texel) and a block's rows (~20 MiB at 2048 rows), not ~0.8 KB per texel.

    pos_vox (I, 3) texel positions in voxel units; sigma the window's standard deviation (voxels); tol the Sobel
    operators' lattice tolerance."""

    def __init__(self, pos_vox: np.ndarray, sigma: float, tol: float = 1e-6):
        self.pos = np.asarray(pos_vox, np.float64)
        self.sigma, self.tol = float(sigma), float(tol)
        #: the window's Chebyshev radius in voxels (``gaussian_window``)
        self.radius = int(3.5 * self.sigma + 0.5)
        self._k = self._k2 = self._s = self._st = None  # the held operators

    @property
    def held(self) -> bool:
        """Whether any operator is held."""
        return any(x is not None for x in (self._k, self._k2, self._s, self._st))

    def window(self) -> WindowOperator:
        """K (I, I) (``gaussian_window``), built and held on first use."""
        if self._k is None:
            self._k = gaussian_window(self.pos, self.sigma)[0]
        return self._k

    def window_sq(self) -> WindowOperator:
        """K squared entrywise (``WindowOperator.squared``), held with K."""
        if self._k2 is None:
            self._k2 = self.window().squared
        return self._k2

    def sobel(self) -> sp.csr_matrix:
        """S (3I, I) CSR float64 (``sobel_operators``), built and held on first use."""
        if self._s is None:
            self._s = sobel_operators(self.pos, self.tol)
        return self._s

    def sobel_t(self) -> sp.csr_matrix:
        """S transposed (I, 3I) CSR, built and held on first use."""
        if self._st is None:
            self._st = self.sobel().T.tocsr()
        return self._st

    def release(self) -> None:
        """Free the held operators: later products find their rows a block at a time (the same bits)."""
        self._k = self._k2 = self._s = self._st = None

    def blocks(self, window=None, window_sq=None, sobel=None, wsum: bool = False):
        """Yields (s, e, K @ window, K^2 @ window_sq, S @ sobel, n) of texel rows s:e, blocks in order covering
        every texel: ``window`` (I, a), ``window_sq`` (I, b), ``sobel`` (I, c) float arrays or None; a block's
        results (e - s, a), (e - s, b) float64 and a tuple of three (e - s, c) (S's rows of axes x, y, z), None
        where not asked; n (e - s,) the window's row sums K @ 1 (``gaussian_window``'s) if ``wsum``, else None.
        Held operators give their products whole (one block when all asked are held); the others are found."""
        n_tex = len(self.pos)
        held_k, held_s = self._k is not None, self._s is not None
        whole = [None] * 4  # the held operators' products, every row
        if held_k:
            whole[0] = None if window is None else self._k @ window
            whole[1] = None if window_sq is None else self.window_sq() @ window_sq
            whole[3] = self._k.row_sums() if wsum else None
        if held_s and sobel is not None:
            whole[2] = self._s @ sobel
        find = (None, None) if held_k else (window, window_sq)
        find += (None if held_s else sobel, wsum and not held_k)
        if any(x is not None for x in find[:3]) or find[3]:
            found = self._found(*find)
        else:
            found = [(0, n_tex, None, None, None, None)]
        for s, e, *got in found:
            for i, w in enumerate(whole):
                if w is not None:
                    got[i] = tuple(w[a * n_tex + s : a * n_tex + e] for a in range(3)) if i == 2 else w[s:e]
            yield s, e, *got

    def _found(self, window, window_sq, sobel, wsum: bool):
        """``blocks``'s results, every operator's rows found ``NEIGHBOUR_BLOCK_ROWS`` rows at a time."""
        n_tex = len(self.pos)
        need_k = window is not None or window_sq is not None or wsum
        reach_k = self.radius + 1e-6
        reach = max(reach_k if need_k else 0.0, 1.0 + self.tol if sobel is not None else 0.0)
        tree = cKDTree(self.pos)
        for s in range(0, n_tex, NEIGHBOUR_BLOCK_ROWS):
            e = min(n_tex, s + NEIGHBOUR_BLOCK_ROWS)
            row, col, dist = _block_pairs(self.pos, tree, s, e, reach)
            sx = None
            if sobel is not None:
                sx = tuple(rows @ sobel for rows in _sobel_block(self.pos, row, col, dist, s, e, self.tol))
            k = (None,) * 3
            if need_k:
                if reach > reach_k:  # a window narrower than the Sobel operators' reach
                    row, col = row[dist <= reach_k], col[dist <= reach_k]
                k = self._window_block(row, col, s, e, window, window_sq, wsum)
            del row, col, dist
            yield s, e, k[0], k[1], sx, k[2]

    def products(self, window=None, window_sq=None, sobel=None, wsum: bool = False) -> tuple:
        """(K @ window, K^2 @ window_sq, S @ sobel, n) of every texel (``blocks``): (I, a), (I, b), (3I, c) float64
        (row a*I + i of S's: axis a, texel i), (I,) or None where not asked."""
        n_tex = len(self.pos)
        out = [None if x is None else np.empty((n_tex, x.shape[1])) for x in (window, window_sq)]
        out += [None if sobel is None else np.empty((3 * n_tex, sobel.shape[1])), np.empty(n_tex) if wsum else None]
        for s, e, k, k2, sx, n in self.blocks(window, window_sq, sobel, wsum):
            for o, g in ((out[0], k), (out[1], k2), (out[3], n)):
                if o is not None:
                    o[s:e] = g
            for a in range(3) if sx is not None else ():
                out[2][a * n_tex + s : a * n_tex + e] = sx[a]
        return tuple(out)

    def _window_block(self, row, col, s: int, e: int, window, window_sq, wsum: bool) -> tuple:
        """(K @ window, K^2 @ window_sq, K @ 1) of rows s:e (None where not asked) from the block's pairs (row, col)
        (``_block_pairs``)."""
        d2 = _squared_distances(self.pos, row, col)
        table, code = np.unique(d2, return_inverse=True)  # few distinct weights on the lattice
        values = np.exp(table * (-0.5 / (self.sigma * self.sigma)))
        indptr = np.zeros(e - s + 1, np.int64)
        np.cumsum(np.bincount(row - s, minlength=e - s), out=indptr[1:])
        rows = sp.csr_matrix((values[code], col, indptr), shape=(e - s, len(self.pos)))
        k = None if window is None else rows @ window
        n = np.add.reduceat(rows.data, rows.indptr[:-1]) if wsum else None
        k2 = None
        if window_sq is not None:
            rows.data = (values * values)[code]
            k2 = rows @ window_sq
        return k, k2, n
