"""Each quantization method's ink-count error per optimisation voxel, without rendering: per optimisation voxel, the
ink fractions among the printer voxels it encloses (``printing.quantize.ink_fractions``) minus its mixture, and that
error low-passed over neighbouring optimisation voxels (a Gaussian of ``--sigma`` voxels, normalised over the inside
voxels), each as the RMS over the run's texel voxels (the surface voxels the texels sit in) of the error's norm over
the inks (a share, 0 to sqrt(2)). Where the optimiser's mixture changes from voxel to voxel, a dither that rounds each
voxel's counts on its own leaves an error that does not cancel between neighbours; one that carries it to them
leaves a smaller low-passed error. Writes the entry NAME of experiments/results/count_error.json.

    .venv/bin/python experiments/count_error.py NAME RUN METHOD [METHOD ...] [--sigma 1.0] [--down F] [--shells S]

``--down`` and ``--shells``: ``counts.CountDiffusion.down`` (the fraction of each residual carried to the next
optimisation layer) and ``.shells`` (the depth shells the error stays in) for this run, to measure them.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import add_study_entry, machine, provenance  # noqa: E402

from inkopt.model import Quantization  # noqa: E402
from inkopt.printing.counts import CountDiffusion  # noqa: E402
from inkopt.printing.quantize import ink_fractions, quantize  # noqa: E402
from inkopt.rundir import RunDir  # noqa: E402


def lowpass(err: np.ndarray, inside: np.ndarray, sigma: float) -> np.ndarray:
    """(z, y, x, N) error zero outside, Gaussian-filtered over the inside voxels (normalised by the filtered inside
    weight, so the outside does not pull it to zero)."""
    w = gaussian_filter(inside.astype(np.float32), sigma, mode="constant")
    out = np.empty_like(err)
    for n in range(err.shape[3]):
        out[..., n] = gaussian_filter(err[..., n], sigma, mode="constant") / np.maximum(w, 1e-6)
    return out


def method_row(vol, mix, inside, vox, method: str, sigma: float) -> dict:
    """The count error of ``method`` (seed 0, nearest upsampling) at the texel voxels ``vox`` (V, 3)."""
    t0 = time.perf_counter()
    labels, vp = quantize(vol, Quantization(method, 0))
    seconds = time.perf_counter() - t0
    frac, _ = ink_fractions(labels, mix.shape[3], mix.shape[:3], vol.voxel_mm, vp)
    del labels
    err = np.where(inside[..., None], frac - mix, 0.0).astype(np.float32)
    del frac
    low = lowpass(err, inside, sigma)
    at = (vox[:, 0], vox[:, 1], vox[:, 2])
    norm = np.linalg.norm(err[at], axis=1)
    low_norm = np.linalg.norm(low[at], axis=1)
    return {
        "seconds": seconds,
        "rms_voxel": float(np.sqrt(np.mean(norm**2))),
        "rms_lowpass": float(np.sqrt(np.mean(low_norm**2))),
        "rms_voxel_inside": float(np.sqrt(np.mean(np.sum(err[inside] ** 2, 1)))),
        "rms_lowpass_inside": float(np.sqrt(np.mean(np.sum(low[inside] ** 2, 1)))),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    ap.add_argument("run")
    ap.add_argument("methods", nargs="+")
    ap.add_argument("--sigma", type=float, default=1.0)
    ap.add_argument("--down", type=float, default=None)
    ap.add_argument("--shells", type=int, default=None)
    a = ap.parse_args()
    if a.down is not None:
        CountDiffusion.down = a.down
    if a.shells is not None:
        CountDiffusion.shells = a.shells
    d = RunDir(a.run)
    rec, vol = d.load_scene(), d.load_volume()
    mix = np.asarray(vol.mixture, np.float64)
    inside = np.ones(mix.shape[:3], bool) if vol.inside is None else np.asarray(vol.inside, bool)
    mix = np.where(inside[..., None], mix / np.maximum(mix.sum(3, keepdims=True), 1e-12), 0.0)
    vox = np.unique(rec.texels.voxel.astype(np.int64), axis=0)
    entry = {**provenance(), "run": a.run, "sigma_voxels": a.sigma, "texel_voxels": len(vox)}
    entry["down"], entry["shells"] = CountDiffusion.down, CountDiffusion.shells
    entry["methods"] = {}
    for m in a.methods:
        entry["methods"][m] = row = method_row(vol, mix, inside, vox, m, a.sigma)
        print(m, {k: round(v, 4) for k, v in row.items()}, flush=True)
    entry.update(machine())
    add_study_entry("count_error.json", a.name, entry)


if __name__ == "__main__":
    main()
