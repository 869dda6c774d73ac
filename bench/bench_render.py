"""Forward-render benchmark on the reference slab (top face, 16 spp by default).

    .venv/bin/python bench/bench_render.py [--spp 16] [--repeats 3] [--threads N]

Prints and writes bench/results/render.json (render_threads<N>.json with --threads N): texel-samples/s
(one texel-sample = 3 monochromatic paths), paths/s, collision events/s (best of the repeats), with the
machine's load for context.
"""

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine, reference_slab, write  # noqa: E402

from inkopt.model import Texels  # noqa: E402
from inkopt.render import Renderer  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int)
    a = ap.parse_args()
    vol = reference_slab()
    tex = Texels.for_volume(vol, ["top"])
    r = Renderer(vol, a.threads)
    runs = [r.render(tex, a.spp, seed=i) for i in range(a.repeats)]
    best = min(runs, key=lambda x: x.seconds)
    out = {
        "volume": "177x118x30 voxels, 300 DPI, random CMYKW with 50 % white, top face",
        "texels": len(tex),
        "spp": a.spp,
        "threads": r.threads,
        "seconds": best.seconds,
        "texel_samples_per_s": len(tex) * a.spp / best.seconds,
        "paths_per_s": best.paths / best.seconds,
        "events_per_s": best.events / best.seconds,
        "events_per_path": best.events / best.paths,
        "all_seconds": [x.seconds for x in runs],
        **machine(),
    }
    print(
        f"{out['texels']} texels x {a.spp} spp on {r.threads} threads: {best.seconds:.3f} s, "
        f"{out['texel_samples_per_s'] / 1e6:.2f} M texel-samples/s, {out['events_per_s'] / 1e6:.1f} M events/s"
    )
    print("wrote", write("render.json" if a.threads is None else f"render_threads{a.threads}.json", out))


if __name__ == "__main__":
    main()
