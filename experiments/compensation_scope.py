"""Where the share compensation applies: flat patches of a run's own surface mixtures, dithered as given and dithered
with each compensation variant, against the continuous patch of the same mixture. The compensation's factors were
fitted on patches of one ink in white; ``--compensate`` (``+comp1``) counts every other ink as white, ``+compw``
corrects each ink against the white share alone (no correction where there is no white). The mixtures are drawn from
the run's texels' voxels, in bins of their white share, so the patches say whether the package effect the factors
model is there in mixtures with little or no white. Writes the entry NAME of
experiments/results/compensation_scope.json.

    .venv/bin/python experiments/compensation_scope.py NAME RUN [--per-bin 4] [--variants +comp1,+compw]

Per patch: the ΔE76 of each dithered patch's top colour from the continuous patch's (both rendered with their own
seeds; ``compensate._top_colour``: 1024 top texels at 64 spp dithered, 64 at 256 spp continuous) ± its standard
error.
"""

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import printed_refine  # noqa: E402
from common import add_study_entry, machine, provenance  # noqa: E402

from inkopt.color import linear_to_lab  # noqa: E402
from inkopt.model import Quantization  # noqa: E402
from inkopt.printing import compensate as C  # noqa: E402
from inkopt.printing import quantize as Q  # noqa: E402
from inkopt.rundir import RunDir  # noqa: E402

WHITE_BINS = ((0.0, 0.01), (0.01, 0.2), (0.2, 0.6), (0.6, 1.01))  # the white share of a drawn mixture


def draw_rows(mix: np.ndarray, voxels: np.ndarray, white: int, per_bin: int, seed: int = 0) -> list[np.ndarray]:
    """``per_bin`` mixtures (N,) per ``WHITE_BINS`` bin drawn at random from the voxels ``voxels`` (k, 3) of
    ``mix`` (z, y, x, N)."""
    rows = mix[voxels[:, 0], voxels[:, 1], voxels[:, 2]].astype(np.float64)
    rng = np.random.default_rng(seed)
    out = []
    for lo, hi in WHITE_BINS:
        idx = np.flatnonzero((rows[:, white] >= lo) & (rows[:, white] < hi) & (rows.sum(1) > 0.99))
        out += [rows[i] for i in rng.choice(idx, min(per_bin, len(idx)), replace=False)]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    ap.add_argument("run")
    ap.add_argument("--per-bin", type=int, default=4)
    ap.add_argument("--variants", default="+comp1,+compw")
    ap.add_argument("--threads", type=int, default=None)
    a = ap.parse_args()
    d = RunDir(a.run)
    rec, vol = d.load_scene(), d.load_volume()
    q = Quantization("blue-noise")
    comp = C.share_compensation(vol.inks, replace_compensate(q), vol.g, vol.ior, a.threads, print)
    rows = draw_rows(np.asarray(vol.mixture), rec.texels.voxel.astype(np.int64), comp.base, a.per_bin)
    t0 = time.perf_counter()
    patches = []
    for m, row in enumerate(rows):
        seed = 1000 + 10 * m
        cont_rgb, cont_se = C._top_colour(C._mixture_patch(row, vol.inks, vol.g, vol.ior), 4 * C.PATCH_SPP, seed, None)
        cont = linear_to_lab(cont_rgb)
        out = {"row": row.tolist(), "white": float(row[comp.base])}
        for k, variant in enumerate(["none", *a.variants.split(",")]):
            given = row
            if variant != "none":
                with printed_refine.compensation_variant(printed_refine.quantization("blue-noise" + variant)[1]):
                    given = Q.share_compensation(vol.inks, replace_compensate(q), vol.g, vol.ior).apply(row)
            patch = C.patch_labels(given, vol.inks, q, vol.g, vol.ior)
            rgb, se = C._top_colour(patch, C.PATCH_SPP, seed + 1 + k, a.threads)
            out[variant] = {
                "delta_e76": float(np.linalg.norm(linear_to_lab(rgb) - cont)),
                "stderr": float(np.hypot(se, cont_se)),
            }
            out[variant]["delta_lab"] = (linear_to_lab(rgb) - cont).tolist()
        patches.append(out)
        print(f"white {out['white']:.2f}", {v: round(out[v]["delta_e76"], 2) for v in out if isinstance(out[v], dict)})
    entry = {**provenance(), "run": a.run, "seconds": time.perf_counter() - t0, "patches": patches}
    entry.update(machine())
    add_study_entry("compensation_scope.json", a.name, entry)


def replace_compensate(q: Quantization) -> Quantization:
    """``q`` asking for the compensation (the factors are looked up for its dither and grid)."""
    return replace(q, compensate=True)


if __name__ == "__main__":
    main()
