"""Which way a result misses its target: the signed mean CIELAB offset of each run's continuous prediction from its
target, and the inks' mean shares by depth below the surface (docs/quality.md, "The duck's margin at 20 mm").

    nice -n 5 .venv/bin/python experiments/colour_offsets.py NAME LABEL=RUN [LABEL=RUN ...]

RUN is an optimisation run folder with ``predictions.npz`` of every texel (what the run's final figures rendered;
an evaluation that samples texels leaves it). Per run the entry NAME of experiments/results/colour_offsets.json
holds: the texels and the prediction's samples per texel; the target's and the prediction's mean L*, a*, b*; the
mean signed offset (prediction − target) in L*, a*, b*, over all texels and over the target's most common colour
(texels within ΔE76 10 of the target's median); the mean ΔE76 of the prediction (not corrected for its render
noise; beside it the noise-corrected one of evaluation.json, or of report.json for a run not evaluated); and the
mean ink shares of the inside voxels by distance to the outside (mm, Euclidean distance transform of the inside
mask, bins ``DEPTHS``).
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from scipy.ndimage import distance_transform_edt

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import add_study_entry, machine, provenance  # noqa: E402

#: depth bins (mm from the outside) of the ink shares
DEPTHS = (0.0, 0.25, 0.5, 1.0, 2.0, 4.0, np.inf)


def lab_offsets(run: Path) -> dict:
    """The prediction's and target's mean CIELAB and their signed mean offsets (module docstring)."""
    from inkopt.color import linear_to_lab

    pred = np.load(run / "predictions.npz")
    target = np.load(run / "scene.npz")["target_rgb"]
    rgb = pred["rgb_continuous"]
    if rgb.shape != target.shape:
        raise SystemExit(f"{run}: predictions.npz holds {len(rgb)} texels of {len(target)}: a sampled evaluation")
    lt, lp = linear_to_lab(target), linear_to_lab(rgb)
    d = lp - lt
    main = np.linalg.norm(lt - np.median(lt, axis=0), axis=1) < 10.0
    evaluated = (run / "evaluation.json").is_file()
    figures = json.loads((run / ("evaluation.json" if evaluated else "report.json")).read_text())
    corrected = (figures["continuous"] if evaluated else figures)["delta_e76_mean_corrected"]
    return {
        "texels": len(lt),
        "spp": int(pred["spp"][0]),
        "target_lab": lt.mean(0).tolist(),
        "prediction_lab": lp.mean(0).tolist(),
        "offset_lab": d.mean(0).tolist(),
        "main_colour_share": float(main.mean()),
        "main_colour_lab": lt[main].mean(0).tolist(),
        "main_colour_offset_lab": d[main].mean(0).tolist(),
        "delta_e76_mean": float(np.linalg.norm(d, axis=1).mean()),
        "delta_e76_mean_corrected": corrected,
        "delta_e76_mean_corrected_of": "evaluation.json" if evaluated else "report.json",
    }


def shares_by_depth(run: Path) -> dict:
    """Mean ink shares of the inside voxels by depth bin: {"bins_mm": [[lo, hi], ...], "voxels", "shares"}."""
    from inkopt.model import Volume

    vol = Volume.load(run / "volume.npz")
    inside = np.asarray(vol.inside_mask())
    mix = np.asarray(vol.mixture)[inside]
    depth = distance_transform_edt(inside, sampling=vol.voxel_mm)[inside]
    bins, voxels, shares = [], [], []
    for lo, hi in zip(DEPTHS[:-1], DEPTHS[1:]):
        sel = (depth > lo) & (depth <= hi)
        if sel.any():
            bins.append([lo, None if np.isinf(hi) else hi])
            voxels.append(int(sel.sum()))
            shares.append(mix[sel].mean(0, dtype=np.float64).round(4).tolist())
    return {"inks": list(vol.inks.names), "bins_mm": bins, "voxels": voxels, "shares": shares}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    ap.add_argument("runs", nargs="+", help="LABEL=RUN")
    a = ap.parse_args()
    entry = {**provenance(), "runs": {}}
    for item in a.runs:
        label, _, run = item.partition("=")
        run = Path(run)
        entry["runs"][label] = {"run": str(run), **lab_offsets(run), "depth": shares_by_depth(run)}
        r = entry["runs"][label]
        print(
            f"{label}: ΔE76 {r['delta_e76_mean']:.2f} ({r['delta_e76_mean_corrected']:.2f} corrected), "
            f"offset L*a*b* {np.round(r['offset_lab'], 2).tolist()}, target {np.round(r['target_lab'], 1).tolist()}"
        )
        for b, n, s in zip(r["depth"]["bins_mm"], r["depth"]["voxels"], r["depth"]["shares"]):
            print(f"   depth {b} mm: {n} voxels, shares {s}")
    entry.update(machine())
    add_study_entry("colour_offsets.json", a.name, entry)


if __name__ == "__main__":
    main()
