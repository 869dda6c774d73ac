"""The perceptual loss E(C, T) over texels (docs/method.md §5) with analytic gradients.

Predictions and targets are linear RGB (I, 3) per texel; the terms are computed in CIELAB (``inkopt.color``):
E1 mean ΔE76², E2 texel SSIM on normalised L*a*b* with a Gaussian window restricted to texels, E3 3D Sobel on
normalised L*a*b*.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from .color import LAB_NORM_SCALE, linear_to_lab, linear_to_lab_jacobian, linear_to_lab_vjp, normalise_lab

K1 = 0.01**2
K2 = 0.03**2
# E1 enters the combined loss in units of (dE/100)^2: that puts it in the range of E2 and E3 (E3's factor 100 is
# chosen for the same range, docs/method.md §5), so the paper's weight recommendations (g2 in [3, 9], g3 <= 3) apply.
# The reported e1 stays the mean dE76^2.
E1_WEIGHT_SCALE = 1e-4
# A texel is "flat" when the target's windowed standard deviation of L* is below FLAT_L_STD and that of its chroma,
# sqrt(var a* + var b*), below FLAT_CHROMA_STD (about the 8-bit quantization of a flat picture region): where the
# mottle figure (``evaluation.metrics``) looks and the optimiser's step smoothing (``optim.smooth``) acts.
FLAT_L_STD = 1.0
FLAT_CHROMA_STD = 2.0


# ----------------------------------------------------------------------------- neighbourhood operators
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
    building it takes little more than K itself (~5 bytes per entry, ~120 entries per texel on a face; 9 while it
    is built).
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
    codes, table = np.empty(int(indptr[-1]), np.uint32), _Codes()
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
        codes[indptr[s] : indptr[e]] = table.of(d2)
    values = np.exp(table.values * (-0.5 / (sigma * sigma)))
    for small in (np.uint8, np.uint16):
        if len(values) <= np.iinfo(small).max + 1:
            codes = codes.astype(small)
            break
    else:  # positions off any lattice: one weight per entry
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
    i, j, r = pairs[keep, 0], pairs[keep, 1], r[keep].astype(np.int64)
    dtap = np.array([-1.0, 0.0, 1.0])
    stap = np.array([1.0, 2.0, 1.0])
    rows, cols, vals = [], [], []
    for a in range(3):
        b, c = [x for x in range(3) if x != a]
        w = dtap[r[:, a] + 1] * stap[r[:, b] + 1] * stap[r[:, c] + 1]  # weight of j in row i; row j gets -w
        nz = w != 0
        wi, ii, jj = w[nz], i[nz], j[nz]
        centre = -(np.bincount(ii, wi, n_tex) - np.bincount(jj, wi, n_tex))
        rows += [a * n_tex + ii, a * n_tex + jj, a * n_tex + np.arange(n_tex)]
        cols += [jj, ii, np.arange(n_tex)]
        vals += [wi, -wi, centre]
    s = sp.coo_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * n_tex, n_tex)
    ).tocsr()
    s.sum_duplicates()
    s.eliminate_zeros()
    return s


# ----------------------------------------------------------------------------- the loss
@dataclass
class LossResult:
    """value = E; e1, e2, e3 the three terms (e2, e3 NaN when not evaluated: ``all_terms=False`` at weight 0);
    grad (I, 3) float64 = dE/d pred (linear RGB); lab (I, 3) float64 CIELAB of the prediction."""

    value: float
    e1: float
    e2: float
    e3: float
    grad: np.ndarray
    lab: np.ndarray


class TexelLoss:
    """E = (g1 E1 / 100^2 + g2 E2 + g3 E3) / (g1 + g2 + g3) over I texels (docs/method.md §5; E1 is scaled
    to units of (dE/100)^2 in the sum, see ``E1_WEIGHT_SCALE``).

    target_rgb (I, 3) linear RGB targets; pos_vox (I, 3) texel positions (x, y, z) in voxel units
    (``Texels.pos_vox``); gamma = (g1, g2, g3) >= 0 with a positive sum; sigma the SSIM Gaussian window's
    standard deviation in voxels.

    - E1 = (1/I) sum_i dE76_i^2 (squared CIELAB distance).
    - E2 = 1 - (1/(3I)) sum_i sum_{L,a,b} SSIM_i on normalised L*a*b*. We divide by 3 (the channel count)
      so E2 lies in [0, 2] (0 when the prediction equals the target). Local means, variances and covariance
      use the texel Gaussian window W (population form, sigma_x^2 = W(x^2) - (Wx)^2, like scikit-image's
      ``use_sample_covariance=False``); K1 = 0.01^2, K2 = 0.03^2 (data range 1).
    - E3 = 100 (1/3) sum_axes sum_{L,a,b} (1/I)(1/4)(1/32) sum_i (S*C - S*T)^2 on normalised L*a*b*, with the
      texel 3D Sobel operators of ``sobel_operators``.

    All three terms are evaluated unless the call says ``all_terms=False`` (the optimiser's training steps): then a
    term of weight 0 is reported as NaN and costs nothing (on the reference slab at the default γ = (1, 0, 0) the
    SSIM and edge terms were half of the loss's time).
    The sparse operators (W: ~(2r+1)^2 entries per texel on a face, r = int(3.5 sigma + 0.5)) are built on first
    use; ``release_operators`` frees them between uses.
    """

    def __init__(self, target_rgb, pos_vox, gamma=(1.0, 0.0, 0.0), sigma: float = 1.5):
        target = np.asarray(target_rgb, np.float64)
        pos = np.asarray(pos_vox, np.float64)
        if target.ndim != 2 or target.shape[1] != 3 or len(target) == 0:
            raise ValueError(f"target_rgb must have shape (I, 3) with I > 0, got {target.shape}")
        if pos.shape != target.shape:
            raise ValueError(f"pos_vox must have shape {target.shape} (x, y, z per texel), got {pos.shape}")
        if not (np.all(np.isfinite(target)) and np.all(np.isfinite(pos))):
            raise ValueError("target_rgb and pos_vox must be finite")
        g = np.asarray(gamma, np.float64).reshape(-1)
        if g.shape != (3,) or not np.all(np.isfinite(g)) or np.any(g < 0) or g.sum() <= 0:
            raise ValueError(f"gamma must be 3 non-negative weights with a positive sum, got {gamma}")
        if not (np.isfinite(sigma) and sigma > 0):
            raise ValueError(f"sigma must be a positive number of voxels, got {sigma}")
        self.gamma = g
        self.sigma = float(sigma)
        self.n = len(target)
        self.target_rgb = target
        self.target_lab = linear_to_lab(target)
        self.target_n = normalise_lab(self.target_lab)
        self._pos = pos
        self._K = self._K2 = self._S = self._ST = None  # the operators, built on first use (``release_operators``)
        self._wsum = None  # kept by ``release_operators`` (I floats)
        #: the window's Chebyshev radius in voxels (``gaussian_window``)
        self.radius = int(3.5 * self.sigma + 0.5)
        tn = self.target_n
        self._mu_t = self._window(tn)
        self._var_t = self._window(tn * tn) - self._mu_t**2
        self._sobel_t = self.S @ tn
        lab = self.target_lab
        var = np.maximum(self._window(lab * lab) - self._window(lab) ** 2, 0.0)
        #: (I,) bool: texels whose target neighbourhood is flat (``FLAT_L_STD``, ``FLAT_CHROMA_STD``)
        self.flat = (np.sqrt(var[:, 0]) < FLAT_L_STD) & (np.sqrt(var[:, 1] + var[:, 2]) < FLAT_CHROMA_STD)

    @property
    def K(self) -> WindowOperator:
        """The window's weights (``gaussian_window``), (I, I) float64; built on first use."""
        if self._K is None:
            self._K, self._wsum, _ = gaussian_window(self._pos, self.sigma)
        return self._K

    @property
    def wsum(self) -> np.ndarray:
        """(I,) float64: the window weight that falls on texels (``gaussian_window``'s n)."""
        if self._wsum is None:
            self.K  # noqa: B018 (builds the window)
        return self._wsum

    @property
    def K2(self) -> WindowOperator:
        """K squared entrywise (the noise of windowed statistics), sharing K's structure; built on first use."""
        if self._K2 is None:
            self._K2 = self.K.squared
        return self._K2

    @property
    def S(self) -> sp.csr_matrix:
        """The stacked Sobel operators (``sobel_operators``), (3I, I) CSR float64; built on first use."""
        if self._S is None:
            self._S = sobel_operators(self._pos)
        return self._S

    def release_operators(self) -> None:
        """Free the window and Sobel operators (~0.8 KB per texel: the window's ~120 entries of 5 bytes, its
        square sharing them, the Sobel operators' ~17 entries of 12 bytes); the next call that needs them builds
        them again, equal to the last. A colour-only training step (``all_terms=False`` at γ2 = γ3 = 0) never
        reads them."""
        self._K = self._K2 = self._S = self._ST = None

    @property
    def needs_operators(self) -> bool:
        """Whether a training step (``all_terms=False``) reads the operators: γ2 > 0 or γ3 > 0."""
        return bool(self.gamma[1] > 0 or self.gamma[2] > 0)

    def highpass(self, x: np.ndarray) -> np.ndarray:
        """(1 - W) x for x (I, k): each texel's value minus its windowed mean."""
        return x - self._window(x)

    def _window(self, x: np.ndarray) -> np.ndarray:
        """W @ x for x (I, k)."""
        return (self.K @ x) / self.wsum[:, None]

    def _window_t(self, y: np.ndarray) -> np.ndarray:
        """W.T @ y for y (I, k) (K is symmetric)."""
        return self.K @ (y / self.wsum[:, None])

    def _check(self, pred_rgb) -> np.ndarray:
        p = np.asarray(pred_rgb, np.float64)
        if p.shape != (self.n, 3):
            raise ValueError(f"pred_rgb must have shape ({self.n}, 3), got {p.shape}")
        if not np.all(np.isfinite(p)):
            raise ValueError("pred_rgb contains NaN or infinite values")
        return p

    @staticmethod
    def _check_var(pred: np.ndarray, pred_var) -> np.ndarray | None:
        """``pred_var`` as float64 (I, 3), or None; a one-line error if it is not a non-negative finite array."""
        if pred_var is None:
            return None
        var = np.asarray(pred_var, np.float64)
        if var.shape != pred.shape or not np.all(np.isfinite(var)) or np.any(var < 0):
            raise ValueError(f"pred_var must be a non-negative (I, 3) array like pred_rgb, got {var.shape}")
        return var

    def _noise(self, pred: np.ndarray, pred_var) -> tuple[np.ndarray, np.ndarray] | None:
        """Noise of a Monte Carlo prediction in the windowed statistics: (W v, sum_j W_ij^2 v_j) with v the
        variance of each texel's normalised L*a*b* (delta method from the linear-RGB variance ``pred_var``)."""
        var = self._check_var(pred, pred_var)
        if var is None:
            return None
        jac = linear_to_lab_jacobian(pred)  # (I, 3 lab, 3 rgb)
        v = np.einsum("ikj,ij->ik", jac * jac, var) * LAB_NORM_SCALE**2
        return (self.K @ v) / self.wsum[:, None], (self.K2 @ v) / (self.wsum**2)[:, None]

    def _ssim_parts(self, cn: np.ndarray, noise=None):
        """SSIM terms. ``noise`` = (W v, W^2 v): with it, the prediction's windowed mean square and variance are
        corrected for the estimator's noise (E[(W c^)^2] = (W c)^2 + W^2 v, E[W c^2] = W c^2 + W v); the noise is
        independent of the target, so the covariance needs no correction. Corrections are constants for the
        gradient."""
        tn = self.target_n
        m = self._window(np.concatenate([cn, cn * cn, cn * tn], axis=1))
        mx, qx, pxy = m[:, :3], m[:, 3:6], m[:, 6:]
        mt = self._mu_t
        mx2, var_x = mx * mx, qx - mx * mx
        if noise is not None:
            wv, w2v = noise
            mx2 = np.maximum(mx2 - w2v, 0.0)
            var_x = np.maximum(var_x - wv + w2v, 0.0)
        a1 = 2.0 * mx * mt + K1
        b1 = mx2 + mt * mt + K1
        a2 = 2.0 * (pxy - mx * mt) + K2
        b2 = var_x + self._var_t + K2
        return (a1 * a2) / (b1 * b2), mx, a1, b1, a2, b2

    def ssim_map(self, pred_rgb, pred_var=None) -> np.ndarray:
        """Per-texel, per-channel SSIM (I, 3) on normalised L*, a*, b*. ``pred_var`` (I, 3): the variance of a
        Monte Carlo prediction (``RenderResult.var_mean``): its noise is removed from the statistics, so the
        value estimates the SSIM of the noise-free prediction instead of being biased low."""
        pred = self._check(pred_rgb)
        cn = normalise_lab(linear_to_lab(pred))
        return self._ssim_parts(cn, self._noise(pred, pred_var))[0]

    def ssim_mean(self, pred_rgb, pred_var=None) -> float:
        """Mean SSIM over texels and the three normalised L*a*b* channels (= 1 - E2); see ``ssim_map``."""
        return float(self.ssim_map(pred_rgb, pred_var).mean())

    def _value_with_noise(self, pred_rgb, noise) -> float:
        """The loss value with a fixed noise correction (for gradient checks)."""
        pred = self._check(pred_rgb)
        lab = linear_to_lab(pred)
        dlab = lab - self.target_lab
        cn = normalise_lab(lab)
        ssim = self._ssim_parts(cn, noise)[0]
        sob = self.S @ cn - self._sobel_t
        e1, e2 = float(np.sum(dlab * dlab) / self.n), float(1.0 - ssim.mean())
        e3 = float(100.0 / (3.0 * self.n * 4.0 * 32.0) * np.sum(sob * sob))
        g1, g2, g3 = self.gamma
        return (g1 * E1_WEIGHT_SCALE * e1 + g2 * e2 + g3 * e3) / self.gamma.sum()

    def __call__(self, pred_rgb, pred_var=None, *, all_terms: bool = True) -> LossResult:
        """Loss and gradient at ``pred_rgb``; ``pred_var`` (I, 3) corrects the SSIM term for Monte Carlo noise;
        ``all_terms=False``: terms of weight 0 are not evaluated (NaN in the result)."""
        pred = self._check(pred_rgb)
        n = self.n
        g1, g2, g3 = self.gamma
        lab = linear_to_lab(pred)
        dlab = lab - self.target_lab
        e1 = float(np.sum(dlab * dlab) / n)
        cn = normalise_lab(lab)
        e2 = e3 = float("nan")
        if all_terms or g2 > 0:
            ssim, mx, a1, b1, a2, b2 = self._ssim_parts(cn, self._noise(pred, pred_var))
            e2 = float(1.0 - ssim.mean())
        else:
            self._check_var(pred, pred_var)  # unused, but a bad variance is still an error
        c3 = 100.0 / (3.0 * n * 4.0 * 32.0)
        if all_terms or g3 > 0:
            sob = self.S @ cn - self._sobel_t
            e3 = float(c3 * np.sum(sob * sob))
        gs = self.gamma.sum()
        value = sum(g * e for g, e in ((g1 * E1_WEIGHT_SCALE, e1), (g2, e2), (g3, e3)) if g > 0) / gs

        g_lab = (2.0 * g1 * E1_WEIGHT_SCALE / n) * dlab if g1 > 0 else np.zeros_like(lab)
        g_n = np.zeros_like(lab)
        if g2 > 0:
            coef = -g2 / (3.0 * n)  # dE2 / dSSIM_ic, times gamma2
            mt = self._mu_t
            gm = coef * 2.0 * ssim * (mt / a1 - mx / b1 - mt / a2 + mx / b2)  # d/d(Wx)
            gq = coef * (-ssim / b2)  # d/d(W x^2)
            gp = coef * 2.0 * ssim / a2  # d/d(W x t)
            back = self._window_t(np.concatenate([gm, gq, gp], axis=1))
            g_n += back[:, :3] + 2.0 * cn * back[:, 3:6] + self.target_n * back[:, 6:]
        if g3 > 0:
            if self._ST is None:
                self._ST = self.S.T.tocsr()
            g_n += (2.0 * g3 * c3) * (self._ST @ sob)
        g_lab += g_n * LAB_NORM_SCALE
        grad = linear_to_lab_vjp(pred, g_lab / gs)
        return LossResult(value=float(value), e1=e1, e2=e2, e3=e3, grad=grad, lab=lab)
