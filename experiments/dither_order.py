"""The inks' order in the blue-noise dither, measured without rendering: a run's mixture dithered with the inks in
index order and lightest first (``printing.dither.lightness_order``), and for comparison by error diffusion and by
random draws; each printer voxel given its ink's thick-layer luminance (``dither.thick_layer_reflectance``), the
halftone's lightness error low-passed as scattering does: the RMS difference between the Gaussian-filtered (0.1
mm) luminance of the labels and of the nearest-upsampled mixture, over the printer voxels within 0.2 mm of the
outside. Writes the entry NAME of experiments/results/dither_order.json.

    .venv/bin/python experiments/dither_order.py NAME RUN [--layers LO:HI]

``--layers``: only those optimisation layers (z), for a big object whose printer grid does not fit in memory whole
(the cut faces count as surface for both orders alike).
"""

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import add_study_entry, machine, provenance  # noqa: E402

from inkopt.model import EMPTY, Quantization  # noqa: E402
from inkopt.printing.dither import LUMINANCE, thick_layer_reflectance  # noqa: E402
from inkopt.printing.grid import _enclosing  # noqa: E402
from inkopt.printing.quantize import MixtureLayers, quantize  # noqa: E402
from inkopt.rundir import RunDir  # noqa: E402

SIGMA_MM = 0.1
NEAR_MM = 0.2


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    ap.add_argument("run")
    ap.add_argument("--layers", default=None)
    a = ap.parse_args()
    vol = RunDir(a.run).load_volume()
    mix, inside = np.asarray(vol.mixture, np.float32), vol.inside.dense()
    if a.layers:
        lo, hi = (int(v) for v in a.layers.split(":"))
        mix, inside = mix[lo:hi], inside[lo:hi]
    lum = (thick_layer_reflectance(vol.inks, vol.g, vol.ior) @ LUMINANCE).astype(np.float32)
    entry = {**provenance(), "run": a.run, "layers": a.layers, "sigma_mm": SIGMA_MM, "near_mm": NEAR_MM}
    entry["ink_luminance"] = dict(zip(vol.inks.names, lum.tolist()))
    ref = None
    cases = (
        ("index", "blue-noise", "index"),
        ("lightness", "blue-noise", "lightness"),
        ("error-diffusion", "error-diffusion", "index"),
        ("random", "random", "index"),
    )
    layers = MixtureLayers(mix, vol.voxel_mm, inside, vol.inks, vol.g, vol.ior)
    for name, method, ink_order in cases:
        lab, vp = quantize(layers, Quantization(method, 0, ink_order=ink_order))
        filled = lab != EMPTY
        sig = SIGMA_MM / np.asarray(vp)[::-1]
        if ref is None:  # the mixture's luminance on the printer grid, filtered; the voxels near the surface
            (Z, Y, X), (nz, ny, nx), vo = lab.shape, mix.shape[:3], vol.voxel_mm
            iz, iy, ix = (_enclosing(n, vp[k], m, vo[k]) for n, m, k in ((Z, nz, 2), (Y, ny, 1), (X, nx, 0)))
            m_lum = (mix / np.maximum(mix.sum(-1, keepdims=True), 1e-12)) @ lum
            weight = np.maximum(ndimage.gaussian_filter(filled.astype(np.float32), sig), 1e-6)
            ref = ndimage.gaussian_filter(np.where(filled, m_lum[iz][:, iy][:, :, ix], 0), sig) / weight
            near = filled & (ndimage.distance_transform_edt(filled, sampling=np.asarray(vp)[::-1]) < NEAR_MM)
            del m_lum
        low = ndimage.gaussian_filter(np.where(filled, lum[np.minimum(lab, len(lum) - 1)], 0), sig) / weight
        entry[name] = float(np.sqrt(np.mean((low - ref)[near] ** 2)))
        print(f"{name} ({method}): RMS low-passed luminance error {entry[name]:.5f}", flush=True)
    entry["ratio"] = entry["lightness"] / entry["index"]
    entry["voxels"] = int(near.sum())
    print(f"lightness / index: {entry['ratio']:.3f} over {entry['voxels']} printer voxels")
    entry.update(machine())
    add_study_entry("dither_order.json", a.name, entry)


if __name__ == "__main__":
    main()
