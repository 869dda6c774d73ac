"""Quantization of an optimised ink mixture to one ink per printer voxel (docs/method.md §7).

The optimiser works on a coarse grid (300 DPI, ~85 µm voxels); the printer deposits one ink per voxel on a
finer, anisotropic grid (600 × 300 DPI in x × y, 27 µm layers by default). ``quantize`` upsamples the mixture
to the printer grid and gives every printer voxel exactly one ink:

- ``random``: the paper's method. Each printer voxel draws its ink independently with the (upsampled) mixture as
  the probability distribution (``numpy.random.default_rng(seed)``). Adds white noise.
- ``blue-noise`` (default): ordered dithering. A 3D blue-noise threshold array ``t`` (void-and-cluster, tiled
  periodically over the printer grid) is compared with the cumulative mixture: the voxel gets ink ``k`` with
  ``c_{k-1} <= t < c_k``, ``c_k = rho_0 + ... + rho_k``. Every ink then occupies a band of threshold values
  whose share equals its mixture weight, and because the thresholds of neighbouring voxels are spread evenly,
  the local ink fractions match the mixture much more closely than independent draws (the error is pushed to
  high spatial frequencies, which the scattering medium low-passes). The inks are summed in the order ``order``
  gives: lightest first (``dither.lightness_order``, which says why) for ``quantize_volume``, ``inkopt quantize``
  and the evaluation's baselines, through ``band_order``; index order when None.
- ``error-diffusion``: deterministic 3D vector error diffusion (``inkopt_core::diffuse``, in Rust). Printer
  voxels are visited layer by layer (z up), rows in y, each row serpentine in x (direction alternating with
  ``y + z``); each takes the ink with the largest component of its corrected mixture (mixture + carried error,
  i.e. the nearest one-hot vector) and passes the residual (corrected mixture - one-hot) to unvisited
  neighbours: 7/8 in its layer with Floyd–Steinberg's proportions (49, 21, 35, 7)/128, 1/8 to the next layer
  (8/128 straight down, 2/128 to each of that voxel's four xy neighbours; the weights and the measurements that
  chose them are in crates/core/src/kernels/diffuse.rs). Weights are renormalised over neighbours
  inside the object; outside voxels neither take nor pass error. The ink counts of any window differ from its
  summed mixture only by the residuals crossing its boundary (each bounded: within [-1/2, 1/2] for two inks).
  ``seed`` is unused.

The first two use the same inverse-CDF rule with a threshold ``t`` in [0, 1): uniform random numbers make it an
exact draw from the mixture, the blue-noise array makes it ordered dithering.

Upsampling (``upsample``): ``nearest`` (default, as the paper) gives every printer voxel the mixture of the
optimisation voxel that encloses its centre; ``linear`` interpolates the mixture trilinearly between
optimisation voxel centres (normalised over voxels inside the object, so empty space never bleeds in). The
``inside`` mask is always upsampled by nearest; printer voxels outside get label ``EMPTY`` (255).

Memory: the printer grid is processed one layer at a time; only the xy-upsampled cumulative mixture of one or
two optimisation layers (N × Y × X float32) exists at a time, never the full upsampled float volume (error
diffusion adds the carried error of this and the next printer layer, 2 × Y × X × N float32).

Conventions (docs/conventions.md): arrays (z, y, x[, ink]); ``voxel_mm`` and ``dpi`` are (x, y, z).
"""

from __future__ import annotations

import numpy as np

from ..model import EMPTY, Quantization, SurfaceNormals, Volume
from ..units import MM_PER_INCH, PRINTER_DPI, PRINTER_LAYER_UM
from .dither import lightness_order, load_blue_noise

METHODS = ("blue-noise", "random", "error-diffusion")
UPSAMPLE = ("nearest", "linear")
DEFAULT_DPI = PRINTER_DPI
DEFAULT_LAYER_UM = PRINTER_LAYER_UM


# ----------------------------------------------------------------------------------------------- grids
def printer_grid(shape_opt, voxel_mm_opt, dpi=(600, 300, None), layer_um: float = DEFAULT_LAYER_UM):
    """Printer voxel grid covering the same box as an optimisation grid.

    shape_opt (z, y, x) voxels; voxel_mm_opt (x, y, z) mm; ``dpi`` (x, y) or (x, y, z) dots per inch, the z
    entry None (default) meaning "use ``layer_um``" (layer thickness in µm, 27 by default, 14 for high quality).
    Each printer dimension is ``round(extent_mm / printer_voxel_mm)`` (at least 1), so the printed extent differs
    from the optimised one by at most half a printer voxel.
    Returns ``(shape_p (Z, Y, X) tuple of int, voxel_mm_p (3,) float64 (x, y, z) mm)``.
    """
    shape_opt = tuple(int(s) for s in shape_opt)
    vo = np.asarray(voxel_mm_opt, np.float64).reshape(-1)
    if len(shape_opt) != 3 or min(shape_opt) < 1:
        raise ValueError(f"shape_opt must be 3 positive sizes (z, y, x), got {shape_opt}")
    if vo.shape != (3,) or not np.all(np.isfinite(vo)) or np.any(vo <= 0):
        raise ValueError(f"voxel_mm must be 3 positive finite sizes (x, y, z) in mm, got {vo}")
    dpi = tuple(dpi)
    if len(dpi) not in (2, 3):
        raise ValueError(f"dpi must be (x, y) or (x, y, z), got {dpi}")
    if len(dpi) == 3 and dpi[2] is not None:
        vz = MM_PER_INCH / float(dpi[2])
    else:
        vz = float(layer_um) / 1000.0
    vp = np.array([MM_PER_INCH / float(dpi[0]), MM_PER_INCH / float(dpi[1]), vz], np.float64)
    if not np.all(np.isfinite(vp)) or np.any(vp <= 0):
        raise ValueError(f"dpi and layer_um must be positive, got dpi={dpi} layer_um={layer_um}")
    extent = np.array(shape_opt[::-1], np.float64) * vo  # (x, y, z) mm
    n = np.maximum(1, np.rint(extent / vp)).astype(int)
    return (int(n[2]), int(n[1]), int(n[0])), vp


def _enclosing(n_p: int, vp: float, n_o: int, vo: float) -> np.ndarray:
    """Index (int64) of the optimisation voxel that encloses each printer voxel centre along one axis."""
    return np.clip(np.floor((np.arange(n_p) + 0.5) * (vp / vo)).astype(np.int64), 0, n_o - 1)


def _linear(n_p: int, vp: float, n_o: int, vo: float):
    """(i0, i1, w1) of linear interpolation between optimisation voxel centres at printer voxel centres."""
    s = np.clip((np.arange(n_p) + 0.5) * (vp / vo) - 0.5, 0.0, n_o - 1.0)
    i0 = np.minimum(np.floor(s).astype(np.int64), n_o - 1)
    i1 = np.minimum(i0 + 1, n_o - 1)
    return i0, i1, (s - i0).astype(np.float32)


# ----------------------------------------------------------------------------------------- quantization
def settings(method: str, seed: int, vp, upsample: str) -> Quantization:
    """The record of a quantization made now on printer voxels of ``vp`` (x, y, z) mm: blue noise sums the inks
    lightest first (``ink_order`` "lightness"), the other methods use no order ("index")."""
    dpi = tuple(float(v) for v in MM_PER_INCH / np.asarray(vp, np.float64))
    return Quantization(method, int(seed), dpi, upsample, "lightness" if method == "blue-noise" else "index")


def band_order(q: Quantization, inks, g: float, ior: float):
    """The ``order`` argument of :func:`quantize` that the settings ``q`` say: the inks lightest first
    (``dither.lightness_order``) for blue noise with ``q.ink_order`` "lightness", else None (index order). Every
    caller takes it from here, so ours and the evaluation's baselines are dithered alike, a labels file made in index
    order included."""
    if q.method == "blue-noise" and q.ink_order == "lightness":
        return lightness_order(inks, g, ior)
    return None


def check_quantization(method: str, upsample: str = "nearest") -> None:
    """One-line ValueError for an unknown quantization ``method`` or ``upsample``."""
    if method not in METHODS:
        raise ValueError(f"unknown quantization method '{method}'; use one of {list(METHODS)}")
    if upsample not in UPSAMPLE:
        raise ValueError(f"unknown upsample '{upsample}'; use one of {list(UPSAMPLE)}")


def quantize(
    mixture,
    voxel_mm,
    *,
    method: str = "blue-noise",
    dpi=DEFAULT_DPI,
    layer_um: float = DEFAULT_LAYER_UM,
    inside=None,
    seed: int = 0,
    upsample: str = "nearest",
    out=None,
    order=None,
):
    """One ink per printer voxel from a mixture on the optimisation grid.

    mixture  float (z, y, x, N), non-negative; rows are normalised to sum 1 (rows inside must have a positive sum)
    voxel_mm (x, y, z) mm of the optimisation grid
    method   "blue-noise" (ordered dithering, default), "random" (the paper's independent draws) or
             "error-diffusion" (deterministic 3D vector error diffusion)
    dpi      printer (x, y) or (x, y, z) DPI; z None -> ``layer_um`` (µm per layer)
    inside   optional bool (z, y, x); printer voxels whose enclosing optimisation voxel is outside get 255
    seed     ``default_rng(seed)``: the random draws (one layer after the other, so the result does not depend on
             any chunking), or the toroidal offset of the blue-noise tile; unused by error diffusion
    upsample "nearest" (enclosing voxel) or "linear" (trilinear between voxel centres, inside voxels only)
    out      None (a new array is returned) or anything taking ``out[k] = layer`` (Y, X) uint8 for k = 0, 1, ...
             in order (``model.labelfile.LabelFileWriter``: the labels go to a file one layer at a time)
    order    blue-noise only: the ink indices (N,) in the order their bands follow in the cumulative mixture
             (``band_order``: lightest first, as ``quantize_volume``, ``inkopt quantize`` and the evaluation's
             baselines use); None: index order
    ``mixture`` may also be a layer source (``model.mixturefile.MixtureSource``): ``shape`` (z, y, x, N) and
    ``[z]`` giving one (y, x, N) layer, asked for in increasing z; its layers are checked as they are read.
    Returns ``(labels uint8 (Z, Y, X) or out, voxel_mm_printer (3,) float64 (x, y, z))``; label = ink index,
    255 = empty.
    """
    source = not isinstance(mixture, np.ndarray) and hasattr(mixture, "shape")
    m = mixture if source else np.asarray(mixture)
    if len(m.shape) != 4 or m.shape[3] < 1:
        raise ValueError(f"mixture must have shape (z, y, x, N), got {m.shape}")
    n_inks = m.shape[3]
    if n_inks >= EMPTY:
        raise ValueError(f"at most {EMPTY - 1} inks fit uint8 labels, got {n_inks}")
    check_quantization(method, upsample)
    nz, ny, nx = m.shape[:3]
    if inside is not None:
        inside = np.asarray(inside, bool)
        if inside.shape != (nz, ny, nx):
            raise ValueError(f"inside mask shape {inside.shape} differs from mixture shape {(nz, ny, nx)}")
    if source:

        def get(z: int):
            lay = np.asarray(m[z])
            return lay, _checked_total(lay, None if inside is None else inside[z])
    else:
        if not np.issubdtype(m.dtype, np.floating):
            m = m.astype(np.float32)
        total = _checked_total(m, inside)

        def get(z: int):
            return m[z], total[z]

    shape_p, vp = printer_grid((nz, ny, nx), voxel_mm, dpi=dpi, layer_um=layer_um)
    vo = np.asarray(voxel_mm, np.float64).reshape(-1)
    Z, Y, X = shape_p

    enc = [_enclosing(Z, vp[2], nz, vo[2]), _enclosing(Y, vp[1], ny, vo[1]), _enclosing(X, vp[0], nx, vo[0])]
    rng = np.random.default_rng(seed)
    perm = None  # the bands' ink order (blue noise), and its map from band to ink label
    if method == "blue-noise" and order is not None:
        perm = np.asarray(order, np.int64).reshape(-1)
        if sorted(perm.tolist()) != list(range(n_inks)):
            raise ValueError(f"order must be a permutation of the {n_inks} ink indices, got {perm.tolist()}")
        band_ink = perm.astype(np.uint8)
    if method == "blue-noise":
        tile = load_blue_noise()
        tz, ty, tx = tile.shape
        oz, oy, ox = (int(v) for v in rng.integers(0, tile.shape))
        ty_idx = ((np.arange(Y) + oy) % ty)[:, None]
        tx_idx = ((np.arange(X) + ox) % tx)[None, :]

        def thresholds(k):
            return tile[(k + oz) % tz][ty_idx, tx_idx]
    elif method == "random":

        def thresholds(k):
            return rng.random((Y, X), dtype=np.float32)

    lin = (
        None
        if upsample == "nearest"
        else [_linear(Z, vp[2], nz, vo[2]), _linear(Y, vp[1], ny, vo[1]), _linear(X, vp[0], nx, vo[0])]
    )
    cache: dict[int, np.ndarray] = {}

    def layer_cum(z: int) -> np.ndarray:
        """xy-upsampled cumulative mixture of optimisation layer z, float32 (N, Y, X); entry N-1 = weight."""
        if z in cache:
            return cache[z]
        lay, t = get(z)
        lay = lay.astype(np.float64)
        w = np.ones((ny, nx)) if inside is None else inside[z].astype(np.float64)
        lay = lay * (w / np.where(t > 0, t, 1.0))[..., None]  # rows sum to 1 inside, 0 outside
        if perm is not None:
            lay = lay[..., perm]
        c = np.cumsum(lay, axis=2).astype(np.float32).transpose(2, 0, 1)  # (N, ny, nx)
        if lin is None:
            out = c[:, enc[1]][:, :, enc[2]]
        else:
            (y0, y1, wy), (x0, x1, wx) = lin[1], lin[2]
            c = c[:, y0] * (1 - wy)[None, :, None] + c[:, y1] * wy[None, :, None]
            out = c[:, :, x0] * (1 - wx) + c[:, :, x1] * wx
        if len(cache) >= 2:
            cache.pop(next(iter(cache)))
        cache[z] = np.ascontiguousarray(out, dtype=np.float32)
        return cache[z]

    def inside_p(k: int) -> np.ndarray:
        """Printer layer k's inside mask (nearest), bool (Y, X); all False past the last layer."""
        if k >= Z:
            return np.zeros((Y, X), bool)
        if inside is None:
            return np.ones((Y, X), bool)
        return inside[enc[0][k]][enc[1][:, None], enc[2][None, :]]

    labels = np.empty(shape_p, np.uint8) if out is None else out
    error = np.zeros((2, Y, X, n_inks), np.float32) if method == "error-diffusion" else None
    for k in range(Z):
        if lin is None:
            c = layer_cum(int(enc[0][k]))
        else:
            z0, z1, wz = (a[k] for a in lin[0])
            c = layer_cum(int(z0)) * (1 - wz) + layer_cum(int(z1)) * wz
        if error is not None:
            lab = np.empty((Y, X), np.uint8)
            _diffuse(c, inside_p(k), inside_p(k + 1), error, k, lab)
            labels[k] = lab
            continue
        t = thresholds(k)
        if lin is not None:
            t = t * c[-1]  # normalise by the interpolated inside weight (t * w >= c_n  <=>  t >= c_n / w)
        lab = np.zeros((Y, X), np.uint8)
        for n in range(n_inks - 1):
            lab += t >= c[n]
        if perm is not None:
            lab = band_ink[lab]
        if inside is not None:
            lab[~inside_p(k)] = EMPTY
        labels[k] = lab
    return labels, vp


def _checked_total(m, inside) -> np.ndarray:
    """Row sums (float64) of a mixture array (..., N), checked: finite, non-negative, positive inside."""
    if not np.all(np.isfinite(m)) or m.min() < 0:
        raise ValueError("mixture must be finite and non-negative")
    total = m.sum(axis=-1, dtype=np.float64)
    if np.any((total <= 0) if inside is None else (inside & (total <= 0))):
        raise ValueError("mixture rows inside the object must have a positive sum")
    return total


def _diffuse(cum, inside_k, inside_next, error, k: int, out) -> None:
    """Error-diffuse printer layer k in Rust: ``cum`` (N, Y, X) cumulative mixture whose last entry is the
    (interpolated) inside weight; ``error`` (2, Y, X, N) float32 carried error; writes the labels into ``out``."""
    from .. import _core

    w = cum[-1]
    mix = np.diff(cum, axis=0, prepend=np.zeros((1,) + w.shape, np.float32))
    mix /= np.where(w > 0, w, 1.0).astype(np.float32)
    _core.diffuse_layer(
        np.ascontiguousarray(mix, np.float32), inside_k.view(np.uint8), inside_next.view(np.uint8), error, int(k), out
    )


def ink_fractions(labels, n_inks: int, shape_opt, voxel_mm_opt, voxel_mm_printer):
    """Per optimisation voxel, the fraction of each ink among the printer voxels it encloses.

    labels uint8 (Z, Y, X) (255 = empty, not counted); shape_opt (z, y, x); voxel sizes (x, y, z) mm. The printer
    voxel -> optimisation voxel map is the one ``quantize`` uses (the voxel enclosing the printer voxel centre).
    Returns ``(fractions float64 (z, y, x, N), counts int64 (z, y, x))``: counts = non-empty printer voxels per
    optimisation voxel; fractions are 0 where counts is 0.
    """
    labels = np.asarray(labels)
    if labels.ndim != 3 or labels.dtype != np.uint8:
        raise ValueError(f"labels must be uint8 (Z, Y, X), got {labels.dtype} {labels.shape}")
    nz, ny, nx = (int(s) for s in shape_opt)
    vo = np.asarray(voxel_mm_opt, np.float64).reshape(-1)
    vp = np.asarray(voxel_mm_printer, np.float64).reshape(-1)
    Z, Y, X = labels.shape
    iz, iy, ix = _enclosing(Z, vp[2], nz, vo[2]), _enclosing(Y, vp[1], ny, vo[1]), _enclosing(X, vp[0], nx, vo[0])
    used = labels[labels != EMPTY]
    if used.size and int(used.max()) >= n_inks:
        raise ValueError(f"labels use ink {int(used.max())} but n_inks is {n_inks}")
    nb = n_inks + 1  # last bin: empty
    base = ((iy[:, None] * nx + ix[None, :]) * nb).ravel()
    acc = np.zeros((nz, ny * nx * nb), np.int64)
    for k in range(Z):
        lab = labels[k].ravel().astype(np.int64)
        lab[lab == EMPTY] = n_inks
        acc[iz[k]] += np.bincount(base + lab, minlength=ny * nx * nb)
    counts = acc.reshape(nz, ny, nx, nb)[..., :n_inks]
    tot = counts.sum(axis=3)
    frac = counts / np.maximum(tot, 1)[..., None]
    return frac, tot


# ----------------------------------------------------------------------------------------- volumes
def upsample_normals(normals: SurfaceNormals, shape_p, vp, vo) -> SurfaceNormals:
    """Shading normals on the printer grid ``shape_p`` (Z, Y, X) of ``vp`` (x, y, z) mm voxels, nearest from
    ``normals`` on an optimisation grid of ``vo`` mm voxels: every printer voxel inside a voxel with a normal gets
    it (a few printer voxels per surface voxel; 20 bytes each). Built one printer layer at a time."""
    (nz, ny, nx), (Z, Y, X) = normals.shape, shape_p
    iz, iy, ix = (_enclosing(Z, vp[2], nz, vo[2]), _enclosing(Y, vp[1], ny, vo[1]), _enclosing(X, vp[0], nx, vo[0]))
    index, vectors, last = [], [], None
    for k in range(Z):
        if iz[k] != last:  # printer layers in one optimisation layer share its upsampled normals (iz is sorted)
            up = normals.layer(iz[k])[iy][:, ix].reshape(-1, 3)
            has = np.flatnonzero(np.any(up != 0, axis=1))
            vec, last = up[has], iz[k]
        index.append(k * Y * X + has)
        vectors.append(vec)
    return SurfaceNormals(shape_p, np.concatenate(index), np.concatenate(vectors))


def quantize_volume(
    volume: Volume,
    *,
    method: str = "blue-noise",
    dpi=DEFAULT_DPI,
    layer_um: float = DEFAULT_LAYER_UM,
    seed: int = 0,
    upsample: str = "nearest",
    normals: bool = True,
) -> Volume:
    """A labels Volume at printer resolution from a mixture Volume (``quantize`` above).

    dpi (x, y) or (x, y, z) printer DPI (z None/absent -> ``layer_um`` µm layers). Keeps inks, g, ior, boundary;
    ``inside`` is encoded by label 255. Shading normals (meshes) are upsampled by nearest if ``normals``
    (``upsample_normals``). The settings are kept in ``Volume.quantization`` (dpi (x, y, z)).
    """
    if volume.form != "mixture":
        raise ValueError(f"quantization needs a mixture volume, got a {volume.form} volume")
    check_quantization(method, upsample)
    q = settings(
        method, seed, printer_grid(volume.shape, volume.voxel_mm, dpi=tuple(dpi), layer_um=layer_um)[1], upsample
    )
    labels, vp = quantize(
        volume.mixture,
        volume.voxel_mm,
        method=method,
        dpi=tuple(dpi),
        layer_um=layer_um,
        inside=volume.inside,
        seed=int(seed),
        upsample=upsample,
        order=band_order(q, volume.inks, volume.g, volume.ior),
    )
    nrm = None
    if normals and volume.normals is not None:
        nrm = upsample_normals(volume.normals, labels.shape, vp, volume.voxel_mm)
    return Volume.from_labels(
        voxel_mm=vp,
        labels=labels,
        inks=volume.inks,
        g=volume.g,
        ior=volume.ior,
        inside=None,
        normals=nrm,
        boundary=volume.boundary,
        origin_mm=volume.origin_mm,
        quantization=q,
    )


def summary_lines(shape, vp, ink_names, q: Quantization | None, counts, seconds: float) -> list[str]:
    """What ``inkopt quantize`` prints about a labels volume: grid ``shape`` (Z, Y, X) of ``vp`` (x, y, z) mm
    voxels, the ink voxel ``counts`` (256,), settings."""
    filled = int(counts[:EMPTY].sum())
    Z, Y, X = shape
    q = q or Quantization()
    dpi = MM_PER_INCH / np.asarray(vp, np.float64)
    out = [
        f"printer grid {X} x {Y} x {Z} (x, y, z) voxels of {vp[0] * 1000:.1f} x {vp[1] * 1000:.1f} x "
        f"{vp[2] * 1000:.1f} um ({dpi[0]:.0f} x {dpi[1]:.0f} DPI, {vp[2] * 1000:.1f} um layers)",
        f"{filled} ink voxels ({counts[EMPTY]} empty); method {q.method}, seed {q.seed}, upsample "
        f"{q.upsample}; {seconds:.1f} s",
        "inks: "
        + ", ".join(f"{n} {counts[i]} ({100.0 * counts[i] / max(filled, 1):.1f} %)" for i, n in enumerate(ink_names)),
    ]
    return out
