"""Neighbourhood operators over texels for the loss's SSIM and edge terms (docs/method.md §5): the Gaussian window
restricted to texels (``gaussian_window``, a ``WindowOperator`` whose weights are coded by squared distance) and
the 3D Sobel operators (``sobel_operators``). Positions are texel centres in voxel units, (I, 3) float."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

#: texel rows of the window built or applied at a time (``gaussian_window``, ``WindowOperator``: transient memory)
WINDOW_CHUNK_ROWS = 1 << 13


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
        m = cKDTree(pos[s:e]).sparse_distance_matrix(tree, reach, p=np.inf, output_type="ndarray")
        order = np.argsort(m["i"] * n_tex + m["j"])  # by row, then column
        row, col = m["i"][order] + s, m["j"][order]
        del m, order
        if len(row) != indptr[e] - indptr[s]:
            raise RuntimeError("texel window: the neighbour search disagrees with its counts")
        d2 = np.zeros(len(row))
        for a in range(3):
            d = pos[col, a] - pos[row, a]
            d2 += d * d
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
    layers cancel) and the normal-axis operator is 0.
    """
    pos = np.asarray(pos_vox, np.float64)
    n_tex = len(pos)
    pairs = cKDTree(pos).query_pairs(1.0 + tol, p=np.inf, output_type="ndarray")
    off = pos[pairs[:, 1]] - pos[pairs[:, 0]]
    r = np.rint(off)
    keep = np.all(np.abs(off - r) <= tol, axis=1) & np.any(r != 0, axis=1)
    del off
    i, j, r = pairs[keep, 0], pairs[keep, 1], r[keep].astype(np.int8)  # lattice offsets in {-1, 0, 1}
    del pairs, keep
    dtap = np.array([-1.0, 0.0, 1.0])
    stap = np.array([1.0, 2.0, 1.0])
    # one axis's operator at a time, each in canonical CSR form (its coordinate lists, 24 B per entry, are
    # transient per axis, not for all three at once), stacked: the same rows, entries and order as one build
    axes = []
    for a in range(3):
        b, c = [x for x in range(3) if x != a]
        w = dtap[r[:, a] + 1] * stap[r[:, b] + 1] * stap[r[:, c] + 1]  # weight of j in row i; row j gets -w
        nz = w != 0
        wi, ii, jj = w[nz], i[nz], j[nz]
        del w, nz
        centre = -(np.bincount(ii, wi, n_tex) - np.bincount(jj, wi, n_tex))
        rows = np.concatenate([ii, jj, np.arange(n_tex)])
        cols = np.concatenate([jj, ii, np.arange(n_tex)])
        vals = np.concatenate([wi, -wi, centre])
        del wi, ii, jj, centre
        s = sp.coo_matrix((vals, (rows, cols)), shape=(n_tex, n_tex)).tocsr()
        del rows, cols, vals
        s.sum_duplicates()
        s.eliminate_zeros()
        axes.append(s)
    return sp.vstack(axes, format="csr")
