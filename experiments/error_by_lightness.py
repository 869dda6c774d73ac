"""Where a Spot result's colour error is, against the extrusion baseline's mixture: the mean ΔE76 and ΔE2000 and the
mean lightness error ΔL* of the texels in bands of the target's lightness L* and chroma C*, each band's share of
the difference in mean ΔE2000 (band "all": every texel), from one render of each at equal spp and seeds (not
noise-corrected: both carry the noise of ``--spp`` samples). Writes the entry NAME of
experiments/results/error_by_lightness.json.

    .venv/bin/python experiments/error_by_lightness.py NAME RUN/volume.npz --height-mm 40 [--spp 64] [--threads 2]

The extrusion baseline here is the optimisation grid's mixture (``--init extrusion``), not ``inkopt evaluate``'s
printed one at printer resolution.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import add_study_entry, machine, provenance  # noqa: E402
from shell_compare import SPOT  # noqa: E402

from inkopt.color import delta_e76, delta_e2000, linear_to_lab  # noqa: E402
from inkopt.evaluation.baselines import baseline_mixture  # noqa: E402
from inkopt.model import InkTable  # noqa: E402
from inkopt.optim import Optimization, OptimizeConfig  # noqa: E402
from inkopt.scenes import build_scene  # noqa: E402
from inkopt.scenes.spec import MeshSpec  # noqa: E402

#: bands of the target's L* and C* (lower edge inclusive)
L_BANDS = (0, 30, 60, 80, 101)
C_BANDS = (0, 10, 30, 1000)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    ap.add_argument("volume")
    ap.add_argument("--height-mm", type=float, default=20.0)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    scene = build_scene(MeshSpec(SPOT, height_mm=a.height_mm), InkTable.parse("vero-cmykw"))

    def baseline(kind):
        return baseline_mixture(kind, scene.volume, scene.texels, scene.target_rgb, scene.fixed_share)

    target = linear_to_lab(scene.target_rgb)
    light, chroma = target[:, 0], np.hypot(target[:, 1], target[:, 2])
    bands = {f"L {lo}-{hi}": (light >= lo) & (light < hi) for lo, hi in zip(L_BANDS, L_BANDS[1:])}
    bands |= {f"C {lo}-{hi}": (chroma >= lo) & (chroma < hi) for lo, hi in zip(C_BANDS, C_BANDS[1:])}
    de2000 = {}
    entry = {**provenance(), "volume": a.volume, "height_mm": a.height_mm, "spp": a.spp, "texels": len(target)}
    for name, init in (("result", a.volume), ("extrusion", "extrusion")):
        cfg = OptimizeConfig(init=init, iterations=1).for_scene("mesh")
        run = Optimization(scene, cfg, threads=a.threads, baseline=baseline)
        lab = linear_to_lab(run.renderer().render(scene.texels, a.spp, 12345, cfg.include_specular).rgb)
        run.release_renderer()
        e76, e00 = delta_e76(lab, target), delta_e2000(lab, target)
        d_light = lab[:, 0] - light
        de2000[name] = e00
        bands_all = {"all": np.ones(len(target), bool)} | bands
        entry[name] = {
            band: {
                "share": float(m.mean()),
                "delta_e76": float(e76[m].mean()),
                "delta_e2000": float(e00[m].mean()),
                "delta_l": float(d_light[m].mean()),
            }
            for band, m in bands_all.items()
            if m.any()
        }
    diff = de2000["result"] - de2000["extrusion"]
    entry["delta_e2000_difference"] = {
        band: float(diff[m].sum() / len(diff)) for band, m in bands_all.items() if m.any()
    }
    entry.update(machine())
    for band in entry["result"]:
        r, e = entry["result"][band], entry["extrusion"][band]
        print(
            f"{band:10s} {r['share'] * 100:5.1f} %  result ΔE76 {r['delta_e76']:6.2f} ΔE2000 {r['delta_e2000']:6.2f} "
            f"ΔL* {r['delta_l']:+6.2f}  extrusion ΔE76 {e['delta_e76']:6.2f} ΔE2000 {e['delta_e2000']:6.2f} "
            f"ΔL* {e['delta_l']:+6.2f}  ΔE2000 difference {entry['delta_e2000_difference'][band]:+.3f}"
        )
    add_study_entry("error_by_lightness.json", a.name, entry)


if __name__ == "__main__":
    main()
