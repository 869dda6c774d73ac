"""Why the print differs from its mixture, variant by variant: on one random sample of a run's texels, the continuous
mixture rendered once and each quantization variant's print rendered at the same spp, and per variant the printed -
continuous CIELAB difference split into its mean over the sample (the bias, ± its standard error) and its
noise-corrected spread (E|d|² minus both renders' Monte Carlo variance), plus the bias in bins of the texel's share
of each ink (where the print is lighter or less saturated than its mixture). A variant is
``METHOD[:UPSAMPLE][/ORDER][@DPI][+comp[1][tP]][~mm|~2d]`` (e.g. ``blue-noise``, ``blue-noise@1200x600x1881`` for a
printer grid twice as fine in every axis, ``random``, ``blue-noise/tint-first`` with the inks' bands in that
``Quantization.ink_order``, ``blue-noise+comp`` with the shares pre-compensated with the pair factors (``+comp1``: each
ink's factor against the base alone, what ``--compensate`` does; ``t0.05``: tapered below a share of 0.05),
``blue-noise-columns`` (``thresholds.BlueNoiseColumns``: golden-ratio shifts of a 2D mask along depth),
``count-diffusion`` (``counts.CountDiffusion``: each optimisation voxel's counts error-diffused, ``~shellsN`` with
the error kept within N depth shells under the surface), ``blue-noise~mm`` with a blue-noise array whose energy is
isotropic in mm rather than in printer voxels (and
``blue-noise-columns~mm`` with such a 2D mask), ``~2d`` with
2D blue-noise layers, ``layered_tile``): if the bias shrinks on a finer grid, it comes from the size of the printer
voxels (the grains of one ink absorb less than the same ink spread through the mixture), not from the dither's
order. Writes the entry NAME of experiments/results/halftone_cause.json.

    .venv/bin/python experiments/halftone_cause.py NAME RUN VARIANT [VARIANT ...] [--texels 1500] [--spp 512]

Compensations are measured (and cached) outside the timed part.
"""

import argparse
import contextlib
import sys
import time
from pathlib import Path
from unittest import mock

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import printed_refine  # noqa: E402
from common import add_study_entry, machine, provenance  # noqa: E402

from inkopt.color import linear_to_lab  # noqa: E402
from inkopt.evaluation.noise import lab_covariance  # noqa: E402
from inkopt.evaluation.printed import PrintedRenderer  # noqa: E402
from inkopt.model import Quantization  # noqa: E402
from inkopt.printing import counts, thresholds  # noqa: E402
from inkopt.printing.compensate import share_compensation  # noqa: E402
from inkopt.printing.dither import BLUE_NOISE_SHAPE, BLUE_NOISE_SIGMA, void_and_cluster  # noqa: E402
from inkopt.printing.grid import PrinterGrid  # noqa: E402
from inkopt.printing.quantize import quantize_volume  # noqa: E402
from inkopt.render import Renderer  # noqa: E402
from inkopt.rundir import RunDir  # noqa: E402
from inkopt.units import parse_dpi  # noqa: E402

SEED = 2**62 + 7
SHARE_EDGES = [0.0, 0.01, 0.03, 0.05, 0.15, 0.3, 0.5, 1.01]


def physical_tile(q: Quantization) -> np.ndarray:
    """A blue-noise threshold array whose void-and-cluster energy is isotropic in mm on ``q``'s printer voxels: per
    axis sigma = 1.5 x (the voxels' geometric mean size) / (the axis's voxel size). 32^3 for blue noise; for the
    columns' dither (``blue-noise-columns``) a 2D mask (y, x) of 64 voxels along the finer axis and as many mm along
    the other (32 x 64 at 600 x 300 DPI), float32 in (0, 1)."""
    vp = PrinterGrid.of((1, 1, 1), (1.0, 1.0, 1.0), q).voxel_mm[::-1]  # (z, y, x) mm
    if q.method == "blue-noise-columns":
        vp = vp[1:]
        shape = tuple(int(round(64 * vp.min() / v)) for v in vp)
    else:
        shape = BLUE_NOISE_SHAPE
    ranks = void_and_cluster(shape, tuple(BLUE_NOISE_SIGMA * np.prod(vp) ** (1 / len(vp)) / vp))
    return ((ranks.astype(np.float64) + 0.5) / ranks.size).astype(np.float32)


def layered_tile() -> np.ndarray:
    """A 32^3 threshold array of 2D blue-noise layers (void-and-cluster in (y, x), one seed per layer): every
    printer layer, the top face's slice, is blue noise of its own, the layers independent of each other."""
    z, y, x = BLUE_NOISE_SHAPE
    ranks = np.stack([void_and_cluster((y, x), seed=k) for k in range(z)])
    return ((ranks.astype(np.float64) + 0.5) / (y * x)).astype(np.float32)


def quantization(spec: str) -> Quantization:
    """``METHOD[:UPSAMPLE][@DPI][+comp[1][tP]][~mm]`` -> the settings (``+comp...``: shares compensated,
    ``printing.compensate``; ``~mm`` and ``~2d``, read by ``main``: ``physical_tile``, ``layered_tile``)."""
    spec = spec.partition("~shells")[0].replace("~mm", "").replace("~2d", "")
    spec, plus, _ = spec.partition("+comp")  # its model's variant: ``printed_refine.quantization``
    head, _, dpi = spec.partition("@")
    head, _, order = head.partition("/")
    method, _, up = head.partition(":")
    dpi = parse_dpi(dpi) if dpi else None
    return Quantization(method, 0, dpi, up or "nearest", order or "lightness", compensate=bool(plus))


def stats(d_lab: np.ndarray, noise_lab: np.ndarray) -> dict:
    """Bias (mean ΔL*, Δa*, Δb* and the standard error of ΔL*) and noise-corrected spread of (S, 3) differences
    (``noise_lab`` (S, 3): both renders' Monte Carlo variance per channel), in all and per channel (``spread_lab``:
    L*, a*, b* less their bias; the grain each channel carries)."""
    noise = noise_lab.sum(1)
    mean = d_lab.mean(0)
    se = d_lab.std(0) / np.sqrt(len(d_lab))
    power = np.sum(d_lab * d_lab, 1) - noise
    return {
        "texels": len(d_lab),
        "mean_dL": float(mean[0]),
        "mean_da": float(mean[1]),
        "mean_db": float(mean[2]),
        "se_dL": float(se[0]),
        "se_db": float(se[2]),
        "bias_dE76": float(np.linalg.norm(mean)),
        "rms_corrected": float(np.sqrt(max(power.mean(), 0.0))),
        "rms_corrected_less_bias": float(np.sqrt(max(power.mean() - mean @ mean, 0.0))),
        "spread_lab": [float(np.sqrt(max(v, 0.0))) for v in channel_power(d_lab, noise_lab) - mean * mean],
    }


def channel_power(d_lab: np.ndarray, noise_lab: np.ndarray) -> np.ndarray:
    """(3,) the noise-corrected mean square of each CIELAB channel of the (S, 3) differences, ``noise_lab`` (S, 3)
    both renders' Monte Carlo variance per channel."""
    return np.mean(d_lab * d_lab - noise_lab, 0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    ap.add_argument("run")
    ap.add_argument("variants", nargs="+")
    ap.add_argument("--texels", type=int, default=1500)
    ap.add_argument("--spp", type=int, default=512)
    ap.add_argument("--threads", type=int, default=None)
    a = ap.parse_args()
    d = RunDir(a.run)
    rec, vol = d.load_scene(), d.load_volume()
    pick = np.sort(np.random.default_rng(0).choice(len(rec.texels), min(a.texels, len(rec.texels)), replace=False))
    t0 = time.perf_counter()
    cont = Renderer(vol, a.threads).render(rec.texels.subset(pick), a.spp, SEED)
    c_rgb, c_var = cont.rgb.astype(np.float64), cont.var_mean.astype(np.float64)
    entry = {**provenance(), "run": a.run, "texels": len(pick), "spp": a.spp, "continuous_seconds": 0.0}
    entry["continuous_seconds"] = time.perf_counter() - t0
    mix = np.asarray(vol.mixture, np.float32)
    vox = rec.texels.subset(pick).voxel.astype(np.int64)
    here = mix[vox[:, 0], vox[:, 1], vox[:, 2]]
    entry["variants"] = {}
    for spec in a.variants:
        q = quantization(spec)
        if q.compensate:
            share_compensation(vol.inks, q, vol.g, vol.ior, a.threads, print)
        tile = physical_tile(q) if "~mm" in spec else layered_tile() if "~2d" in spec else None
        t0 = time.perf_counter()
        variant = printed_refine.compensation_variant(printed_refine.quantization(spec.split("~")[0])[1])
        own = mock.patch.object(thresholds, "load_blue_noise", lambda *_, t=tile: t) if tile is not None else None
        _, shells, n = spec.partition("~shells")  # ``CountDiffusion.shells`` for this variant
        depth = mock.patch.object(counts.CountDiffusion, "shells", int(n)) if shells else contextlib.nullcontext()
        with own or contextlib.nullcontext(), variant, depth:
            labels = quantize_volume(vol, q)
        printer = PrintedRenderer(labels, rec.texels, vol.voxel_mm, rec.kind, a.threads, None, [pick])
        printer.use(labels)
        p_rgb, p_var, _ = printer(a.spp, SEED + 1)
        d_lab = linear_to_lab(p_rgb) - linear_to_lab(c_rgb)
        noise = np.diagonal(lab_covariance(c_rgb, c_var) + lab_covariance(p_rgb, p_var), axis1=1, axis2=2)
        row = {"seconds": time.perf_counter() - t0, "printer_shape": list(labels.shape), "all": stats(d_lab, noise)}
        for i, ink in enumerate(vol.inks.names):
            bins = []
            for lo, hi in zip(SHARE_EDGES[:-1], SHARE_EDGES[1:]):
                m = (here[:, i] >= lo) & (here[:, i] < hi)
                if m.sum() >= 10:
                    bins.append({"lo": lo, "hi": hi, **stats(d_lab[m], noise[m])})
            row[f"share_{ink}"] = bins
        entry["variants"][spec] = row
        print(spec, {k: np.round(v, 3).tolist() for k, v in row["all"].items()}, f"{row['seconds']:.0f} s", flush=True)
        del labels, printer
    entry.update(machine())
    add_study_entry("halftone_cause.json", a.name, entry)


if __name__ == "__main__":
    main()
