"""Where the halftone's cost comes from: on a random sample of a run's texels, the continuous mixture and its
blue-noise print (``inkopt quantize``'s default) rendered at high spp, and per texel the printed - continuous CIELAB
difference split into its mean over the sample (a bias: the print lighter or darker than its mixture) and its
noise-corrected spread (the halftone's texel-to-texel error: E|d|² minus the two renders' Monte Carlo variance),
each in bins of what the halftone might depend on: the mixture's voxel-to-voxel variation about the texel (the RMS
share difference to its 26 neighbours inside), the number of inks mixed at the texel's voxel (share >= 5 %), and the
texel's share of the darkest ink. Writes the entry NAME of experiments/results/halftone_gap.json.

    .venv/bin/python experiments/halftone_gap.py NAME RUN [--texels 1500] [--spp 512] [--threads T]
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import add_study_entry, machine, provenance  # noqa: E402

from inkopt.color import linear_to_lab  # noqa: E402
from inkopt.evaluation.noise import lab_covariance  # noqa: E402
from inkopt.evaluation.printed import PrintedRenderer  # noqa: E402
from inkopt.model import Quantization  # noqa: E402
from inkopt.printing.dither import lightness_order  # noqa: E402
from inkopt.printing.quantize import quantize_volume  # noqa: E402
from inkopt.render import Renderer  # noqa: E402
from inkopt.rundir import RunDir  # noqa: E402

SEED = 2**62 + 7


def neighbour_variation(mix: np.ndarray, inside: np.ndarray, voxels: np.ndarray) -> np.ndarray:
    """RMS over the inside 26-neighbours of each voxel (zyx (S, 3)) of the L2 mixture difference to it."""
    Z, Y, X = inside.shape
    out = np.zeros(len(voxels))
    count = np.zeros(len(voxels))
    for dz in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dz == dy == dx == 0:
                    continue
                n = voxels + [dz, dy, dx]
                ok = np.all((n >= 0) & (n < [Z, Y, X]), 1)
                ok[ok] = inside[n[ok, 0], n[ok, 1], n[ok, 2]]
                d = mix[n[ok, 0], n[ok, 1], n[ok, 2]] - mix[voxels[ok, 0], voxels[ok, 1], voxels[ok, 2]]
                out[ok] += np.sum(d * d, 1)
                count[ok] += 1
    return np.sqrt(out / np.maximum(count, 1))


def binned(feature: np.ndarray, edges, d_lab: np.ndarray, power: np.ndarray) -> list[dict]:
    """Per bin of ``feature``: texels, mean ΔL*, Δa*, Δb* (printed - continuous) and the noise-corrected RMS |ΔLab|."""
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (feature >= lo) & (feature < hi)
        if m.sum() < 10:
            continue
        mean = d_lab[m].mean(0)
        rows.append(
            {
                "lo": float(lo),
                "hi": float(hi),
                "texels": int(m.sum()),
                "mean_dL": float(mean[0]),
                "mean_da": float(mean[1]),
                "mean_db": float(mean[2]),
                "se_dL": float(d_lab[m, 0].std() / np.sqrt(m.sum())),
                "rms_corrected": float(np.sqrt(max(power[m].mean(), 0.0))),
            }
        )
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    ap.add_argument("run")
    ap.add_argument("--texels", type=int, default=1500)
    ap.add_argument("--spp", type=int, default=512)
    ap.add_argument("--threads", type=int, default=None)
    a = ap.parse_args()
    d = RunDir(a.run)
    rec, vol = d.load_scene(), d.load_volume()
    pick = np.sort(np.random.default_rng(0).choice(len(rec.texels), min(a.texels, len(rec.texels)), replace=False))
    tex = rec.texels.subset(pick)
    t0 = time.perf_counter()
    cont = Renderer(vol, a.threads).render(tex, a.spp, SEED)
    labels = quantize_volume(vol, Quantization("blue-noise"))
    printer = PrintedRenderer(labels, rec.texels, vol.voxel_mm, rec.kind, a.threads, None, [pick])
    printer.use(labels)
    p_rgb, p_var, _ = printer(a.spp, SEED + 1)
    seconds = time.perf_counter() - t0
    c_rgb, c_var = cont.rgb.astype(np.float64), cont.var_mean.astype(np.float64)
    d_lab = linear_to_lab(p_rgb) - linear_to_lab(c_rgb)
    noise = np.trace(lab_covariance(c_rgb, c_var) + lab_covariance(p_rgb, p_var), axis1=1, axis2=2)
    power = np.sum(d_lab * d_lab, 1) - noise
    mix = np.asarray(vol.mixture, np.float32)
    vox = tex.voxel.astype(np.int64)
    here = mix[vox[:, 0], vox[:, 1], vox[:, 2]]
    darkest = int(lightness_order(vol.inks, vol.g, vol.ior)[-1])
    feats = {
        "variation": (neighbour_variation(mix, vol.inside_mask(), vox), [0, 0.05, 0.1, 0.2, 0.3, 0.5, 2]),
        "inks": (np.sum(here >= 0.05, 1).astype(float), [0.5, 1.5, 2.5, 3.5, 4.5, 6]),
        "darkest_share": (here[:, darkest], [0, 0.02, 0.05, 0.1, 0.2, 0.4, 1.01]),
    }
    mean = d_lab.mean(0)
    entry = {**provenance(), "run": a.run, "texels": len(pick), "spp": a.spp, "render_seconds": seconds}
    entry["all"] = {
        "mean_dL": float(mean[0]),
        "mean_da": float(mean[1]),
        "mean_db": float(mean[2]),
        "se_dL": float(d_lab[:, 0].std() / np.sqrt(len(d_lab))),
        "rms_corrected": float(np.sqrt(max(power.mean(), 0.0))),
        "rms_of_bias": float(np.linalg.norm(mean)),
        "noise_rms": float(np.sqrt(noise.mean())),
    }
    print("all", {k: round(v, 3) for k, v in entry["all"].items()})
    for name, (f, edges) in feats.items():
        entry[name] = binned(f, edges, d_lab, power)
        for r in entry[name]:
            print(name, {k: round(v, 3) if isinstance(v, float) else v for k, v in r.items()})
    entry["darkest_ink"] = vol.inks.names[darkest]
    entry.update(machine())
    add_study_entry("halftone_gap.json", a.name, entry)


if __name__ == "__main__":
    main()
