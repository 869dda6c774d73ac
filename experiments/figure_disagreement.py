"""Where ΔE76 and ΔE2000 disagree on a mesh suite run, and why: per result (the continuous optimum, the print and the
extrusion baseline, both printed as ``inkopt evaluate`` prints them), the mean ΔE76 and ΔE2000 of a random texel
sample, their decomposition (mean |ΔL*|, |ΔC*ab|, |ΔH*ab|; the ΔE2000 terms |ΔL'/SL|, |ΔC'/SC|, |ΔH'/SH|, the mean
weights SL, SC, SH), split by bins of the target's chroma C*ab and by whether the target lies outside what a thick
patch of the inks reaches (the evaluation's colour table, ``ColourTable.reachable_lab``: the gamut floor per texel).
Writes the entry MESH of experiments/results/figure_disagreement.json.

    nice -n 5 .venv/bin/python experiments/figure_disagreement.py RUN_DIR --name MESH [--texels 1500] [--spp 512]
    .venv/bin/python docs/tables.py     # the docs' tables (figure-terms, figure-verdicts) from the results file

RUN_DIR is a suite run (bench/mesh_suite.py) with scene.npz, volume.npz and quantized.npz; it is copied to a
temporary directory first, so nothing is written into it. Every result is rendered on the same sampled texels with
the same seeds at ``--spp`` samples per scene texel (the prints on their printer texels, averaged onto the scene
texels as ``inkopt evaluate`` does).

Noise: ΔE76 is reported raw and noise-corrected (``evaluation.noise.NoiseModel``, as ``evaluate``); ΔE2000 has no
correction in ``evaluate``, so its inflation is estimated here by adding Gaussian CIELAB noise of the render's own
covariance once more (``NOISE_DRAWS`` draws) and taking the increase of the mean: for noise small against the error
the inflation grows with the variance, so doubling the variance adds about what the render's noise already added.
The same estimate for ΔE76 is reported beside the model's correction as a check. Standard errors are the sampling
errors of means over the sampled texels (the render noise of each texel is part of the spread).
"""

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import add_study_entry, machine, provenance  # noqa: E402

from inkopt.color import delta_e76, delta_e2000, linear_to_lab  # noqa: E402
from inkopt.evaluation.baselines import BaselineLayers  # noqa: E402
from inkopt.evaluation.colour_table import colour_table  # noqa: E402
from inkopt.evaluation.evaluate import Evaluating, _Grid, _printed_results, _render_continuous  # noqa: E402
from inkopt.evaluation.noise import NoiseModel, lab_covariance  # noqa: E402
from inkopt.evaluation.options import EvaluateOptions  # noqa: E402

#: lower edges of the target chroma bins C*ab (the last is open)
CHROMA_BINS = (0.0, 20.0, 40.0, 60.0)
#: a target farther than this (ΔE76) from what a thick patch reaches counts as outside the ink gamut
OUT_OF_GAMUT_DE76 = 1.0
NOISE_DRAWS = 8
RUN_FILES = (
    "scene.npz",
    "volume.npz",
    "quantized.npz",
    "quantized_labels.npy",
    "quantized_labels.layers",
    "report.json",
)


def ciede2000_terms(lab_ref: np.ndarray, lab: np.ndarray) -> dict:
    """The CIEDE2000 difference of ``lab`` (I, 3) from ``lab_ref`` (I, 3) term by term (Sharma, Wu and Dalal 2005):
    dL = ΔL'/SL, dC = ΔC'/SC, dH = ΔH'/SH, the weights SL, SC, SH, the rotation term RT·dC·dH, and ``de`` the total
    (I,) each. kL = kC = kH = 1."""
    l1, a1, b1 = lab_ref.T
    l2, a2, b2 = lab.T
    c_bar = 0.5 * (np.hypot(a1, b1) + np.hypot(a2, b2))
    g = 0.5 * (1 - np.sqrt(c_bar**7 / (c_bar**7 + 25.0**7)))
    a1p, a2p = (1 + g) * a1, (1 + g) * a2
    c1p, c2p = np.hypot(a1p, b1), np.hypot(a2p, b2)
    h1p = np.degrees(np.arctan2(b1, a1p)) % 360
    h2p = np.degrees(np.arctan2(b2, a2p)) % 360
    zero = c1p * c2p == 0
    dh = h2p - h1p
    dh = np.where(dh > 180, dh - 360, np.where(dh < -180, dh + 360, dh))
    dh = np.where(zero, 0.0, dh)
    d_l, d_c = l2 - l1, c2p - c1p
    d_h = 2 * np.sqrt(c1p * c2p) * np.sin(np.radians(dh) / 2)
    l_bar, cp_bar = 0.5 * (l1 + l2), 0.5 * (c1p + c2p)
    hsum, hdiff = h1p + h2p, np.abs(h1p - h2p)
    h_bar = np.where(hdiff <= 180, hsum / 2, np.where(hsum < 360, (hsum + 360) / 2, (hsum - 360) / 2))
    h_bar = np.where(zero, hsum, h_bar)
    hr = np.radians(h_bar)
    t = 1 - 0.17 * np.cos(hr - np.radians(30)) + 0.24 * np.cos(2 * hr)
    t += 0.32 * np.cos(3 * hr + np.radians(6)) - 0.20 * np.cos(4 * hr - np.radians(63))
    theta = np.radians(30 * np.exp(-(((h_bar - 275) / 25) ** 2)))
    rc = 2 * np.sqrt(cp_bar**7 / (cp_bar**7 + 25.0**7))
    sl = 1 + 0.015 * (l_bar - 50) ** 2 / np.sqrt(20 + (l_bar - 50) ** 2)
    sc, sh = 1 + 0.045 * cp_bar, 1 + 0.015 * cp_bar * t
    tl, tc, th = d_l / sl, d_c / sc, d_h / sh
    rot = -np.sin(2 * theta) * rc * tc * th
    de = np.sqrt(np.maximum(tl * tl + tc * tc + th * th + rot, 0.0))
    return {"dL": tl, "dC": tc, "dH": th, "SL": sl, "SC": sc, "SH": sh, "rot": rot, "de": de}


def cie76_terms(lab_ref: np.ndarray, lab: np.ndarray) -> dict:
    """ΔE76 of ``lab`` from ``lab_ref`` (I, 3) split into ΔL*, ΔC*ab and ΔH*ab (ΔE76² = ΔL*² + ΔC*ab² + ΔH*ab²)."""
    d = lab - lab_ref
    d_c = np.hypot(lab[:, 1], lab[:, 2]) - np.hypot(lab_ref[:, 1], lab_ref[:, 2])
    d_h = np.sqrt(np.maximum(d[:, 1] ** 2 + d[:, 2] ** 2 - d_c**2, 0.0))
    return {"dL": d[:, 0], "dC": d_c, "dH": d_h, "de": np.sqrt(np.sum(d * d, 1))}


def noise_inflation(rgb: np.ndarray, var: np.ndarray, target_lab: np.ndarray, seed: int = 1) -> dict:
    """Estimated inflation (I,) of each texel's ΔE76 and ΔE2000 by the render noise (module docstring): the mean
    increase when Gaussian CIELAB noise of the render's covariance is added once more, over ``NOISE_DRAWS`` draws;
    and the ΔE76 correction of ``NoiseModel`` for comparison."""
    lab = linear_to_lab(rgb)
    chol = np.linalg.cholesky(lab_covariance(rgb, var) + 1e-12 * np.eye(3))
    rng = np.random.default_rng(seed)
    e76, e00 = delta_e76(lab, target_lab), delta_e2000(target_lab, lab)
    up76, up00 = np.zeros(len(lab)), np.zeros(len(lab))
    for _ in range(NOISE_DRAWS):
        noisy = lab + np.einsum("ikl,il->ik", chol, rng.standard_normal(lab.shape))
        up76 += (delta_e76(noisy, target_lab) - e76) / NOISE_DRAWS
        up00 += (delta_e2000(target_lab, noisy) - e00) / NOISE_DRAWS
    return {"e76_sim": up76, "e2000_sim": up00, "e76_model": NoiseModel.of(rgb, var, target_lab).per_texel()}


def mean_se(x: np.ndarray, population: int) -> list:
    """[mean, standard error] of a simple random sample x of a population (finite-population corrected)."""
    n = len(x)
    if n < 2:
        return [float(x.mean()) if n else None, None]
    return [float(x.mean()), float(x.std(ddof=1) / np.sqrt(n) * np.sqrt(max(1 - n / population, 0.0)))]


def render_results(run: Path, texels: int, spp: int, threads: int, seed: int) -> dict:
    """The continuous result, the print (quantized.npz) and the printed extrusion baseline of the run copied from
    ``run``, each rendered on the same ``texels`` sampled scene texels at ``spp`` per scene texel, as ``inkopt
    evaluate`` renders them. Returns the sampled targets (linear RGB and CIELAB, (n, 3)), the reachable colours
    (``reachable``, CIELAB (n, 3)), the population and each result's (rgb, var) of the sampled texels."""
    with tempfile.TemporaryDirectory(prefix="figure_disagreement_") as tmp:
        for name in RUN_FILES:
            if (run / name).exists():
                shutil.copy2(run / name, Path(tmp) / name)
        opts = EvaluateOptions(spp=spp, seed=seed, threads=threads, texel_sample=texels, sample_windows=2, write=False)
        ev = Evaluating.open(tmp, opts, None)
        vol = ev.d.load_volume()
        _render_continuous(ev, vol)
        table = colour_table(vol.inks, vol.g, vol.ior, patch_mm=opts.patch_mm, threads=threads)
        fixed = ev.rec.fixed_share(vol.inks, vol.shape)
        extrusion = BaselineLayers("extrusion", vol, ev.rec.texels, ev.target, fixed, table, refine=opts.refine)
        grid = _Grid(vol.shape, vol.voxel_mm)
        del vol
        _printed_results(ev, grid, {"extrusion": extrusion})
        points = ev.sample.points
        target = ev.target[points]
        return {
            "target": target,
            "target_lab": ev.target_lab[points],
            "reachable": table.reachable_lab(target),
            "population": ev.sample.population,
            "results": {name: (r.ads[0].rgb, r.ads[0].var) for name, r in ev.renders.items()},
        }


def per_texel(target_lab: np.ndarray, rgb: np.ndarray, var: np.ndarray) -> dict:
    """Every per-texel value of one result (I,) by name: ΔE76 and ΔE2000 (raw and less their estimated noise
    inflation), the loss's colour term ΔE76² less its noise (E[|d + n|²] = |d|² + tr cov: ``e1_corrected``), the
    absolute ΔE76 and ΔE2000 terms, the ΔE2000 weights."""
    lab = linear_to_lab(rgb)
    t76, t00 = cie76_terms(target_lab, lab), ciede2000_terms(target_lab, lab)
    check = np.max(np.abs(t00["de"] - delta_e2000(target_lab, lab)))
    if check > 1e-6:
        raise RuntimeError(f"the CIEDE2000 terms disagree with scikit-image's total by {check:g}")
    noise = noise_inflation(rgb, var, target_lab)
    trace = np.trace(lab_covariance(rgb, var), axis1=1, axis2=2)
    return {
        "e1_corrected": t76["de"] ** 2 - trace,
        "de76": t76["de"],
        "de76_corrected": t76["de"] - noise["e76_model"],
        "de2000": t00["de"],
        "de2000_corrected": t00["de"] - noise["e2000_sim"],
        "noise76_model": noise["e76_model"],
        "noise76_sim": noise["e76_sim"],
        "noise2000_sim": noise["e2000_sim"],
        "abs_dL76": np.abs(t76["dL"]),
        "abs_dC76": np.abs(t76["dC"]),
        "abs_dH76": np.abs(t76["dH"]),
        "abs_dL_SL": np.abs(t00["dL"]),
        "abs_dC_SC": np.abs(t00["dC"]),
        "abs_dH_SH": np.abs(t00["dH"]),
        "SL": t00["SL"],
        "SC": t00["SC"],
        "SH": t00["SH"],
        "dC76_signed": t76["dC"],
        "dL76_signed": t76["dL"],
    }


def texel_groups(target_lab: np.ndarray, reachable: np.ndarray) -> dict:
    """Boolean masks (n,) of the sampled texels by name: all, each target chroma bin, inside and outside the gamut."""
    chroma = np.hypot(target_lab[:, 1], target_lab[:, 2])
    out = delta_e76(reachable, target_lab) >= OUT_OF_GAMUT_DE76
    groups = {"all": np.ones(len(chroma), bool)}
    edges = (*CHROMA_BINS, np.inf)
    for lo, hi in zip(edges, edges[1:]):
        groups[f"C* {lo:g}-{hi:g}" if np.isfinite(hi) else f"C* >= {lo:g}"] = (chroma >= lo) & (chroma < hi)
    groups["in gamut"], groups["out of gamut"] = ~out, out
    return groups


def summarise(data: dict) -> dict:
    """Each group's share, target figures (chroma, gamut distance and its chroma part) and every result's means of
    ``per_texel``'s values [mean, standard error], and the paired differences of the ours from extrusion."""
    tl, reach, pop = data["target_lab"], data["reachable"], data["population"]
    values = {name: per_texel(tl, rgb, var) for name, (rgb, var) in data["results"].items()}
    floor = cie76_terms(tl, reach)
    target = {
        "chroma": np.hypot(tl[:, 1], tl[:, 2]),
        "gamut_de76": floor["de"],
        "gamut_abs_dC76": np.abs(floor["dC"]),
        "gamut_de2000": delta_e2000(tl, reach),
    }
    out = {}
    for group, m in texel_groups(tl, reach).items():
        if not m.any():
            continue
        entry = {"share": float(m.mean()), "texels": int(m.sum())}
        entry["target"] = {k: mean_se(v[m], pop) for k, v in target.items()}
        for name, vals in values.items():
            entry[name] = {k: mean_se(v[m], pop) for k, v in vals.items()}
        for name in ("continuous", "quantized"):
            entry[f"{name} - extrusion"] = {
                k: mean_se(values[name][k][m] - values["extrusion"][k][m], pop)
                for k in ("de76", "de76_corrected", "de2000", "de2000_corrected", "e1_corrected")
            }
            # the group's part of the whole sample's mean difference (the parts add up to the "all" difference)
            entry[f"{name} - extrusion"]["de76_corrected_part"] = float(
                np.sum(values[name]["de76_corrected"][m] - values["extrusion"]["de76_corrected"][m]) / len(m)
            )
            entry[f"{name} - extrusion"]["de2000_corrected_part"] = float(
                np.sum(values[name]["de2000_corrected"][m] - values["extrusion"]["de2000_corrected"][m]) / len(m)
            )
        out[group] = entry
    return out


def print_table(name: str, groups: dict) -> None:
    """One line per group and result: mean ΔE76 (corrected), ΔE2000 (corrected) and their terms."""
    print(f"{name}: group (share) result: ΔE76c ΔE2000c | |ΔL*| |ΔC*| |ΔH*| | |ΔL/SL| |ΔC/SC| |ΔH/SH| SC")
    for group, e in groups.items():
        t = e["target"]
        print(
            f"  {group} ({e['share'] * 100:.1f} %): target C* {t['chroma'][0]:.1f}, gamut ΔE76 "
            f"{t['gamut_de76'][0]:.2f} (|ΔC*| {t['gamut_abs_dC76'][0]:.2f}), ΔE2000 {t['gamut_de2000'][0]:.2f}"
        )
        for r in ("continuous", "quantized", "extrusion"):
            v = {k: x[0] for k, x in e[r].items()}
            print(
                f"    {r:11s} {v['de76_corrected']:6.2f} {v['de2000_corrected']:6.2f} | {v['abs_dL76']:5.2f} "
                f"{v['abs_dC76']:5.2f} {v['abs_dH76']:5.2f} | {v['abs_dL_SL']:5.2f} {v['abs_dC_SC']:5.2f} "
                f"{v['abs_dH_SH']:5.2f} {v['SC']:5.2f}"
            )
        d = e["continuous - extrusion"]
        print(
            f"    continuous - extrusion: ΔE76c {d['de76_corrected'][0]:+.2f} ± {d['de76_corrected'][1]:.2f}, "
            f"ΔE2000c {d['de2000_corrected'][0]:+.2f} ± {d['de2000_corrected'][1]:.2f}"
        )


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="a suite run directory")
    ap.add_argument("--name", required=True)
    ap.add_argument("--texels", type=int, default=1500)
    ap.add_argument("--spp", type=int, default=512)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    entry = {**provenance(), "run": str(a.run), "texels_sampled": a.texels, "spp": a.spp, "seed": a.seed}
    data = render_results(a.run, a.texels, a.spp, a.threads, a.seed)
    entry["population"] = data["population"]
    entry["groups"] = summarise(data)
    entry.update(machine())
    print_table(a.name, entry["groups"])
    add_study_entry("figure_disagreement.json", a.name, entry)


if __name__ == "__main__":
    main()
