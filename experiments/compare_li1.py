"""Compare the paper's biased one-pass L_i = 1 gradient with the unbiased path-replay gradient.

    .venv/bin/python experiments/compare_li1.py

On a random CMYKW slab (and on an all-white start) with a random positive adjoint on the top face: cosine
similarity of the sigma_a gradients and of the mixture gradients, ratio of norms, and cost of each pass.
Writes experiments/results/li1_vs_replay.json.
"""

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import machine  # noqa: E402
from common import write_study as write

from inkopt.model import InkTable, Texels, Volume, mix_grad  # noqa: E402
from inkopt.render import Renderer  # noqa: E402


def cos(a, b):
    return float(np.sum(a * b) / np.sqrt(np.sum(a * a) * np.sum(b * b)))


def main():
    inks = InkTable.parse("vero-cmykw")
    rng = np.random.default_rng(0)
    out = {}
    for name in ("random", "white"):
        if name == "random":
            m = rng.dirichlet(np.ones(5), size=(20, 40, 40)).astype(np.float32)
        else:
            m = np.zeros((20, 40, 40, 5), np.float32)
            m[..., :4], m[..., 4] = 0.0075, 0.97
        vol = Volume.from_mixture(voxel_mm=(25.4 / 300,) * 3, mixture=m, inks=inks)
        tex = Texels.for_volume(vol, ["top"])
        adj = rng.uniform(0.2, 1.0, (len(tex), 3)).astype(np.float32)
        r = Renderer(vol)
        t0 = time.perf_counter()
        r.render(tex, 64, 0)
        tf = time.perf_counter() - t0
        t0 = time.perf_counter()
        gs, ga, _ = r.gradient(tex, adj, 64, 1, method="replay")
        tr = time.perf_counter() - t0
        t0 = time.perf_counter()
        ls, la, _ = r.gradient(tex, adj, 64, 1, method="li1")
        tl = time.perf_counter() - t0
        gm, lm = mix_grad(gs, ga, inks), mix_grad(ls, la, inks)
        out[name] = {
            "cos_sigma_a": cos(ga, la),
            "cos_mixture": cos(gm, lm),
            "norm_ratio_sigma_a": float(np.linalg.norm(la) / np.linalg.norm(ga)),
            "forward_s": tf,
            "replay_s": tr,
            "li1_s": tl,
        }
        print(name, {k: round(v, 3) for k, v in out[name].items()})
    print("wrote", write("li1_vs_replay.json", {**out, **machine()}))


if __name__ == "__main__":
    main()
