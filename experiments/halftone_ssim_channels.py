"""Which channel of SSIM a quantization variant moves: on one run's evaluation texel sample (``inkopt evaluate``'s
own choice, its adaptive noise-free sampling), the continuous result and each variant's print (as in
``printed_refine.py``), and per result the mean SSIM of each normalised CIELAB channel (L*, a*, b*) over the sample's
window centres and the mean CIELAB there, SSIM's factors per channel (``ssim_terms``: the luminance factor, the
contrast-structure factor, the print's windowed standard deviation (its grain) and covariance with the target), with
the paired differences of every variant against blue noise and of
blue noise against the continuous result (± their standard errors over the centres). Writes the entry NAME of
experiments/results/halftone_ssim_channels.json.

    .venv/bin/python experiments/halftone_ssim_channels.py NAME RUN [--methods blue-noise+comp,...] [--threads T]
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import printed_refine  # noqa: E402
from common import add_study_entry, machine, provenance  # noqa: E402

from inkopt.color import linear_to_lab, normalise_lab  # noqa: E402
from inkopt.evaluation import evaluate as E  # noqa: E402
from inkopt.evaluation import sample as sampled  # noqa: E402
from inkopt.evaluation.options import EvaluateOptions  # noqa: E402
from inkopt.evaluation.printed import PrintedRenderer  # noqa: E402
from inkopt.loss import K2, TexelLoss  # noqa: E402


def paired(a: np.ndarray, b: np.ndarray) -> dict:
    """Mean per channel of a - b over the centres (C, 3) and its standard error."""
    d = a - b
    return {"value": d.mean(0).tolist(), "stderr": (d.std(0) / np.sqrt(len(d))).tolist()}


TERMS = ("luminance", "contrast_structure", "std", "covariance")


def ssim_terms(loss: TexelLoss, rgb, var, rows) -> dict:
    """Per window centre (``rows``) and normalised CIELAB channel (C, 3), SSIM's two factors and what the second
    is made of: ``luminance`` (2 m m_t + K1) / (m^2 + m_t^2 + K1), ``contrast_structure`` (2 cov + K2) /
    (var + var_t + K2), the prediction's windowed standard deviation ``std`` (sqrt var, its Monte Carlo noise
    removed as in ``ssim_map``: the grain a window sees) and its ``covariance`` with the target (the structure it
    shares). Their product is ``ssim_map``."""
    rgb = np.asarray(rgb, np.float64)
    cn = normalise_lab(loss.colours[0].lab(rgb))
    noise = loss._noise(rgb, var, loss.colours[0])
    _, mx, a1, b1, a2, b2 = loss._ssim_parts(cn, noise)
    var_x = b2 - loss._var_t - K2
    return {
        "luminance": (a1 / b1)[rows],
        "contrast_structure": (a2 / b2)[rows],
        "std": np.sqrt(np.maximum(var_x, 0.0))[rows],
        "covariance": ((a2 - K2) / 2.0)[rows],
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    ap.add_argument("run")
    ap.add_argument("--methods", default="blue-noise+comp")
    ap.add_argument("--threads", type=int, default=None)
    a = ap.parse_args()
    opts = EvaluateOptions(baselines=False, threads=a.threads, write=False)
    ev = E.Evaluating.open(a.run, opts, lambda s: print(s, flush=True))
    ev.progress = False
    vol = ev.d.load_volume()
    E._render_continuous(ev, vol)  # chooses the texel sample
    if ev.sample is None:
        raise SystemExit("this study reads a texel sample's SSIM windows; the run was evaluated on every texel")
    methods = [m for m in a.methods.split(",") if m]
    made, _ = printed_refine.candidates(vol, ev.d, [], methods, False, a.threads, print)
    printer = None
    for name, (labels, _, _) in made.items():
        if printer is None:
            groups = ev.sample.groups
            printer = PrintedRenderer(labels, ev.rec.texels, vol.voxel_mm, ev.rec.kind, a.threads, ev.lighting, groups)
        E._render_printed(ev, printer, name, labels, time.perf_counter(), name)
    loss = TexelLoss(ev.target[ev.sample.windows], ev.groups[-1].texels.pos_vox, sigma=sampled.SIGMA)
    ct = ev.sample.centre_rows
    ssim, parts, entry = {}, {}, {**provenance(), "run": a.run, "centres": len(ct), "results": {}}
    for name, r in ev.renders.items():
        win = r.ads[1]
        ssim[name] = loss.ssim_map(win.rgb, win.var)[ct]
        parts[name] = ssim_terms(loss, win.rgb, win.var, ct)
        lab = linear_to_lab(np.asarray(win.rgb, np.float64))[ct].mean(0)
        entry["results"][name] = {"ssim_lab": ssim[name].mean(0).tolist(), "mean_lab": lab.tolist()}
        entry["results"][name].update({t: v.mean(0).tolist() for t, v in parts[name].items()})
        print(name, "SSIM L* a* b*", ssim[name].mean(0).round(4), "mean L*a*b*", lab.round(2), flush=True)
        print("   ", {t: v.mean(0).round(4).tolist() for t, v in parts[name].items()}, flush=True)
    entry["target_mean_lab"] = linear_to_lab(np.asarray(ev.target[ev.sample.windows], np.float64))[ct].mean(0).tolist()
    entry["differences"] = {"blue-noise - continuous": paired(ssim["blue-noise"], ssim["continuous"])}
    for m in methods:
        entry["differences"][f"{m} - blue-noise"] = paired(ssim[m], ssim["blue-noise"])
    entry["term_differences"] = {}
    for m, ref in [("blue-noise", "continuous")] + [(m, "blue-noise") for m in methods]:
        entry["term_differences"][f"{m} - {ref}"] = {t: paired(parts[m][t], parts[ref][t]) for t in TERMS}
    for k, v in entry["differences"].items():
        print(k, np.round(v["value"], 4), "±", np.round(v["stderr"], 4))
    for k, v in entry["term_differences"].items():
        for t, d in v.items():
            print(k, t, np.round(d["value"], 4), "±", np.round(d["stderr"], 4))
    entry.update(machine())
    add_study_entry("halftone_ssim_channels.json", a.name, entry)


if __name__ == "__main__":
    main()
