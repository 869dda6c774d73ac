"""The perceptual loss E(C, T) over texels (docs/method.md §5) with analytic gradients.

Targets are linear RGB (I, 3) per texel; predictions are C linear channels per texel turned into CIELAB by a
colour map (``inkopt.color.ColourMap``: linear sRGB by default; a spectral prediction's B bands under a light,
``inkopt.spectral.lights``); the terms are computed in CIELAB: E1 mean ΔE76², E2 texel SSIM on normalised L*a*b*
with a Gaussian window restricted to texels, E3 3D Sobel on normalised L*a*b*. With several colour maps (lights)
the loss is the mean, or the worst, of the loss under each.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .color import LAB_NORM_SCALE, RGB, ColourMap, linear_to_lab, normalise_lab
from .neighbourhood import TexelNeighbours, WindowOperator

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


#: how a loss over several lights combines the loss under each
COMBINE = ("mean", "worst")
#: the colour term E1: "squared", the mean ΔE76² (the paper's); "linear", the mean ΔE76 itself in a smooth
#: (Charbonnier) form, mean sqrt(ΔE76² + LINEAR_EPS²), entering the loss squared (E1_WEIGHT_SCALE (mean)², the
#: squared term's units; the same minimiser): the figure the suite's targets are stated in (docs/quality.md, "The
#: colour term as the figure the targets are stated in")
COLOUR_TERMS = ("squared", "linear")
#: ΔE76 below which the linear term turns quadratic (smooth where a texel meets its target)
LINEAR_EPS = 1.0


# ----------------------------------------------------------------------------- the loss
@dataclass
class LossResult:
    """value = E; e1, e2, e3 the three terms (e2, e3 NaN when not evaluated: ``all_terms=False`` at weight 0);
    grad (I, C) float64 = dE/d pred (the prediction's channels; None when not asked); lab (I, 3) float64 CIELAB of
    the prediction (under the first colour map)."""

    value: float
    e1: float
    e2: float
    e3: float
    grad: np.ndarray | None
    lab: np.ndarray


@dataclass
class LossFigures:
    """A prediction's loss and its figures' windowed statistics from one pass over the texels' neighbourhoods per
    colour map (``TexelLoss.figures``): ``loss`` as ``TexelLoss.__call__(..., gradient=False)`` gives it; ``ssim`` the
    mean SSIM under the first colour map (``TexelLoss.ssim_mean``'s); ``window`` (I, a) float64 K @ the asked columns
    and ``window_sq`` (I, b) K^2 @ the asked columns (None when none were asked)."""

    loss: LossResult
    ssim: float
    window: np.ndarray | None
    window_sq: np.ndarray | None


class TexelLoss:
    """E = (g1 E1 / 100^2 + g2 E2 + g3 E3) / (g1 + g2 + g3) over I texels (docs/method.md §5; E1 is scaled
    to units of (dE/100)^2 in the sum, see ``E1_WEIGHT_SCALE``).

    target_rgb (I, 3) linear RGB targets; pos_vox (I, 3) texel positions (x, y, z) in voxel units
    (``Texels.pos_vox``); gamma = (g1, g2, g3) >= 0 with a positive sum; sigma the SSIM Gaussian window's
    standard deviation in voxels. ``colours``: the colour maps of the prediction's C channels (default linear
    sRGB, ``color.RGB``), one per light; with several, ``combine`` "mean" (E is the mean of E under each: its terms
    and gradient are the means) or "worst" (E is the largest, its gradient that light's). The target's CIELAB is
    the same under every light (``linear_to_lab(target_rgb)``): the print should look like the texture to a viewer
    adapted to the light.

    - E1 = (1/I) sum_i dE76_i^2 (squared CIELAB distance); with ``colour_term`` "linear" the value and gradient
      take ((1/I) sum_i sqrt(dE76_i^2 + LINEAR_EPS^2))^2 instead (``COLOUR_TERMS``), the reported ``e1`` stays
      the mean dE76^2.
    - E2 = 1 - (1/(3I)) sum_i sum_{L,a,b} SSIM_i on normalised L*a*b*. We divide by 3 (the channel count)
      so E2 lies in [0, 2] (0 when the prediction equals the target). Local means, variances and covariance
      use the texel Gaussian window W (population form, sigma_x^2 = W(x^2) - (Wx)^2, like scikit-image's
      ``use_sample_covariance=False``); K1 = 0.01^2, K2 = 0.03^2 (data range 1).
    - E3 = 100 (1/3) sum_axes sum_{L,a,b} (1/I)(1/4)(1/32) sum_i (S*C - S*T)^2 on normalised L*a*b*, with the
      texel 3D Sobel operators of ``sobel_operators``.

    All three terms are evaluated unless the call says ``all_terms=False`` (the optimiser's training steps): then a
    term of weight 0 is reported as NaN and costs nothing (on the reference slab at the default γ = (1, 0, 0) the
    SSIM and edge terms were half of the loss's time).
    The sparse operators (W: ~(2r+1)^2 entries per texel on a face, r = int(3.5 sigma + 0.5)) are applied a block
    of texel rows at a time without being held (``neighbourhood.TexelNeighbours``), unless a call with the gradient
    at γ2 > 0 or γ3 > 0 (a training step that reads them) has built them: then they are held and reused until
    ``release_operators``. Both give the same products bit for bit.
    """

    def __init__(
        self,
        target_rgb,
        pos_vox,
        gamma=(1.0, 0.0, 0.0),
        sigma: float = 1.5,
        colours: tuple[ColourMap, ...] | None = None,
        combine: str = "mean",
        colour_term: str = "squared",
    ):
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
        colours = (RGB,) if colours is None else tuple(colours)
        if not colours or len({c.channels for c in colours}) != 1:
            raise ValueError("colours must be one or more colour maps of one channel count")
        if combine not in COMBINE:
            raise ValueError(f"combine must be one of {', '.join(COMBINE)}, got {combine!r}")
        if colour_term not in COLOUR_TERMS:
            raise ValueError(f"colour_term must be one of {', '.join(COLOUR_TERMS)}, got {colour_term!r}")
        #: the colour term's form (``COLOUR_TERMS``)
        self.colour_term = colour_term
        #: the prediction's colour maps (one per light), its channel count and how the lights combine
        self.colours, self.channels, self.combine = colours, colours[0].channels, combine
        self.gamma = g
        self.sigma = float(sigma)
        self.n = len(target)
        self.target_rgb = target
        self.target_lab = linear_to_lab(target)
        self.target_n = normalise_lab(self.target_lab)
        self._pos = pos
        self._ops = TexelNeighbours(pos, self.sigma)  # applied a block of rows at a time unless held
        #: the window's Chebyshev radius in voxels (``gaussian_window``)
        self.radius = self._ops.radius
        tn, lab = self.target_n, self.target_lab
        # the target's windowed statistics in one pass (no operator held): W [t, t^2, lab, lab^2], S t, K @ 1
        k, _, self._sobel_t, self._wsum = self._ops.products(
            np.concatenate([tn, tn * tn, lab, lab * lab], axis=1), sobel=tn, wsum=True
        )
        w = k / self._wsum[:, None]
        del k
        self._mu_t = np.ascontiguousarray(w[:, 0:3])
        self._var_t = w[:, 3:6] - self._mu_t**2
        var = np.maximum(w[:, 9:12] - w[:, 6:9] ** 2, 0.0)
        del w
        #: (I,) bool: texels whose target neighbourhood is flat (``FLAT_L_STD``, ``FLAT_CHROMA_STD``)
        self.flat = (np.sqrt(var[:, 0]) < FLAT_L_STD) & (np.sqrt(var[:, 1] + var[:, 2]) < FLAT_CHROMA_STD)

    @property
    def K(self) -> WindowOperator:
        """The window's weights (``gaussian_window``), (I, I) float64; built and held on first use."""
        return self._ops.window()

    @property
    def wsum(self) -> np.ndarray:
        """(I,) float64: the window weight that falls on texels (``gaussian_window``'s n; kept from the start)."""
        return self._wsum

    @property
    def K2(self) -> WindowOperator:
        """K squared entrywise (the noise of windowed statistics), sharing K's structure; held with K."""
        return self._ops.window_sq()

    @property
    def S(self) -> sp.csr_matrix:
        """The stacked Sobel operators (``sobel_operators``), (3I, I) CSR float64; built and held on first use."""
        return self._ops.sobel()

    def release_operators(self) -> None:
        """Free the held window and Sobel operators (~0.8 KB per texel: the window's ~120 entries of 5 bytes, its
        square sharing them, the Sobel operators' ~17 entries of 12 bytes); later calls apply them a block of rows
        at a time (or build them again, equal to the last, for a step's gradient). A colour-only training step
        (``all_terms=False`` at γ2 = γ3 = 0) never reads them."""
        self._ops.release()

    def _hold_operators(self) -> None:
        """Build and hold the operators a gradient at the loss's weights reads (the window at γ2 > 0, the Sobel
        operators at γ3 > 0): a training step's products then come from them, not from a new search each call."""
        if self.gamma[1] > 0:
            self._ops.window_sq()
        if self.gamma[2] > 0:
            self._ops.sobel_t()

    def products(self, window=None, window_sq=None, sobel=None) -> tuple:
        """(K @ window, K^2 @ window_sq, S @ sobel) for (I, k) float arrays or None: (I, k), (I, k), (3I, k) float64,
        None where not asked (``TexelNeighbours.products``: from the held operators or a block of rows at a time,
        the same bits)."""
        return self._ops.products(window, window_sq, sobel)[:3]

    def under(self, light: int) -> TexelLoss:
        """This loss under its colour map ``light`` alone (the target's statistics and operators shared, not
        copied): the figures under one light."""
        view = copy.copy(self)
        view.colours = (self.colours[light],)
        return view

    @property
    def needs_operators(self) -> bool:
        """Whether a training step (``all_terms=False``) reads the operators: γ2 > 0 or γ3 > 0."""
        return bool(self.gamma[1] > 0 or self.gamma[2] > 0)

    def highpass(self, x: np.ndarray) -> np.ndarray:
        """(1 - W) x for x (I, k): each texel's value minus its windowed mean."""
        return x - self._window(x)

    def _window(self, x: np.ndarray) -> np.ndarray:
        """W @ x for x (I, k)."""
        return self.products(window=x)[0] / self.wsum[:, None]

    def _window_t(self, y: np.ndarray) -> np.ndarray:
        """W.T @ y for y (I, k) (K is symmetric)."""
        return self._ops.window() @ (y / self.wsum[:, None])

    def _check(self, pred_rgb) -> np.ndarray:
        p = np.asarray(pred_rgb, np.float64)
        if p.shape != (self.n, self.channels):
            raise ValueError(f"pred_rgb must have shape ({self.n}, {self.channels}), got {p.shape}")
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
            raise ValueError(f"pred_var must be a non-negative (I, C) array like pred_rgb, got {var.shape}")
        return var

    def _lab_var(self, pred: np.ndarray, pred_var, cmap: ColourMap) -> np.ndarray | None:
        """(I, 3) float64 variance of each texel's normalised L*a*b* under ``cmap`` (delta method from the channels'
        variance ``pred_var``), or None without it."""
        var = self._check_var(pred, pred_var)
        if var is None:
            return None
        jac = cmap.lab_jacobian(pred)  # (I, 3 lab, C)
        return np.einsum("ikj,ij->ik", jac * jac, var) * LAB_NORM_SCALE**2

    def _noise(self, pred: np.ndarray, pred_var, cmap: ColourMap | None = None) -> tuple[np.ndarray, np.ndarray] | None:
        """Noise of a Monte Carlo prediction in the windowed statistics: (W v, sum_j W_ij^2 v_j) with v the
        variance of each texel's normalised L*a*b* (``_lab_var``) under ``cmap`` (default the first colour map)."""
        v = self._lab_var(pred, pred_var, cmap or self.colours[0])
        if v is None:
            return None
        k, k2, _ = self.products(window=v, window_sq=v)
        return k / self.wsum[:, None], k2 / (self.wsum**2)[:, None]

    def _terms(self, cn: np.ndarray, v, ssim: bool, sobel: bool, parts: bool, extra=(None, None)) -> tuple:
        """One pass over the texels' neighbourhoods a block of rows at a time (``TexelNeighbours.blocks``) for a
        prediction's normalised L*a*b* ``cn`` (I, 3) and its variance ``v`` (I, 3) (``_lab_var``, or None): (the
        SSIM map (I, 3) if ``ssim``, S cn - S t (3I, 3) if ``sobel``, the SSIM parts (mx, a1, b1, a2, b2), each
        (I, 3), if ``parts``, K @ extra[0], K^2 @ extra[1] for ``extra`` (I, a), (I, b) arrays or None), None where
        not asked. Only these are whole arrays: the windowed statistics are a block's."""
        n = self.n
        window, window_sq = [], []
        if ssim:
            window.append(np.concatenate([cn, cn * cn, cn * self.target_n], axis=1))
            if v is not None:
                window.append(v)
                window_sq.append(v)
        at = (sum(x.shape[1] for x in window), sum(x.shape[1] for x in window_sq))  # where the extra columns start
        for cols, to in zip(extra, (window, window_sq)):
            if cols is not None:
                to.append(cols)
        window = np.concatenate(window, axis=1) if window else None
        window_sq = np.concatenate(window_sq, axis=1) if window_sq else None
        out = [np.empty((n, 3)) if ssim else None, np.empty((3 * n, 3)) if sobel else None]
        out += [[np.empty((n, 3)) for _ in range(5)] if parts else None]
        out += [None if c is None else np.empty((n, c.shape[1])) for c in extra]
        for s, e, k, k2, sx, _ in self._ops.blocks(window, window_sq, cn if sobel else None):
            if ssim:
                w = self.wsum[s:e, None]
                noise = None if v is None else (k[:, 9:12] / w, k2[:, :3] / (self.wsum[s:e] ** 2)[:, None])
                got = self._ssim_parts(cn[s:e], noise, k[:, :9] / w, slice(s, e))
                out[0][s:e] = got[0]
                for o, g in zip(out[2] or (), got[1:]):
                    o[s:e] = g
            for a in range(3) if sobel else ():
                rows = slice(a * n + s, a * n + e)
                out[1][rows] = sx[a] - self._sobel_t[rows]
            for o, r, c in zip(out[3:], (k, k2), at):
                if o is not None:
                    o[s:e] = r[:, c:]
        return tuple(out)

    def _ssim_parts(self, cn: np.ndarray, noise=None, m: np.ndarray | None = None, rows=slice(None)):
        """SSIM terms of texels ``rows`` (``cn`` and ``noise`` theirs). ``noise`` = (W v, W^2 v): with it, the
        prediction's windowed mean square and variance are corrected for the estimator's noise (E[(W c^)^2] =
        (W c)^2 + W^2 v, E[W c^2] = W c^2 + W v); the noise is independent of the target, so the covariance needs
        no correction. Corrections are constants for the gradient. ``m``: W [cn, cn^2, cn t] of the rows if taken
        (``_terms``), else every texel's is taken here."""
        if m is None:
            m = self._window(np.concatenate([cn, cn * cn, cn * self.target_n], axis=1))
        mx, qx, pxy = m[:, :3], m[:, 3:6], m[:, 6:]
        mt = self._mu_t[rows]
        mx2, var_x = mx * mx, qx - mx * mx
        if noise is not None:
            wv, w2v = noise
            mx2 = np.maximum(mx2 - w2v, 0.0)
            var_x = np.maximum(var_x - wv + w2v, 0.0)
        a1 = 2.0 * mx * mt + K1
        b1 = mx2 + mt * mt + K1
        a2 = 2.0 * (pxy - mx * mt) + K2
        b2 = var_x + self._var_t[rows] + K2
        return (a1 * a2) / (b1 * b2), mx, a1, b1, a2, b2

    def ssim_map(self, pred_rgb, pred_var=None, light: int = 0) -> np.ndarray:
        """Per-texel, per-channel SSIM (I, 3) on normalised L*, a*, b* under colour map ``light``. ``pred_var``
        (I, C): the variance of a Monte Carlo prediction (``RenderResult.var_mean``): its noise is removed from the
        statistics, so the value estimates the SSIM of the noise-free prediction instead of being biased low."""
        pred = self._check(pred_rgb)
        cmap = self.colours[light]
        cn = normalise_lab(cmap.lab(pred))
        return self._terms(cn, self._lab_var(pred, pred_var, cmap), ssim=True, sobel=False, parts=False)[0]

    def ssim_mean(self, pred_rgb, pred_var=None, light: int = 0) -> float:
        """Mean SSIM over texels and the three normalised L*a*b* channels (= 1 - E2); see ``ssim_map``."""
        return float(self.ssim_map(pred_rgb, pred_var, light).mean())

    def _value_with_noise(self, pred_rgb, noise, light: int = 0) -> float:
        """The loss value under colour map ``light`` with a fixed noise correction (for gradient checks)."""
        pred = self._check(pred_rgb)
        lab = self.colours[light].lab(pred)
        dlab = lab - self.target_lab
        cn = normalise_lab(lab)
        ssim = self._ssim_parts(cn, noise)[0]
        sob = self.products(sobel=cn)[2] - self._sobel_t
        c1, e2 = self._colour(dlab, False)[0], float(1.0 - ssim.mean())
        e3 = float(100.0 / (3.0 * self.n * 4.0 * 32.0) * np.sum(sob * sob))
        g1, g2, g3 = self.gamma
        return (g1 * E1_WEIGHT_SCALE * c1 + g2 * e2 + g3 * e3) / self.gamma.sum()

    def _colour(self, dlab: np.ndarray, gradient: bool) -> tuple[float, np.ndarray | None]:
        """The colour term in ΔE76² units (the mean ΔE76², or the squared mean of the linear form) of the CIELAB
        errors ``dlab`` (I, 3), and (``gradient``) the direction its gradient takes: the term's gradient with
        respect to ``dlab`` is 2 / I times it (``dlab`` itself for the squared term)."""
        if self.colour_term == "squared":
            return float(np.sum(dlab * dlab) / self.n), dlab
        r = np.sqrt(np.sum(dlab * dlab, axis=1) + LINEAR_EPS**2)
        e = float(r.mean())
        return e * e, e * dlab / r[:, None] if gradient else None

    def __call__(self, pred_rgb, pred_var=None, *, all_terms: bool = True, gradient: bool = True) -> LossResult:
        """Loss and gradient at ``pred_rgb`` (I, C); ``pred_var`` (I, C) corrects the SSIM term for Monte Carlo
        noise; ``all_terms=False``: terms of weight 0 are not evaluated (NaN in the result); ``gradient=False``:
        the value and terms only (``grad`` None; the figures: none of the gradient's per-texel temporaries). Several
        colour maps: combined by ``combine`` (the result's ``lab`` is under the first)."""
        pred = self._check(pred_rgb)
        if gradient:  # a training step: the operators its gradient reads are held for the next steps
            self._hold_operators()
        return self._combined([self._under(pred, pred_var, all_terms, c, gradient)[0] for c in self.colours])

    def figures(self, pred_rgb, pred_var=None, window=None, window_sq=None) -> LossFigures:
        """The loss's value and terms at ``pred_rgb`` (I, C) (``self(pred_rgb, pred_var, gradient=False)``'s, bit for
        bit), the mean SSIM under the first colour map (``ssim_mean``'s) and K @ ``window`` (I, a), K^2 @
        ``window_sq`` (I, b) (float arrays or None: a figure's other windowed statistics, e.g. the mottle's), from
        one pass over the texels' neighbourhoods per colour map: a prediction's figures without the operators held
        (``TexelNeighbours``)."""
        pred = self._check(pred_rgb)
        each, first = [], None
        for k, cmap in enumerate(self.colours):
            res, parts = self._under(pred, pred_var, True, cmap, False, (window, window_sq) if k == 0 else (None, None))
            each.append(res)
            first = parts if first is None else first
        return LossFigures(self._combined(each), *first)

    def _combined(self, each: list[LossResult]) -> LossResult:
        """The loss under each colour map combined by ``combine`` (one: itself)."""
        if len(each) == 1:
            return each[0]
        if self.combine == "worst":
            worst = max(each, key=lambda r: r.value)
            return LossResult(worst.value, worst.e1, worst.e2, worst.e3, worst.grad, each[0].lab)
        k = len(each)
        terms = [sum(getattr(r, t) for r in each) / k for t in ("value", "e1", "e2", "e3")]
        grad = sum(r.grad for r in each) / k if each[0].grad is not None else None
        return LossResult(*terms, grad=grad, lab=each[0].lab)

    def _under(self, pred, pred_var, all_terms: bool, cmap: ColourMap, gradient: bool = True, extra=(None, None)):
        """The loss and (``gradient``) its gradient under one colour map (see ``__call__``), and (mean SSIM, K @
        extra[0], K^2 @ extra[1]) from the same pass over the neighbourhoods (``_statistics``; the SSIM NaN when not
        evaluated): (``LossResult``, that tuple)."""
        n = self.n
        g1, g2, g3 = self.gamma
        lab = cmap.lab(pred)
        dlab = lab - self.target_lab
        e1 = float(np.sum(dlab * dlab) / n)
        c1, g_c1 = self._colour(dlab, gradient and g1 > 0)
        cn = normalise_lab(lab)
        e2 = e3 = ssim_mean = float("nan")
        want_ssim, want_sobel = all_terms or g2 > 0, all_terms or g3 > 0
        if want_ssim:
            v = self._lab_var(pred, pred_var, cmap)
        else:
            v = self._check_var(pred, pred_var)  # unused, but a bad variance is still an error
        ssim, sob, parts, *products = self._terms(cn, v, want_ssim, want_sobel, gradient and g2 > 0, extra)
        if want_ssim:
            mean = ssim.mean()
            e2, ssim_mean = float(1.0 - mean), float(mean)
        c3 = 100.0 / (3.0 * n * 4.0 * 32.0)
        if want_sobel:  # squared in place when no gradient reads it: no second (3I, 3) array
            e3 = float(c3 * np.sum(sob * sob if gradient else np.multiply(sob, sob, out=sob)))
        gs = self.gamma.sum()
        value = sum(g * e for g, e in ((g1 * E1_WEIGHT_SCALE, c1), (g2, e2), (g3, e3)) if g > 0) / gs
        figures = (ssim_mean, *products)
        if not gradient:
            return LossResult(value=float(value), e1=e1, e2=e2, e3=e3, grad=None, lab=lab), figures

        g_lab = (2.0 * g1 * E1_WEIGHT_SCALE / n) * g_c1 if g1 > 0 else np.zeros_like(lab)
        g_n = np.zeros_like(lab)
        if g2 > 0:
            coef = -g2 / (3.0 * n)  # dE2 / dSSIM_ic, times gamma2
            mx, a1, b1, a2, b2 = parts
            mt = self._mu_t
            gm = coef * 2.0 * ssim * (mt / a1 - mx / b1 - mt / a2 + mx / b2)  # d/d(Wx)
            gq = coef * (-ssim / b2)  # d/d(W x^2)
            gp = coef * 2.0 * ssim / a2  # d/d(W x t)
            back = self._window_t(np.concatenate([gm, gq, gp], axis=1))
            g_n += back[:, :3] + 2.0 * cn * back[:, 3:6] + self.target_n * back[:, 6:]
        if g3 > 0:
            g_n += (2.0 * g3 * c3) * (self._ops.sobel_t() @ sob)
        g_lab += g_n * LAB_NORM_SCALE
        grad = cmap.lab_vjp(pred, g_lab / gs)
        return LossResult(value=float(value), e1=e1, e2=e2, e3=e3, grad=grad, lab=lab), figures
