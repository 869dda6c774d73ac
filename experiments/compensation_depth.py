"""Does the package effect depend on how deep the tint lies? The shipped compensation (``printing.compensate``) fits
one factor k per ink on patches that hold the ink through their whole 2.5 mm; a result's tint often lies in a thin
layer at the surface over white (Spot's cream: a few percent of yellow in white). If a thin layer's dithered tint
looks less diluted than a thick one's, the compensation overshoots there (the b* overshoot of docs/quality.md, "The
compensation on the suite's 20 mm cells").

For each layer thickness L and share p: a periodic patch (32 x 32 printer voxels, 2.5 mm thick) whose top L holds
the ink at share p in white and whose rest is white, dithered by the default quantization on the printer grid (the
rest's labels all white), against continuous patches of the same layering at the compensation's continuous shares;
the dithered colour's nearest point on that curve is its effective share, and k is fitted per L as the shipped
factors are (``compensate.fit_k``).

    .venv/bin/python experiments/compensation_depth.py [--inks yellow,magenta] [--layers 0.08,0.16,0.3,0.6,1.2,2.5]
        [--shares 0.02,0.05,0.1,0.2,0.4] [--name NAME]

Writes experiments/results/compensation_depth.json.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "bench"))
from common import add_study_entry, machine, provenance  # noqa: E402

from inkopt.color import linear_to_lab  # noqa: E402
from inkopt.model import InkTable, Quantization, Volume  # noqa: E402
from inkopt.printing.compensate import (  # noqa: E402
    CONTINUOUS_SHARES,
    PATCH_LATERAL,
    PATCH_MM,
    PATCH_SPP,
    _curve_share,
    _top_colour,
    fit_k,
    share_compensation,
)
from inkopt.printing.dithers import band_order, dither_class  # noqa: E402
from inkopt.printing.grid import PrinterGrid, upsampler_class  # noqa: E402
from inkopt.printing.layers import CumulativeLayers, MixtureLayers  # noqa: E402

RESULT = "compensation_depth.json"


def layered(row: np.ndarray, white: int, layers: int, nz: int, lateral: int) -> np.ndarray:
    """(nz, lateral, lateral, N) float32: ``row`` in the top ``layers`` z-planes (+z, the last), white below."""
    mix = np.zeros((nz, lateral, lateral, len(row)), np.float32)
    mix[..., white] = 1.0
    mix[nz - layers :] = row
    return mix


def dithered_patch(row, white: int, layer_mm: float, inks: InkTable, q: Quantization) -> Volume:
    """The dithered layered patch as a labels volume (``compensate.patch_labels`` with the tint in the top layer)."""
    vp = PrinterGrid.of((1, 1, 1), (1.0, 1.0, 1.0), q).voxel_mm
    nz = max(1, int(round(PATCH_MM / vp[2])))
    top = min(nz, max(1, int(round(layer_mm / vp[2]))))
    mix = layered(np.asarray(row, np.float32), white, top, nz, PATCH_LATERAL)
    grid = PrinterGrid.of(mix.shape[:3], vp, q)
    order = band_order(q, inks, inks.g, 1.5)
    dither = dither_class(q.method)(q, grid, len(inks), order)
    layers = CumulativeLayers(MixtureLayers(mix, vp, None, inks, inks.g, 1.5), upsampler_class(q.upsample)(grid), order)
    labels = np.stack([dither.layer(k, *layers.printer_layer(k)) for k in range(grid.shape[0])])
    return Volume.from_labels(grid.voxel_mm, labels, inks, g=inks.g, ior=1.5, boundary="periodic-xy")


def continuous_curve(i: int, white: int, layer_mm: float, inks: InkTable, dz: float, seed: int):
    """CIELAB (K, 3) and ΔE76 standard errors (K,) of continuous layered patches at ``CONTINUOUS_SHARES``."""
    nz = max(1, int(round(PATCH_MM / dz)))
    top = min(nz, max(1, int(round(layer_mm / dz))))
    lab, err = [], []
    for j, p in enumerate(CONTINUOUS_SHARES):
        row = np.zeros(len(inks), np.float32)
        row[i], row[white] = p, 1.0 - p
        vol = Volume.from_mixture(
            (0.25, 0.25, dz), layered(row, white, top, nz, 8), inks, g=inks.g, ior=1.5, boundary="periodic-xy"
        )
        rgb, se = _top_colour(vol, 4 * PATCH_SPP, seed + j, None)
        lab.append(linear_to_lab(rgb))
        err.append(se)
    return np.array(lab), np.array(err)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--inks", default="yellow,magenta")
    ap.add_argument("--layers", default="0.08,0.16,0.3,0.6,1.2,2.5", help="tinted layer thicknesses, mm")
    ap.add_argument("--shares", default="0.02,0.05,0.1,0.2,0.4")
    ap.add_argument("--name", default="vero-cmykw")
    args = ap.parse_args()
    inks = InkTable.parse("vero-cmykw")
    q = Quantization("blue-noise")
    white = inks.names.index("white")
    dz = PrinterGrid.of((1, 1, 1), (1.0, 1.0, 1.0), q).voxel_mm[2]
    shipped = share_compensation(inks, q, inks.g, 1.5)
    shares = np.array([float(s) for s in args.shares.split(",")])
    entry = {"printer_layer_mm": float(dz), "shares": shares.tolist(), "inks": {}}
    seed = 1
    for name in args.inks.split(","):
        i = inks.names.index(name)
        rows = []
        for layer_mm in (float(x) for x in args.layers.split(",")):
            curve, curve_se = continuous_curve(i, white, layer_mm, inks, dz, seed)
            seed += len(CONTINUOUS_SHARES)
            eff, eff_se = [], []
            for p in shares:
                row = np.zeros(len(inks))
                row[i], row[white] = p, 1.0 - p
                rgb, se = _top_colour(dithered_patch(row, white, layer_mm, inks, q), PATCH_SPP, seed, None)
                seed += 1
                e, slope, j = _curve_share(linear_to_lab(rgb), curve, np.array(CONTINUOUS_SHARES))
                eff.append(e)
                eff_se.append(float(np.hypot(se, curve_se[j : j + 2].mean()) / max(slope, 1e-9)))
            k, k_se = fit_k(shares, np.array(eff), np.array(eff_se))
            rows.append({"layer_mm": layer_mm, "effective": eff, "stderr": eff_se, "k": k, "k_stderr": k_se})
            ratios = ", ".join(f"{p:g}: {e / p:.3f}" for p, e in zip(shares, eff))
            print(f"{name} L={layer_mm:g} mm  k {k:.3f} ± {k_se:.3f}  (effective / nominal: {ratios})", flush=True)
        entry["inks"][name] = {"shipped_k": float(shipped.k[i]), "layers": rows}
        print(f"{name}: shipped k {shipped.k[i]:.3f}")
    entry.update(machine=machine(), **provenance())
    add_study_entry(RESULT, args.name, entry)


if __name__ == "__main__":
    main()
