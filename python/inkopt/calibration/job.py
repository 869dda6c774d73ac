"""``inkopt calibration-chart``'s outputs: DIR/chart.txt (the chart as CGATS.17, measurement columns empty),
DIR/job/ (a run directory holding the printable chart as a mixture volume: ``inkopt quantize DIR/job`` and
``inkopt export DIR/job`` print it like any job) and DIR/layout.png (the chart seen from above, each patch in its
predicted colour with its SAMPLE_ID).

Layout: patches of ``patch_mm`` x ``patch_mm`` in rows of ``ceil(sqrt(P))``, sample 1 at the top left (largest y,
smallest x, as the top face is seen from above), a gap of a fifth of a patch between them, every patch a separate
column standing on the build plate: its backing layer (if any) at the bottom, the patch layer on top. The grid's
voxels are ``patch_mm / 20`` wide (patches are uniform, so the quantizer's nearest-neighbour upsampling to the
printer grid loses nothing) and 0.1 mm high (every designed thickness is a multiple of it).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io import write_png
from ..model import InkTable, Volume
from ..rundir import RunDir
from .cgats import write as write_cgats
from .chart import Chart, ChartError

VOXELS_PER_PATCH = 20
GAP_VOXELS = 4
Z_MM = 0.1
CHART_FILE, JOB_DIR, LAYOUT_FILE = "chart.txt", "job", "layout.png"


def chart_grid(n: int) -> tuple[int, int]:
    """(rows, columns) of the layout of ``n`` patches."""
    cols = int(np.ceil(np.sqrt(n)))
    return int(np.ceil(n / cols)), cols


def chart_volume(chart: Chart, inks: InkTable, patch_mm: float) -> Volume:
    """The printable chart: a mixture volume of ``inks`` (the chart's ink order) with an inside mask."""
    rows, cols = chart_grid(len(chart))
    pitch = VOXELS_PER_PATCH + GAP_VOXELS
    heights = []
    for p in chart.patches:
        layers = [p.thickness_mm] + ([p.backing_mm] if p.backing != "none" else [])
        counts = [int(round(t / Z_MM)) for t in layers]
        if any(abs(c * Z_MM - t) > 1e-6 or c < 1 for c, t in zip(counts, layers)):
            raise ChartError(f"patch {p.sample_id}: thicknesses {layers} mm are not multiples of {Z_MM} mm")
        heights.append(counts)
    nz = max(sum(h) for h in heights)
    ny, nx = rows * pitch - GAP_VOXELS, cols * pitch - GAP_VOXELS
    mix = np.zeros((nz, ny, nx, len(inks)), np.float32)
    inside = np.zeros((nz, ny, nx), bool)
    for k, (p, h) in enumerate(zip(chart.patches, heights)):
        r, c = divmod(k, cols)
        y1 = ny - r * pitch
        ys, xs = slice(y1 - VOXELS_PER_PATCH, y1), slice(c * pitch, c * pitch + VOXELS_PER_PATCH)
        z = 0
        if p.backing != "none":
            mix[: h[1], ys, xs, chart.inks.index(p.backing)] = 1.0
            z = h[1]
        mix[z : z + h[0], ys, xs] = np.asarray(p.shares, np.float32)
        inside[: z + h[0], ys, xs] = True
    vox = patch_mm / VOXELS_PER_PATCH
    return Volume.from_mixture(voxel_mm=(vox, vox, Z_MM), mixture=mix, inks=inks, inside=inside, g=inks.g)


def layout_picture(chart: Chart, rgb: np.ndarray, px_per_patch: int = 80):
    """The chart from above (PIL image): each patch in ``rgb`` (P, 3) linear, its SAMPLE_ID in black or white."""
    from PIL import Image, ImageDraw, ImageFont

    from ..color import to_srgb8

    rows, cols = chart_grid(len(chart))
    gap = px_per_patch * GAP_VOXELS // VOXELS_PER_PATCH
    pitch = px_per_patch + gap
    im = Image.new("RGB", (cols * pitch + gap, rows * pitch + gap), (128, 128, 128))
    draw = ImageDraw.Draw(im)
    try:
        font = ImageFont.load_default(size=max(10, px_per_patch // 4))
    except TypeError:  # Pillow < 10.1 has no sized default font
        font = ImageFont.load_default()
    srgb = to_srgb8(np.clip(rgb, 0, 1))
    for k, p in enumerate(chart.patches):
        r, c = divmod(k, cols)
        x0, y0 = gap + c * pitch, gap + r * pitch
        col = tuple(int(v) for v in srgb[k])
        draw.rectangle([x0, y0, x0 + px_per_patch - 1, y0 + px_per_patch - 1], fill=col)
        ink = (0, 0, 0) if np.asarray(rgb[k]) @ np.array([0.2126, 0.7152, 0.0722]) > 0.18 else (255, 255, 255)
        draw.text((x0 + px_per_patch / 2, y0 + px_per_patch / 2), p.sample_id, fill=ink, font=font, anchor="mm")
    return im


def write_chart(out, chart: Chart, inks: InkTable, patch_mm: float = 10.0, header: dict | None = None) -> dict:
    """Write chart.txt, job/volume.npz and layout.png under ``out``; returns their paths by name."""
    from .fit import predict_rgb

    if not (np.isfinite(patch_mm) and 2.0 <= patch_mm <= 100.0):
        raise ChartError(f"`patch_mm` must lie in [2, 100] mm, got {patch_mm:g}")
    vol = chart_volume(chart, inks, patch_mm)
    rgb = predict_rgb(chart, inks)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    job = RunDir.create(out / JOB_DIR)
    paths = {"job": job.save_volume(vol)}
    job.remove_stale()  # an earlier chart's quantized print, slices and packages in the same folder
    paths["layout"] = write_png(out / LAYOUT_FILE, layout_picture(chart, rgb))
    paths["chart"] = write_cgats(out / CHART_FILE, chart.table(header=header))
    return paths
