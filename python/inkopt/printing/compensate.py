"""Share pre-compensation of a halftone: the dithered print of an ink at share p looks like its continuous mixture at a
smaller share, so the dither is given a larger one.

Why: a printer voxel (42 x 85 x 27 µm at 600 x 300 DPI) is not small against the inks' mean free paths (yellow
absorbs blue at 16 /mm, white scatters it at 24 /mm), so light that scatters in the base ink's voxels passes the
grains of an absorbing ink less often than the same ink spread evenly through the mixture would make it absorb (the
"package effect"). The print is then lighter and less saturated than its mixture: on the duck at 10 mm the
blue-noise print is ΔE76 1.04 from its mixture on average, Δb* −1.0, and 0.40 on a printer grid twice as fine
(``experiments/halftone_cause.py``, docs/quality.md "Keeping what the optimiser found").

The correction is measured on flat patches: for each ink but the base (the lightest: white), patches of the base
with a share p of the ink, dithered on the printer grid and rendered from the top, are matched to continuous patches
of the same two inks; the continuous share whose colour is nearest in CIELAB is the dithered patch's effective share.
One factor k per ink models them, ``p_eff = p / (1 + k (1 - p))`` (fitted with the patches' standard errors: the
model pools the patches, so an ink without a package effect gets k near 0 instead of each patch's noise).
``ShareCompensation.apply`` inverts it per ink: the dither gets the share p' with ``p_eff(p') = p``, and the base
ink the rest. Where inks mix, each ink's factor against each other ink (``kappa``) is measured too, on patches of
two non-base inks in the base (``measure_mixed``, ``fit_kappa``); it is kept with the compensation and applied only
where ``pairs`` is set: on the meshes measured it corrected less than each ink fitted alone (docs/quality.md).
"""

from __future__ import annotations

import hashlib
import io
import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..color import lab_stderr, linear_to_lab
from ..io import atomic_write_bytes
from ..model import InkTable, Quantization, Texels, Volume
from ..render import Renderer
from .dither import lightness_order
from .dithers import band_order, dither_class
from .grid import PrinterGrid, upsampler_class
from .layers import CumulativeLayers, MixtureLayers

#: nominal shares whose dithered patches are measured (k is fitted to them)
DITHERED_SHARES = (0.02, 0.05, 0.1, 0.2, 0.3, 0.45, 0.6, 0.8)
#: continuous shares of the curve each dithered colour is matched on
CONTINUOUS_SHARES = (0.0, 0.005, 0.01, 0.02, 0.03, 0.045, 0.06, 0.08, 0.1, 0.13, 0.16, 0.2, 0.25, 0.3)
CONTINUOUS_SHARES = CONTINUOUS_SHARES + (0.35, 0.4, 0.45, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)
PATCH_LATERAL = 32  # printer voxels per side of a dithered patch: the blue-noise tile's period, so it wraps exactly
PATCH_MM = 2.5  # patch thickness, as the colour table's
PATCH_SPP = 64  # samples per texel of a dithered patch (1024 texels)
#: shares (p_i, p_j) of the measured patches of two non-base inks i < j in the base (every pair): equal small shares,
#: and one ink small in much of the other (Spot's yellow in magenta or black)
PAIR_SHARES = ((0.1, 0.1), (0.05, 0.3), (0.3, 0.05))
PAIR_STEP = 0.04  # the share step of the continuous patches a mixed patch's effective shares are solved on
PAIR_SPP = 4 * PATCH_SPP  # samples per texel of a mixed dithered patch (its continuous ones: 4 times as many)
MIXED_FIELDS = ("kappa", "kappa_stderr", "mixed_rows", "mixed_effective", "mixed_stderr")
FORMAT = 3  # of the cached file (part of its key)


@dataclass(frozen=True)
class ShareCompensation:
    """How an ink set's dithered inks look against their base ink: per ink i, a dithered share p looks like the
    continuous share ``p / (1 + k_i (1 - p))`` (``effective``; k_i > 0: the package effect, fitted to the measured
    patches by weighted least squares, ``fit_k``).

    base          the base ink's index (the rest of every corrected row goes to it)
    k             (N,) float64 the package factor of each ink (0 for the base)
    k_stderr      (N,) float64 its standard error from the patches' Monte Carlo noise
    shares        (K,) float64 the nominal shares of the measured dithered patches
    measured      (N, K) float64 the continuous share each patch was matched to (the base's row: ``shares``)
    share_stderr  (N, K) float64 its standard error (the colours' ΔE76 standard error over the curve's slope)
    kappa         (N, N) float64 or None: the package factor of ink i against ink j's share (``fit_kappa``, from
                  patches of two non-base inks in the base); None: k_i, every other ink acting as the base
    kappa_stderr  (N, N) float64 its standard error (inf where no patch holds the pair)
    mixed_rows    (M, N) float64 the nominal rows of the measured mixed patches
    mixed_effective, mixed_stderr  (M, N) float64 the continuous rows they look like and the shares' standard errors
    taper         a share (0: none) below which an ink's correction is scaled by share / taper (a setting, not
                  measured)
    pairs         whether ``kappa`` is applied (a setting, default off: on the duck, the spider and Spot 20 mm the
                  correction with it gained less ΔE76 and ΔE2000 than each ink fitted alone against the base;
                  docs/quality.md, "Where inks mix")
    base_only     whether each ink is corrected against the base's share alone, ``p / (1 + k_i w)`` with w the
                  base's share, so that a row without the base is left as it is (a setting; otherwise every other
                  ink counts as base, ``p / (1 + k_i (1 - p))``; ``pairs`` takes precedence)
    """

    base: int
    k: np.ndarray
    k_stderr: np.ndarray
    shares: np.ndarray
    measured: np.ndarray
    share_stderr: np.ndarray
    kappa: np.ndarray | None = None
    kappa_stderr: np.ndarray | None = None
    mixed_rows: np.ndarray | None = None
    mixed_effective: np.ndarray | None = None
    mixed_stderr: np.ndarray | None = None
    taper: float = 0.0
    pairs: bool = False
    base_only: bool = False

    def effective(self, p, i: int) -> np.ndarray:
        """The continuous share that ink ``i`` dithered at share ``p`` (array, in [0, 1]) in the base alone looks
        like."""
        p = np.asarray(p, np.float64)
        return p / (1.0 + self.k[i] * (1.0 - p))

    def factors(self) -> np.ndarray:
        """(N, N) float64: entry (i, j) the package factor of ink i against ink j's share, k_i against the base
        (j = base), ``kappa`` against another ink where ``pairs``, else 0 where ``base_only``, else k_i (every other
        ink acting as the base); the diagonal and the base's row are 0."""
        n = len(self.k)
        if self.kappa is not None and self.pairs:
            f = np.array(self.kappa, np.float64)
        else:
            f = np.repeat(np.asarray(self.k, np.float64)[:, None], n, 1) * (0.0 if self.base_only else 1.0)
        f[:, self.base] = self.k
        np.fill_diagonal(f, 0.0)
        f[self.base] = 0.0
        return f

    def effective_rows(self, rows) -> np.ndarray:
        """The continuous rows (..., N) float64 that dithered ``rows`` (..., N) look like: every ink but the base
        ``p_i / (1 + sum_j f_ij p_j)`` (``factors``; j runs over the other inks and the base), the base the
        rest."""
        rows = np.asarray(rows, np.float64)
        out = rows / (1.0 + rows @ self.factors().T)
        out[..., self.base] = rows.sum(-1) - np.delete(out, self.base, -1).sum(-1)
        return out

    def apply(self, mix: np.ndarray) -> np.ndarray:
        """The pre-compensated rows of ``mix`` (..., N) (rows summing to 1, or 0 outside), same shape, float64:
        every ink but the base takes the share p' whose dither looks like its share p in ``mix`` (``effective_rows``
        of the result equals ``mix``; without ``kappa`` or ``base_only`` p' = p (1 + k) / (1 + k p)), the base the
        rest; where the non-base shares would sum above 1, they are scaled to 1 (no base); below ``taper`` the
        correction shrinks."""
        mix = np.asarray(mix, np.float64)
        total = mix.sum(-1)
        if (self.kappa is None or not self.pairs) and not self.base_only:
            out = np.empty_like(mix)
            for i in range(mix.shape[-1]):
                if i != self.base:
                    p = mix[..., i]
                    out[..., i] = p * (1.0 + self.k[i]) / (1.0 + self.k[i] * p)
        else:
            out = self._inverse(mix, total)
        others = np.delete(np.arange(mix.shape[-1]), self.base)
        if self.taper > 0:  # below the taper share, the correction in proportion to the share
            p = mix[..., others]
            out[..., others] = p + (out[..., others] - p) * np.minimum(p / self.taper, 1.0)
        s = out[..., others].sum(-1)
        over = s > total
        out[..., others] *= np.where(over, total / np.where(over, s, 1.0), 1.0)[..., None]
        out[..., self.base] = np.maximum(total - out[..., others].sum(-1), 0.0)
        return out

    def _inverse(self, mix: np.ndarray, total: np.ndarray) -> np.ndarray:
        """The non-base shares p' (..., N) with ``effective_rows(p')`` = ``mix`` (the base's column: 0), by the
        fixed point p'_i = p_i (1 + sum_j f_ij p'_j) with the base's share total - sum p' (at least 0); its map's
        slope is about the largest factor times the share (< 0.4), so 60 steps reach float64 rounding."""
        f = self.factors()
        f_base = f[:, self.base].copy()
        f[:, self.base] = 0.0
        t = mix.copy()
        t[..., self.base] = 0.0
        p = t.copy()
        for _ in range(60):
            w = np.maximum(total - p.sum(-1), 0.0)
            new = t * (1.0 + p @ f.T + w[..., None] * f_base)
            done = np.max(np.abs(new - p), initial=0.0) < 1e-13
            p = new
            if done:
                break
        return p

    def arrays(self) -> dict:
        """The fields as arrays (the cached file's; the mixed patches' where measured)."""
        fields = ("base", "k", "k_stderr", "shares", "measured", "share_stderr")
        fields += tuple(f for f in MIXED_FIELDS if getattr(self, f) is not None)
        return {f: np.asarray(getattr(self, f)) for f in fields}


def fit_k(shares: np.ndarray, measured: np.ndarray, stderr: np.ndarray) -> tuple[float, float]:
    """The package factor k minimising sum(((p / (1 + k (1 - p)) - e) / s)^2) over the patches (p, e, s) of one
    ink, in [-0.5, 5], and its standard error (from the model's slope in k at the optimum)."""
    from scipy.optimize import minimize_scalar

    p, e, s = (np.asarray(a, np.float64) for a in (shares, measured, stderr))
    w = 1.0 / np.maximum(s, 1e-6) ** 2
    res = minimize_scalar(lambda k: np.sum(w * (p / (1 + k * (1 - p)) - e) ** 2), bounds=(-0.5, 5.0), method="bounded")
    k = float(res.x)
    slope = -p * (1 - p) / (1 + k * (1 - p)) ** 2
    return k, float(1.0 / np.sqrt(max(np.sum(w * slope * slope), 1e-300)))


def patch_labels(row, inks: InkTable, q: Quantization, g: float, ior: float) -> Volume:
    """A periodic-xy patch of the mixture ``row`` (N,) dithered by ``q`` (without compensation) on its printer grid:
    32 x 32 printer voxels (the blue-noise tile) by ``PATCH_MM`` thick, a labels ``Volume``. The mixture is given on
    the printer grid itself, so the upsampling is the identity and the dither sees ``row`` in every voxel, as
    ``quantize.quantize`` would."""
    q = replace(q, compensate=False)
    vp = PrinterGrid.of((1, 1, 1), (1.0, 1.0, 1.0), q).voxel_mm  # the printer voxel (x, y, z) mm of ``q``
    shape = (max(1, int(round(PATCH_MM / vp[2]))), PATCH_LATERAL, PATCH_LATERAL)
    mix = np.broadcast_to(np.asarray(row, np.float32), shape + (len(inks),))
    grid = PrinterGrid.of(shape, vp, q)
    order = band_order(q, inks, g, ior)
    dither = dither_class(q.method)(q, grid, len(inks), order)
    layers = CumulativeLayers(MixtureLayers(mix, vp, None, inks, g, ior), upsampler_class(q.upsample)(grid), order)
    labels = np.stack([dither.layer(k, *layers.printer_layer(k)) for k in range(grid.shape[0])])
    return Volume.from_labels(grid.voxel_mm, labels, inks, g=g, ior=ior, boundary="periodic-xy")


def _top_colour(vol: Volume, spp: int, seed: int, threads) -> tuple[np.ndarray, float]:
    """Mean colour (3,) linear RGB of a patch's top face and its ΔE76 standard error."""
    texels = Texels.for_volume(vol, ["top"])
    res = Renderer(vol, threads).render(texels, spp, seed)
    mean = res.rgb.astype(np.float64).mean(0)
    return mean, float(lab_stderr(mean, res.var_mean.astype(np.float64).sum(0) / len(texels) ** 2))


def _curve_share(lab: np.ndarray, curve: np.ndarray, shares: np.ndarray) -> tuple[float, float, int]:
    """The share at the point of the polyline ``curve`` (K, 3) CIELAB (at ``shares`` (K,)) nearest to ``lab``, the
    curve's slope there (ΔE76 per unit share) and the index of its segment."""
    a, b = curve[:-1], curve[1:]
    ab = b - a
    t = np.clip(np.sum((lab - a) * ab, 1) / np.maximum(np.sum(ab * ab, 1), 1e-12), 0.0, 1.0)
    d = np.sum((a + t[:, None] * ab - lab) ** 2, 1)
    j = int(np.argmin(d))
    slope = float(np.linalg.norm(ab[j]) / (shares[j + 1] - shares[j]))
    return float(shares[j] + t[j] * (shares[j + 1] - shares[j])), slope, j


def _continuous_curve(inks: InkTable, i: int, base: int, g: float, ior: float, seed: int, threads):
    """CIELAB (K, 3) and ΔE76 standard errors (K,) of continuous patches of ink ``i`` in ``base`` at
    ``CONTINUOUS_SHARES`` (64 texels at 4 x ``PATCH_SPP`` spp each, seeds from ``seed``)."""
    n = len(inks)
    lab, err = [], []
    for j, p in enumerate(CONTINUOUS_SHARES):
        row = np.zeros(n)
        row[i], row[base] = p, 1.0 - p
        vol = Volume.from_mixture(
            voxel_mm=(0.25, 0.25, PATCH_MM), mixture=row.reshape(1, 1, 1, n).repeat(8, 1).repeat(8, 2),
            inks=inks, g=g, ior=ior, boundary="periodic-xy",
        )  # fmt: skip
        rgb, se = _top_colour(vol, 4 * PATCH_SPP, seed + j, threads)
        lab.append(linear_to_lab(rgb))
        err.append(se)
    return np.array(lab), np.array(err)


def measure_compensation(inks: InkTable, q: Quantization, g: float, ior: float, base: int, threads=None, log=None):
    """The ``ShareCompensation`` of ``inks`` dithered by ``q`` against the ``base`` ink (module docstring): per ink
    ``CONTINUOUS_SHARES`` continuous patches (``_continuous_curve``) and ``DITHERED_SHARES`` dithered ones (1024
    top texels at ``PATCH_SPP`` spp), each with a seed of its own; each dithered colour matched to its nearest
    point of the continuous curve, and k fitted (``fit_k``); then the factors against other inks (``measure_mixed``,
    kept with ``pairs`` off). About 1 s per patch on 2 cores."""
    n = len(inks)
    shares = np.array(DITHERED_SHARES)
    measured = np.tile(shares, (n, 1))
    share_se = np.zeros((n, len(shares)))
    k, k_se = np.zeros(n), np.zeros(n)
    cs = np.array(CONTINUOUS_SHARES)
    seed = 1
    for i in (i for i in range(n) if i != base):
        curve, curve_se = _continuous_curve(inks, i, base, g, ior, seed, threads)
        seed += len(cs)
        for m, p in enumerate(shares):
            row = np.zeros(n)
            row[i], row[base] = p, 1.0 - p
            rgb, se = _top_colour(patch_labels(row, inks, q, g, ior), PATCH_SPP, seed, threads)
            measured[i, m], slope, j = _curve_share(linear_to_lab(rgb), curve, cs)
            share_se[i, m] = np.hypot(se, curve_se[j : j + 2].mean()) / max(slope, 1e-9)
            seed += 1
        k[i], k_se[i] = fit_k(shares, measured[i], share_se[i])
        if log is not None:
            pairs = ", ".join(f"{p:g} -> {e:.3f}" for p, e in zip(shares, measured[i]))
            log(f"  {inks.names[i]}: k {k[i]:.3f} ± {k_se[i]:.3f} (dithered share -> continuous: {pairs})")
    comp = ShareCompensation(base, k, k_se, shares, measured, share_se)
    return measure_mixed(comp, inks, q, g, ior, seed, threads, log)


def _mixture_patch(row, inks: InkTable, g: float, ior: float) -> Volume:
    """A periodic-xy continuous patch of the mixture ``row`` (N,): 8 x 8 voxels of 0.25 mm, ``PATCH_MM`` thick."""
    n = len(inks)
    mixture = np.asarray(row, np.float64).reshape(1, 1, 1, n).repeat(8, 1).repeat(8, 2)
    return Volume.from_mixture((0.25, 0.25, PATCH_MM), mixture, inks, g=g, ior=ior, boundary="periodic-xy")


def mixed_effective(row, comp: ShareCompensation, inks, q, g, ior, seed: int, threads=None):
    """The continuous shares (N,) that the dither of ``row`` (N,) looks like, and their standard errors (N,) (0 for
    inks not in ``row``; the base: the rest): its top colour linearised about the continuous row ``c0`` that
    ``comp`` predicts, from continuous patches at ``c0`` and at ``c0`` with ``PAIR_STEP`` more of each ink present
    (less base; one seed for all of them, so their differences carry little noise), solved in least squares:
    lab(dithered) = lab(c0) + J (e - c0). The standard errors are those of the two colours (each CIELAB
    coordinate taken with a third of the ΔE76 variance) through (J^T J)^-1 J^T; J's own noise is left out."""
    row = np.asarray(row, np.float64)
    present = [i for i in range(len(row)) if i != comp.base and row[i] > 0]
    lab_d, se_d = _top_colour(patch_labels(row, inks, q, g, ior), PAIR_SPP, seed, threads)
    lab_d = linear_to_lab(lab_d)
    c0 = comp.effective_rows(row)
    rgb0, se0 = _top_colour(_mixture_patch(c0, inks, g, ior), 4 * PAIR_SPP, seed + 1, threads)
    lab0 = linear_to_lab(rgb0)
    jac = np.empty((3, len(present)))
    for m, i in enumerate(present):
        c = c0.copy()
        c[i] += PAIR_STEP
        c[comp.base] -= PAIR_STEP
        jac[:, m] = (linear_to_lab(_top_colour(_mixture_patch(c, inks, g, ior), 4 * PAIR_SPP, seed + 1, threads)[0])
                     - lab0) / PAIR_STEP  # fmt: skip
    delta, *_ = np.linalg.lstsq(jac, lab_d - lab0, rcond=None)
    cov = np.linalg.pinv(jac.T @ jac) * (se_d**2 + se0**2) / 3.0
    eff, se = c0.copy(), np.zeros_like(c0)
    eff[present] += delta
    se[present] = np.sqrt(np.diag(cov))
    eff[comp.base] = row.sum() - np.delete(eff, comp.base).sum()
    return eff, se


def fit_kappa(comp: ShareCompensation, rows: np.ndarray, eff: np.ndarray, se: np.ndarray):
    """The package factors (N, N) of each ink against each other non-base ink and their standard errors, by
    weighted linear least squares per ink i over the mixed patches (M rows (M, N), measured effective shares
    ``eff`` ± ``se``) that hold it: p_i / e_i - 1 - k_i w = sum_j kappa_ij p_j (``effective_rows``), with k_i
    (against the base, share w) fixed at the base patches' fit. An ink pair no patch holds keeps kappa_ij = k_i
    and a standard error of inf."""
    n, b = len(comp.k), comp.base
    kappa = np.repeat(np.asarray(comp.k, np.float64)[:, None], n, 1)
    kappa_se = np.full((n, n), np.inf)
    for i in range(n):
        m = (rows[:, i] > 0) & (eff[:, i] > 0) if i != b else np.zeros(len(rows), bool)
        cols = [j for j in range(n) if j not in (i, b) and np.any(rows[m, j] > 0)]
        if not cols:
            continue
        p, e = rows[m, i], eff[m, i]
        y = p / e - 1.0 - comp.k[i] * rows[m, b]
        w = 1.0 / np.maximum(p / (e * e) * se[m, i], 1e-9) ** 2
        x = rows[m][:, cols]
        cov = np.linalg.pinv(x.T @ (w[:, None] * x))
        kappa[i, cols] = cov @ (x.T @ (w * y))
        kappa_se[i, cols] = np.sqrt(np.diag(cov))
    np.fill_diagonal(kappa, 0.0)
    kappa[b] = 0.0
    return kappa, kappa_se


def measure_mixed(comp: ShareCompensation, inks, q, g, ior, seed: int, threads=None, log=None):
    """``comp`` with its factors against other inks (``fit_kappa``) measured on patches of every pair of non-base
    inks at ``PAIR_SHARES`` in the base (``mixed_effective``; about 2 s per patch on 2 cores)."""
    n, b = len(inks), comp.base
    inks_nb = [i for i in range(n) if i != b]
    rows = []
    for a, i in enumerate(inks_nb):
        for j in inks_nb[a + 1 :]:
            for pi, pj in PAIR_SHARES:
                row = np.zeros(n)
                row[i], row[j], row[b] = pi, pj, 1.0 - pi - pj
                rows.append(row)
    rows = np.array(rows)
    eff, se = np.zeros_like(rows), np.zeros_like(rows)
    for m, row in enumerate(rows):
        eff[m], se[m] = mixed_effective(row, comp, inks, q, g, ior, seed + 2 * m, threads)
    kappa, kappa_se = fit_kappa(comp, rows, eff, se)
    if log is not None:
        for i in inks_nb:
            pairs = ", ".join(f"{inks.names[j]} {kappa[i, j]:.3f} ± {kappa_se[i, j]:.3f}" for j in inks_nb if j != i)
            log(f"  {inks.names[i]} against the other inks: {pairs} (against {inks.names[b]}: {comp.k[i]:.3f})")
    return replace(comp, kappa=kappa, kappa_stderr=kappa_se, mixed_rows=rows, mixed_effective=eff, mixed_stderr=se)


def compensation_key(inks: InkTable, q: Quantization, g: float, ior: float) -> str:
    """A hash of what a compensation depends on: the inks' coefficients, g, ior, the dither (the one whose labels it
    gives on the patches' constant mixtures, ``Dither.constant_as``), its printer voxel (µm, rounded to 0.01) and the
    measurement's settings."""
    vp_um = tuple(np.round(PrinterGrid.of((1, 1, 1), (1.0, 1.0, 1.0), q).voxel_mm * 1000.0, 2).tolist())
    h = hashlib.sha256()
    for a in (inks.sigma_a, inks.sigma_s):  # as float32: an ink table read from a run's files has them so
        h.update(np.ascontiguousarray(a, np.float32).tobytes())
    method = dither_class(q.method).constant_as or q.method  # the patches are constant mixtures
    h.update(repr((FORMAT, float(g), float(ior), method, q.ink_order, vp_um, DITHERED_SHARES)).encode())
    h.update(repr((CONTINUOUS_SHARES, PATCH_LATERAL, PATCH_MM, PATCH_SPP, PAIR_SHARES, PAIR_STEP, PAIR_SPP)).encode())
    return h.hexdigest()[:16]


_MEMORY: dict[str, ShareCompensation] = {}
#: compensations shipped with the package (the default inks' on the default printer grid), read before the cache
PACKAGED = Path(__file__).resolve().parents[1] / "data" / "compensation"


def cache_path(key: str) -> Path:
    """Where the compensation of ``key`` is cached: ``$INKOPT_CACHE_DIR``, else ``$XDG_CACHE_HOME/inkopt``, else
    ``~/.cache/inkopt`` (the colour table's cache)."""
    if os.environ.get("INKOPT_CACHE_DIR"):
        root = Path(os.environ["INKOPT_CACHE_DIR"])
    else:
        root = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "inkopt"
    return root / f"compensation_{key}.npz"


def has_compensation(inks: InkTable | None, q: Quantization, g: float, ior: float) -> bool:
    """Whether ``share_compensation`` would find the factors without measuring them (in memory, shipped or cached)."""
    if inks is None:
        return False
    key = compensation_key(inks, q, g, ior)
    return key in _MEMORY or _stored(key) is not None


def _stored(key: str):
    """The file holding the factors of ``key``: the package's copy (``PACKAGED``), else the disk cache's; None."""
    path = cache_path(key)
    return next((p for p in (PACKAGED / path.name, path) if p.is_file()), None)


def share_compensation(inks: InkTable | None, q: Quantization, g: float, ior: float, threads=None, log=None):
    """The ``ShareCompensation`` of ``inks`` dithered by ``q`` (its base: the lightest ink, whatever the bands'
    order), from this process's memory, the package's copy (``PACKAGED``), the disk cache (``cache_path``) or
    measured (``measure_compensation``, about two minutes for five inks) and cached (atomically; a read-only cache is
    skipped)."""
    if inks is None:
        raise ValueError("a compensated quantization needs the mixture's ink table")
    key = compensation_key(inks, q, g, ior)
    if key in _MEMORY:
        return _MEMORY[key]
    path, stored = cache_path(key), _stored(key)
    if stored is not None:
        with np.load(stored, allow_pickle=False) as z:
            comp = ShareCompensation(**{f: z[f] for f in z.files if f != "base"}, base=int(z["base"]))
    else:
        base = int(lightness_order(inks, g, ior)[0])
        if log is not None:
            log(f"share compensation of {', '.join(inks.names)} on this printer grid: measuring (cached in {path})")
        comp = measure_compensation(inks, q, g, ior, base, threads, log)
        buf = io.BytesIO()
        np.savez(buf, **comp.arrays())
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_bytes(path, buf.getvalue())
        except OSError:
            pass  # a read-only cache: measured again next time
    _MEMORY[key] = comp
    return comp
