"""Quantization of a run without the whole printer label volume (or the whole mixture) in memory.

The run's mixture volume file (volume.npz) is read one (y, x, N) layer at a time by ``model.mixturefile.MixtureSource``.

``quantize_run`` is ``inkopt quantize`` (which runs it twice where the run chooses the compensation:
``evaluation.halftone_choice``): the labels go layer by layer from ``quantize.quantize`` into the run's
label file (``RunDir.quantized_writer``: quantized.npz + quantized_labels.layers, docs/run-dir.md), so memory holds
the inside mask, a few mixture layers and a few printer layers; a mesh's shading normals go to the printer grid
by ``grid.upsample_normals`` (20 bytes per printer voxel inside a surface voxel). Labels and normals are
identical to ``quantize_volume``'s in memory. With ``q.refine`` iterations of the refinement on the printed
prediction (``refine``), the mixture is refined in memory first (the run's scene, loss weights and smoothing width
from scene.npz and report.json) and the refined mixture is dithered. With ``q.compensate`` the share compensation
(``compensate``) is measured first where no cached one fits.
"""

from __future__ import annotations

import time

from ..model import Quantization
from ..model.mixturefile import MixtureSource
from ..rundir import RunDir
from .compensate import share_compensation
from .grid import PrinterGrid, upsample_normals
from .quantize import check_quantization, quantize, record, summary_lines
from .refine import PrintedLoss, refine_mixture


def run_target(d: RunDir, vol) -> PrintedLoss:
    """What a run's printed refinement compares with: its scene (scene.npz: texels, targets, fixed shares) and its
    loss weights and smoothing width (report.json; the scene kind's defaults' where a report does not say)."""
    rec, report = d.load_scene(), d.read_report()
    return PrintedLoss(
        texels=rec.texels,
        target_rgb=rec.target_rgb,
        kind=rec.kind,
        gamma=tuple(report.get("gamma", (1.0, 0.0, 0.0))),
        smooth=float(report.get("smooth") or 0.0),
        fixed_share=rec.fixed_share(vol.inks, vol.shape),
    )


def quantize_run(
    d: RunDir, q: Quantization, threads: int | None = None, log=None, into: RunDir | None = None
) -> list[str]:
    """``inkopt quantize``: DIR/volume.npz -> DIR/quantized.npz + quantized_labels.layers by the settings ``q``
    (module docstring), after ``q.refine`` iterations of the printed refinement (``threads``: its render threads;
    ``log``: its line per iteration). ``into``: another directory the labels are written to instead (a candidate,
    ``RunDir.adopt_quantized`` makes it the run's). Returns the summary lines (``quantize.summary_lines``)."""
    check_quantization(q)  # before any file is read
    t0 = time.perf_counter()
    digest = d.volume_digest()  # recorded in quantized.npz: export and evaluate refuse it once volume.npz changes
    refined = None
    if q.refine:
        vol = d.load_volume()
        refined, _ = refine_mixture(vol, run_target(d, vol), q, threads, log)
        del vol
    with MixtureSource(d.volume_file()) as src:
        grid = PrinterGrid.of(src.shape[:3], src.voxel_mm, q)
        made = record(q, grid.voxel_mm)
        nrm = None if src.normals is None else upsample_normals(src.normals, grid)
        if q.compensate:  # measured (about a minute) or read from the cache before the labels file is opened
            share_compensation(src.inks, q, src.g, src.ior, threads, log)
        with (into or d).quantized_writer(
            src.labels_meta(grid.voxel_mm, made), grid.shape, normals=nrm, volume_digest=digest
        ) as w:
            quantize(src if refined is None else refined, q, out=w)
        counts = w.counts
    return summary_lines(grid.shape, grid.voxel_mm, src.inks.names, made, counts, time.perf_counter() - t0)
