"""Quantization of an optimised ink mixture to one ink per printer voxel (docs/method.md §7).

``quantize(volume, q)`` gives every printer voxel exactly one ink, following the settings ``q`` (a
``model.Quantization``, the one form they travel in: ``check_quantization`` checks them, ``record`` says what a
labels volume keeps of them). It is a pipeline of named steps, one printer layer at a time:

1. the mixture as layers (``layers.MixtureLayers``: an array, a mixture volume or a volume file read lazily);
2. the printer grid over it and its inside mask (``grid.PrinterGrid``: ``q.dpi``, ``q.layer_um``);
3. the inks' order in the bands (``dithers.band_order``: ``q.ink_order`` where the dither orders them);
4. where ``q.compensate``, each ink's share pre-compensated for the halftone (``compensate.share_compensation``);
5. the dither (``dithers.DITHERS[q.method]``: blue-noise dithering, random draws, 3D error diffusion or the error
   diffusion of each optimisation voxel's counts);
6. per printer layer, the cumulative mixture upsampled to it (``layers.CumulativeLayers``, ``grid.UPSAMPLERS
   [q.upsample]``), then the dither's labels (255 = ``EMPTY`` outside).

``quantize_volume`` makes a labels ``Volume`` in memory, ``stream.quantize_run`` a run's labels file
(``inkopt quantize``); ``ink_fractions`` counts the inks per optimisation voxel.

Conventions (docs/conventions.md): arrays (z, y, x[, ink]); ``voxel_mm`` and ``dpi`` are (x, y, z).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import ParameterError
from ..model import EMPTY, Quantization, Volume
from ..units import MM_PER_INCH
from .compensate import share_compensation
from .dithers import INK_ORDERS, band_order, dither_class
from .grid import (
    DEFAULT_DPI,
    DEFAULT_LAYER_UM,
    PrinterGrid,
    _enclosing,
    printer_grid,
    upsample_normals,
    upsampler_class,
)
from .layers import CumulativeLayers, MixtureLayers

__all__ = [
    "DEFAULT_DPI",  # the printer grid's defaults and function (``grid``), for callers of ``quantize``
    "DEFAULT_LAYER_UM",
    "printer_grid",
    "MixtureLayers",
    "band_order",
    "check_quantization",
    "record",
    "quantize",
    "ink_fractions",
    "quantize_volume",
    "summary_lines",
]


def check_quantization(q: Quantization) -> None:
    """One-line ParameterError for settings no quantization follows: an unknown ``method`` or ``upsample``, a
    ``dpi`` that is not 2 or 3 positive numbers, a ``layer_um`` that is not positive, or the layer thickness given
    twice (a z ``dpi`` and ``layer_um``), a ``refine`` that is not a whole number >= 0, a ``compensate`` that is
    not a bool, or linear upsampling for a dither of whole blocks (``Dither.nearest_only``); a ValueError for an
    unknown ``ink_order`` (a record's, from a file)."""
    dither = dither_class(q.method)
    upsampler_class(q.upsample)
    if dither.nearest_only and q.upsample != "nearest":
        raise ParameterError(
            f"method '{q.method}' works on the optimisation voxels' blocks: use upsample 'nearest', or method"
            " 'blue-noise' with linear upsampling"
        )
    if q.ink_order not in INK_ORDERS:  # no flag sets it: a plain ValueError
        raise ValueError(f"unknown ink_order '{q.ink_order}'; use one of {list(INK_ORDERS)}")
    dpi = () if q.dpi is None else q.dpi
    if q.dpi is not None and (
        len(dpi) not in (2, 3)
        or not all(map(_positive, dpi[:2]))
        or not all(v is None or _positive(v) for v in dpi[2:])
    ):
        raise ParameterError(f"`dpi` must be 2 or 3 positive numbers (x, y[, z] dots per inch), got {q.dpi}")
    if q.layer_um is not None:
        if not _positive(q.layer_um):
            raise ParameterError(f"`layer_um` must be positive, got {q.layer_um}")
        if len(dpi) == 3 and dpi[2] is not None:
            raise ParameterError("give the layer thickness once: `dpi` XxYxZ or `layer_um`, not both")
    if not (isinstance(q.refine, (int, np.integer)) and q.refine >= 0):
        raise ParameterError(f"`refine` must be a whole number of iterations >= 0, got {q.refine}")
    if not isinstance(q.compensate, (bool, np.bool_)):
        raise ParameterError(f"`compensate` must be true or false, got {q.compensate!r}")


def _positive(v) -> bool:
    return v is not None and bool(np.isfinite(v)) and v > 0


def record(q: Quantization, vp) -> Quantization:
    """The record of a quantization made with ``q`` on printer voxels of ``vp`` (x, y, z) mm, as a labels volume
    keeps it: ``dpi`` (x, y, z) of those voxels (no ``layer_um``), and ``ink_order`` "index" for a dither that does
    not order the inks."""
    dpi = tuple(float(v) for v in MM_PER_INCH / np.asarray(vp, np.float64))
    ink_order = q.ink_order if dither_class(q.method).ordered else "index"
    return replace(q, seed=int(q.seed), dpi=dpi, ink_order=ink_order, layer_um=None)


def quantize(volume, q: Quantization, out=None):
    """One ink per printer voxel from a mixture on the optimisation grid (module docstring).

    volume  a mixture ``Volume``, a ``model.mixturefile.MixtureSource`` or ``MixtureLayers`` (a bare array or
            layer source with its voxel size, inside mask and inks)
    q       the settings (``check_quantization``); a blue-noise quantization in ``q.ink_order`` "lightness" and a
            compensated one (``q.compensate``: ``printing.compensate``) need the volume's inks
    out     None (a new array is returned) or anything taking ``out[k] = layer`` (Y, X) uint8 for k = 0, 1, ...
            in order (``model.labelfile.LabelFileWriter``: the labels go to a file one layer at a time)
    Returns ``(labels uint8 (Z, Y, X) or out, voxel_mm_printer (3,) float64 (x, y, z))``; label = ink index,
    255 = empty.
    """
    check_quantization(q)
    source = MixtureLayers.of(volume)
    grid = PrinterGrid.of(source.shape[:3], source.voxel_mm, q, inside=source.inside)
    order = band_order(q, source.inks, source.g, source.ior)
    dither = dither_class(q.method)(q, grid, source.shape[3], order)
    comp = share_compensation(source.inks, q, source.g, source.ior) if q.compensate else None
    layers = CumulativeLayers(source, upsampler_class(q.upsample)(grid), order, comp)
    labels = np.empty(grid.shape, np.uint8) if out is None else out
    for k in range(grid.shape[0]):
        labels[k] = dither.layer(k, *layers.printer_layer(k))
    return labels, grid.voxel_mm


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


def quantize_volume(volume: Volume, q: Quantization | None = None, *, normals: bool = True) -> Volume:
    """A labels Volume at printer resolution from a mixture Volume by the settings ``q`` (default
    ``Quantization()``; ``quantize``). Keeps inks, g, ior, boundary; ``inside`` is encoded by label 255. Shading
    normals (meshes) are upsampled by nearest if ``normals`` (``grid.upsample_normals``). The settings' record is
    kept in ``Volume.quantization`` (``record``: dpi (x, y, z))."""
    q = Quantization() if q is None else q
    labels, vp = quantize(volume, q)
    nrm = None
    if normals and volume.normals is not None:
        nrm = upsample_normals(volume.normals, PrinterGrid.of(volume.shape, volume.voxel_mm, q))
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
        quantization=record(q, vp),
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
        f"{q.upsample}{', shares compensated' if q.compensate else ''}; {seconds:.1f} s",
        "inks: "
        + ", ".join(f"{n} {counts[i]} ({100.0 * counts[i] / max(filled, 1):.1f} %)" for i, n in enumerate(ink_names)),
    ]
    return out
