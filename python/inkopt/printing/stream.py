"""Quantization of a run without the whole printer label volume (or the whole mixture) in memory.

The run's mixture volume file (volume.npz) is read one (y, x, N) layer at a time by ``model.mixturefile.MixtureSource``.

``quantize_run`` is ``inkopt quantize``: the labels go layer by layer from ``quantize.quantize`` into the run's
label file (``RunDir.quantized_writer``: quantized.npz + quantized_labels.npy, docs/run-dir.md), so memory holds
the inside mask, a few mixture layers and a few printer layers; a mesh's shading normals go to the printer grid
by ``quantize.upsample_normals`` (20 bytes per printer voxel inside a surface voxel). Labels and normals are
identical to ``quantize_volume``'s in memory.
"""

from __future__ import annotations

import time

from ..model.mixturefile import MixtureSource
from ..rundir import RunDir
from .quantize import band_order, printer_grid, quantize, settings, summary_lines, upsample_normals


def quantize_run(d: RunDir, *, method: str, dpi, layer_um: float, seed: int, upsample: str) -> list[str]:
    """``inkopt quantize``: DIR/volume.npz -> DIR/quantized.npz + quantized_labels.npy (module docstring).
    Returns the summary lines (``quantize.summary_lines``)."""
    t0 = time.perf_counter()
    digest = d.volume_digest()  # recorded in quantized.npz: export and evaluate refuse it once volume.npz changes
    src = MixtureSource(d.volume_file())
    try:
        shape_p, vp = printer_grid(src.shape[:3], src.voxel_mm, dpi=tuple(dpi), layer_um=layer_um)
        quant = settings(method, seed, vp, upsample)
        nrm = None if src.normals is None else upsample_normals(src.normals, shape_p, vp, src.voxel_mm)
        with d.quantized_writer(src.labels_meta(vp, quant), shape_p, normals=nrm, volume_digest=digest) as w:
            quantize(
                src,
                src.voxel_mm,
                method=method,
                dpi=tuple(dpi),
                layer_um=layer_um,
                inside=src.inside,
                seed=int(seed),
                upsample=upsample,
                out=w,
                order=band_order(quant, src.inks, src.g, src.ior),
            )
        counts = w.counts
    finally:
        src.close()
    return summary_lines(shape_p, vp, src.inks.names, quant, counts, time.perf_counter() - t0)
