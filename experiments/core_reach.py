"""How much of a band-over-white-core print's light comes from deep in the core, and what its paths cost there: the
question any shortening of the white core's long walks (a Russian roulette by depth, a core cut off or darkened
below some depth) has to answer.

A flat, laterally infinite piece of a large object (``periodic-xy``, 32 x 32 voxels of 84.7 µm, 300 DPI): a 1 mm
band of one mixture on top of the white core, the core cut at depth h below the top. The light is the upper
hemisphere's (radiance 1), so light that leaves through the bottom face is lost, as if a black ink filled the rest.
For each h the top face's texels are rendered at the same samples and seed, one channel at a time (the other two
channels empty, so that the render's events are that channel's): reflectance R(h) (linear), the per-path second
moment of the value, and the events (collisions) per path. ``h = --deep-mm`` stands for the semi-infinite core.

From these, a roulette that plays once on every path that first reaches depth h, survival probability q, weight
1 / q, is unbiased, saves (1 - q) of the events those paths spend after reaching h, E(deep) - E(h), and adds
(1 / q - 1) E[X_h^2] to a path's variance, X_h the value that reaches the top through depth h. Here X <= 1 (no path
weight exceeds 1 in these media and the light's radiance is 1), so R(deep) - R(h) >= E[X_h^2] >= (R(deep) - R(h))^2 /
P(h), P(h) <= 1: the study reports the efficiency ratio (variance x events, analog over roulette, per channel, at the
best q) between the bound E[X_h^2] = R(deep) - R(h) (a lower bound of the gain) and E[X_h^2] = (R(deep) - R(h))^2 (an
upper bound). A ratio of 2 would halve a white-core run's time at equal noise.

    .venv/bin/python experiments/core_reach.py [--depths 1,1.5,2,3,5,8,13,20] [--deep-mm 40] [--spp 512]
        [--mixtures cream,rose,dark]

Writes experiments/results/core_reach.json.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "bench"))
from common import add_study_entry, machine, provenance  # noqa: E402

from inkopt.lighting import Lighting  # noqa: E402
from inkopt.model import InkTable, Texels, Volume, mix  # noqa: E402
from inkopt.render import Renderer  # noqa: E402

RESULT = "core_reach.json"
VOXEL_MM = 25.4 / 300
SIDE = 32
BAND_MM = 1.0
#: band mixtures (ink -> share of the default inks): Spot's cream, a rose mid-tone and a dark colour
MIXTURES = {
    "cream": {"white": 0.90, "yellow": 0.07, "magenta": 0.03},
    "rose": {"white": 0.60, "magenta": 0.30, "yellow": 0.10},
    "dark": {"white": 0.50, "black": 0.20, "cyan": 0.30},
}


def slab(inks: InkTable, mixture: dict, depth_mm: float, channel: int) -> Volume:
    """The periodic slab: ``BAND_MM`` of ``mixture`` on top (+z) of white, ``depth_mm`` thick in all; only
    ``channel``'s coefficients (the other two channels empty, so that their paths cross without an event and the
    render's events are this channel's)."""
    nz = max(int(round(depth_mm / VOXEL_MM)), 1)
    band = min(int(round(BAND_MM / VOXEL_MM)), nz)
    shares = np.zeros((nz, SIDE, SIDE, len(inks)), np.float32)
    shares[..., inks.names.index("white")] = 1.0
    top = np.zeros(len(inks), np.float32)
    for name, share in mixture.items():
        top[inks.names.index(name)] = share
    shares[nz - band :] = top
    sigma_s, sigma_a = mix(shares, inks)
    others = [c for c in range(3) if c != channel]
    sigma_s[..., others] = 0.0
    sigma_a[..., others] = 0.0
    return Volume.from_coefficients((VOXEL_MM,) * 3, sigma_s, sigma_a, g=inks.g, boundary="periodic-xy")


def sky() -> Lighting:
    """Radiance 1 from the upper hemisphere, 0 from below: light that leaves through the bottom face is lost."""
    env = np.zeros((16, 32, 3), np.float32)
    env[:8] = 1.0
    return Lighting(map=env, source="upper hemisphere")


def measure(inks: InkTable, mixture: dict, depth_mm: float, spp: int, seed: int) -> dict:
    """Per channel: R, the per-path second moment E[X^2] and the events per path of the slab's top face."""
    out = {"depth_mm": depth_mm, "R": [], "R_stderr": [], "second_moment": [], "events_per_path": [], "seconds": 0.0}
    for c in range(3):
        vol = slab(inks, mixture, depth_mm, c)
        texels = Texels.for_volume(vol, ["top"])
        t0 = time.perf_counter()
        res = Renderer(vol, lighting=sky()).render(texels, spp=spp, seed=seed, include_specular=False)
        out["seconds"] += time.perf_counter() - t0
        x = res.rgb[:, c].astype(np.float64)
        var = res.var_mean[:, c].astype(np.float64)
        out["R"].append(float(x.mean()))
        out["R_stderr"].append(float(np.sqrt(var.sum()) / len(x)))
        out["second_moment"].append(float((var * spp + x**2).mean()))  # per path: spp x the mean's variance
        out["events_per_path"].append(3 * res.events / max(res.paths, 1))  # every texel traces spp paths per channel
    out["seconds"] = round(out["seconds"], 2)
    return out


def roulette_gain(deep: dict, at: dict) -> dict:
    """Per channel, the efficiency (variance x events) of the analog walk over a roulette at depth h = ``at``'s, at
    the best q, between E[X_h^2] = R(deep) - R(h) (``low``) and (R(deep) - R(h))^2 (``high``)."""
    out = {}
    for bound in ("low", "high"):
        gains = []
        for c in range(3):
            e_all, saved = deep["events_per_path"][c], max(deep["events_per_path"][c] - at["events_per_path"][c], 0)
            r, dr = deep["R"][c], max(deep["R"][c] - at["R"][c], 0.0)
            var = deep["second_moment"][c] - r * r
            m2 = dr if bound == "low" else dr * dr
            best = 1.0
            for q in np.linspace(0.01, 1.0, 100):
                cost = (var + (1 / q - 1) * m2) * (e_all - (1 - q) * saved)
                best = max(best, var * e_all / cost)
            gains.append(round(float(best), 3))
        out[bound] = gains
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--depths", default="1,1.5,2,3,5,8,13,20", help="core cut-off depths h, mm below the top")
    ap.add_argument("--deep-mm", type=float, default=40.0, help="the depth standing for a semi-infinite core")
    ap.add_argument("--spp", type=int, default=512)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--mixtures", default=",".join(MIXTURES))
    ap.add_argument("--name", default="slab")
    args = ap.parse_args()
    inks = InkTable.parse("vero-cmykw")
    depths = [float(d) for d in args.depths.split(",")]
    entry = {"spp": args.spp, "voxel_mm": VOXEL_MM, "side": SIDE, "band_mm": BAND_MM, "mixtures": {}}
    for name in args.mixtures.split(","):
        deep = measure(inks, MIXTURES[name], args.deep_mm, args.spp, args.seed)
        rows = []
        for h in depths:
            row = measure(inks, MIXTURES[name], h, args.spp, args.seed)
            row["roulette_gain"] = roulette_gain(deep, row)
            rows.append(row)
            print(
                f"{name} h={h:5.1f} mm  R {np.round(row['R'], 4)}  events/path {np.round(row['events_per_path'], 1)}  "
                f"gain low {row['roulette_gain']['low']} high {row['roulette_gain']['high']}",
                flush=True,
            )
        events = np.round(deep["events_per_path"], 1)
        print(f"{name} deep={args.deep_mm} mm  R {np.round(deep['R'], 4)}  events/path {events}")
        entry["mixtures"][name] = {"shares": MIXTURES[name], "deep": deep, "cut": rows}
    entry.update(machine=machine(), **provenance())
    add_study_entry(RESULT, args.name, entry)


if __name__ == "__main__":
    main()
