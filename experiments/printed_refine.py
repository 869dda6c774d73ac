"""The halftone's cost and what keeps it, side by side on one run: the continuous mixture, blue noise (the reference
every variant is paired with), the printed refinement after N iterations (``printing.refine``: blue noise of a mixture
refined on the printed prediction) and other dithers, all evaluated at equal settings in one session on one texel set
(the evaluation's own choice of every texel or a texel sample, its adaptive noise-free sampling; no baselines), with the
paired differences of every printed result against the continuous one and against blue noise (on a texel sample), the
seconds each candidate took to make and that cost as a ratio to one optimisation iteration's passes (forward 16 spp +
gradient 4 spp, the defaults) measured in the same session. Writes the entry NAME of
experiments/results/printed_refine.json.

    .venv/bin/python experiments/printed_refine.py NAME RUN [--refine 3,6] [--control] [--methods M[:UPSAMPLE],...]
        [--texel-sample N] [--windows W] [--threads T] [--no-cost]

``--control``: also the same steps with the loss on the continuous render (``control-N``: their blue-noise print)
and the refined mixtures rendered continuous (``refine-N continuous``), with the paired differences refine-N -
control-N and refine-N - refine-N continuous; ``--control-only``: the control without the refinement.
``--methods``: other quantizations, each METHOD[:UPSAMPLE][/ORDER][+comp[1][tP]] (e.g. ``blue-noise:linear``,
``blue-noise/tint-first``: the inks' order in the bands, ``Quantization.ink_order``; ``+comp``: the shares
pre-compensated for the halftone, ``printing.compensate``, with its factors against other inks; ``+comp1``: with each
ink's factor against the base alone, the other inks counted as base (what ``--compensate`` does); ``t0.05``: the
correction tapered below a share of 0.05; its seconds are those of a cached compensation when one is cached, else they
include measuring it). On a texel sample the entry also holds ``ssim_channels``: each printed result's SSIM
against blue noise per channel (L*, a*, b*), paired on the windows, and binned by each ink's share at the windows'
centres (where a variant's SSIM is lost), and ``delta_e_bins``: its ΔE76 and ΔE2000 against blue noise binned by
each ink's share at the points; ``--windows``: the sample's SSIM windows (``sample_windows``).
"""

import argparse
import contextlib
import json
import sys
import time
from dataclasses import replace
from pathlib import Path
from unittest import mock

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import add_study_entry, machine, provenance  # noqa: E402

from inkopt.evaluation import evaluate as E  # noqa: E402
from inkopt.evaluation import sample as sampled  # noqa: E402
from inkopt.evaluation.options import EvaluateOptions  # noqa: E402
from inkopt.evaluation.printed import PrintedRenderer  # noqa: E402
from inkopt.evaluation.renders import ContinuousSource  # noqa: E402
from inkopt.loss import TexelLoss  # noqa: E402
from inkopt.model import Quantization  # noqa: E402
from inkopt.printing import quantize as Q  # noqa: E402
from inkopt.printing.quantize import quantize_volume  # noqa: E402
from inkopt.printing.refine import REFINE_SPP, REFINE_STEP, PrintedRefinement  # noqa: E402
from inkopt.printing.stream import run_target  # noqa: E402
from inkopt.render import Renderer  # noqa: E402

STUDY = Path(__file__).resolve().parent / "results"
KEYS = ("delta_e76_mean_corrected", "delta_e2000_mean", "ssim", "mottle_l2")
SHARE_BINS = (0.0, 0.01, 0.03, 0.1, 0.3, 1.01)  # an ink's share at a window's centre, for ``ssim_channels``


def iteration_seconds(vol, texels, threads) -> float:
    """One optimisation iteration's passes on ``vol``: a forward render at 16 spp and a gradient pass at 4 spp."""
    r = Renderer(vol, threads)
    t0 = time.perf_counter()
    r.render(texels, 16, 1)
    r.gradient(texels, np.zeros((len(texels), 3), np.float32), 4, 2)
    return time.perf_counter() - t0


class ContinuousRefinement(PrintedRefinement):
    """The control: the refinement's steps with the loss taken on the continuous mixture's render at the same spp
    (more ordinary iterations at the refinement's step), to tell the halftone's correction from further
    optimisation of an unconverged result."""

    def printed(self, seed: int):
        for lo, hi in self.param.chunks():
            self.continuous.set_mixture(self.param.free_index[lo:hi], self.param.free_rows(self.x[lo:hi], lo))
        res = self.continuous.render(self.target.texels, self.spp[0], seed)
        return res.rgb.astype(np.float64), res.var_mean.astype(np.float64)


def layer_factors(layer_mm: float) -> dict:
    """{ink name: k} fitted on patches whose tint fills a top layer of ``layer_mm`` (experiments/compensation_depth.py's
    results, entry "vero-cmykw")."""
    entry = json.loads((STUDY / "compensation_depth.json").read_text())["results"]["vero-cmykw"]
    out = {}
    for ink, m in entry["inks"].items():
        row = next((r for r in m["layers"] if abs(r["layer_mm"] - layer_mm) < 1e-9), None)
        if row is None:
            raise SystemExit(f"compensation_depth.json has no {layer_mm:g} mm layer for {ink}")
        out[ink] = float(row["k"])
    return out


def quantization(spec: str) -> tuple[Quantization, dict]:
    """``METHOD[:UPSAMPLE][/ORDER][+comp[1|w][tP][@LX]]`` -> (the settings, the compensation's changes for
    ``compensation_variant``; ``ORDER``: ``Quantization.ink_order``, e.g. ``tint-first``; ``+compw``: each ink's
    factor against white alone and none against the other inks, p_eff = p / (1 + k w), w the white share, so a
    mixture without white is not corrected (``ShareCompensation.base_only``)):
    ``+comp`` the shares compensated with the factors against other inks (``ShareCompensation.pairs``), ``+comp1``
    with each ink's factor against the base alone (the other inks counted as base: what ``Quantization.compensate``
    applies), ``tP`` (e.g. ``+compt0.05``) with the correction tapered below the share P
    (``ShareCompensation.taper``), ``@LX`` (e.g. ``+comp1@L0.16``) with each ink's k fitted on a tint in a top layer
    of X mm (``layer_factors``); no ``+comp``: uncompensated."""
    head, comp, tail = spec.partition("+comp")
    head, _, order = head.partition("/")
    m, _, up = head.partition(":")
    tail, _, layer = tail.partition("@L")
    single, _, taper = tail.partition("t")
    changes = {"pairs": single != "1"} | ({"taper": float(taper)} if taper else {})
    changes |= {"layer_k": layer_factors(float(layer))} if layer else {}
    changes |= {"base_only": True, "pairs": False} if single == "w" else {}
    q = Quantization(m, upsample=up or "nearest", ink_order=order or "lightness", compensate=bool(comp))
    return q, changes


@contextlib.contextmanager
def compensation_variant(changes: dict):
    """Within it, ``quantize`` uses the measured compensation with ``changes`` (fields of ``ShareCompensation``)."""
    full = Q.share_compensation

    def varied(*a, **k):
        comp, own = full(*a, **k), dict(changes)
        layer_k = own.pop("layer_k", None)
        if layer_k is not None:  # the inks' factors of a thin tinted layer (the base keeps 0)
            names = a[0].names  # share_compensation(inks, q, g, ior)
            own["k"] = np.array([layer_k.get(n, k) for n, k in zip(names, comp.k)])
        return replace(comp, **own)

    with mock.patch.object(Q, "share_compensation", varied):
        yield


def candidates(vol, rd, refine: list[int], methods: list[str], control, threads, log, settings=None):
    """(name -> (labels volume, seconds to make it, extra record), name -> refined mixture volume rendered
    continuous (with the control only)); refinements share one run of the largest count. ``control``: False, True
    (the refinement and its control) or "only" (the control alone)."""
    out, mixtures = {}, {}
    t0 = time.perf_counter()
    out["blue-noise"] = (quantize_volume(vol, Quantization("blue-noise")), time.perf_counter() - t0, {})
    for spec in methods:  # METHOD[:UPSAMPLE][/ORDER][+comp[1][tP]]
        q, changes = quantization(spec)
        t0 = time.perf_counter()
        with compensation_variant(changes):
            out[spec] = (quantize_volume(vol, q), time.perf_counter() - t0, {})
    kinds = [("refine", PrintedRefinement)] if control != "only" else []
    kinds += [("control", ContinuousRefinement)] if control else []
    for label, cls in kinds if refine else []:
        ref = cls(vol, run_target(rd, vol), Quantization(refine=max(refine)), threads, *(settings or ()))
        while ref.iteration < max(refine):
            e = ref.step()
            log(f"{label} {ref.iteration}: ΔE76 {e['delta_e76']:.3f} at {ref.spp[0]} spp, {e['seconds']:.1f} s")
            if ref.iteration in refine:  # its iterations' seconds and the final dither
                t0 = time.perf_counter()
                labels = quantize_volume(ref.volume(), Quantization("blue-noise"))
                seconds = sum(h["seconds"] for h in ref.history) + time.perf_counter() - t0
                out[f"{label}-{ref.iteration}"] = (labels, seconds, {"history": list(ref.history)})
                if control is True and label == "refine":
                    mixtures[f"refine-{ref.iteration} continuous"] = ref.volume()
    return out, mixtures


def centre_shares(ev, vol, texels: np.ndarray) -> np.ndarray:
    """(k, N) float64: the mixture's shares at the voxels of scene texels ``texels`` (k,)."""
    vox = ev.rec.texels.voxel[texels].astype(np.int64)
    return np.asarray(vol.mixture, np.float64)[vox[:, 0], vox[:, 1], vox[:, 2]]


def share_bins(d: dict, shares: np.ndarray, inks, population: int) -> dict:
    """Per ink, the bins of its share (``SHARE_BINS``) with at least 3 rows: their count and the mean ± standard
    error of each per-row difference of ``d`` (name -> (k,) array)."""
    out = {}
    for i, ink in enumerate(inks.names):
        bins = []
        for lo, hi in zip(SHARE_BINS[:-1], SHARE_BINS[1:]):
            m = (shares[:, i] >= lo) & (shares[:, i] < hi)
            if m.sum() >= 3:
                bins.append({"lo": lo, "hi": hi, "count": int(m.sum())})
                for k, v in d.items():
                    bins[-1][k] = dict(zip(("value", "stderr"), sampled.mean_se(v[m], population)))
        out[f"share_{ink}"] = bins
    return out


def delta_e_bins(ev, values: dict, vol, names) -> dict:
    """Name -> each printed result's corrected ΔE76 and ΔE2000 minus blue noise's on the sample's points, binned by
    each ink's share at the points' voxels (``share_bins``)."""
    shares = centre_shares(ev, vol, ev.sample.points)
    b = values["blue-noise"]
    out = {}
    for n in names:
        if n != "blue-noise":
            v = values[n]
            d = {"delta_e76": (v["delta_e76"] - v["noise_contribution"]) - (b["delta_e76"] - b["noise_contribution"])}
            d["delta_e2000"] = v["delta_e2000"] - b["delta_e2000"]
            out[n] = share_bins(d, shares, vol.inks, ev.sample.population)
    return out


def ssim_channels(ev, loss: TexelLoss, vol, names) -> dict:
    """Name -> each printed result's SSIM minus blue noise's on the sample's windows (``ev.renders`` still held):
    ``L``, ``a``, ``b`` (per channel, normalised L*a*b* as ``TexelLoss.ssim_map``) and per ink the bins of its
    share at the centres' voxels (``SHARE_BINS``): windows, the mean SSIM and b* differences, each {value, stderr}
    (``sample.mean_se``)."""
    s, big = ev.sample, ev.sample.population
    ct = s.centre_rows
    per = {n: loss.ssim_map(ev.renders[n].ads[1].rgb, ev.renders[n].ads[1].var)[ct] for n in names}
    shares = centre_shares(ev, vol, s.centres)
    pair = lambda d: dict(zip(("value", "stderr"), sampled.mean_se(d, big)))  # noqa: E731
    out = {}
    for n in names:
        if n == "blue-noise":
            continue
        d = per[n] - per["blue-noise"]
        row = {c: pair(d[:, i]) for i, c in enumerate("Lab")}
        row |= share_bins({"ssim": d.mean(1), "b": d[:, 2]}, shares, vol.inks, big)
        out[n] = row
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    ap.add_argument("run")
    ap.add_argument("--refine", default="3,6")
    ap.add_argument("--methods", default="")
    ap.add_argument("--control", action="store_true", help="also the control (ContinuousRefinement)")
    ap.add_argument("--control-only", action="store_true", help="the control without the refinement")
    ap.add_argument("--texel-sample", type=int, default=None)
    ap.add_argument("--windows", type=int, default=None, help="the texel sample's SSIM windows")
    ap.add_argument("--step", type=float, default=REFINE_STEP, help="the refinement's step (printing.refine)")
    ap.add_argument("--spp", type=int, default=REFINE_SPP, help="its printed render's and gradient pass's spp")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--no-cost", dest="cost", action="store_false", help="skip timing one iteration's passes")
    ap.add_argument("--reference", default=None, help="also pair every other method with this one (e.g. the default)")
    a = ap.parse_args()
    refine = sorted(int(v) for v in a.refine.split(",") if v)
    methods = [m for m in a.methods.split(",") if m]
    opts = EvaluateOptions(
        baselines=False, texel_sample=a.texel_sample, sample_windows=a.windows, threads=a.threads, write=False
    )
    t_start = time.perf_counter()
    ev = E.Evaluating.open(a.run, opts, lambda s: print(s, flush=True))
    ev.progress = False
    vol = ev.d.load_volume()
    E._render_continuous(ev, vol)
    per_it = iteration_seconds(vol, ev.rec.texels, a.threads) if a.cost else None
    print(f"one optimisation iteration's passes: {per_it} s", flush=True)
    settings = (a.step, (a.spp, a.spp))
    say = lambda s: print(s, flush=True)  # noqa: E731
    control = "only" if a.control_only else a.control
    made, mixtures = candidates(vol, ev.d, refine, methods, control, a.threads, say, settings)
    for name, mv in mixtures.items():  # refined mixtures, continuous: on the same texel groups as the first
        t0 = time.perf_counter()
        ev.render(name, ContinuousSource(Renderer(mv, a.threads), ev.groups, False), t0, None)
    printer = None
    for name, (labels, _, _) in made.items():
        if printer is None:
            groups = None if ev.sample is None else ev.sample.groups
            printer = PrintedRenderer(labels, ev.rec.texels, vol.voxel_mm, ev.rec.kind, a.threads, ev.lighting, groups)
        E._render_printed(ev, printer, name, labels, time.perf_counter(), name)
    printer.use(None)
    measured, values = {}, {}
    target = ev.target if ev.sample is None else ev.target[ev.sample.windows]
    loss = TexelLoss(target, ev.groups[-1].texels.pos_vox, sigma=sampled.SIGMA)
    channels = ssim_channels(ev, loss, vol, list(made)) if ev.sample is not None else None
    for name in list(ev.renders):
        measured[name] = E._measured(ev, loss, ev.renders.pop(name), values, name)
    entry = {**provenance(), "run": a.run, "texels": len(ev.rec.texels), "iteration_seconds": per_it}
    entry["refine_settings"] = {"step": a.step, "spp": a.spp}
    s = ev.sample
    entry["sample"] = None if s is None else {"points": len(s.points), "windows": len(s.centres)}
    entry["results"] = {}
    for name, m in measured.items():
        fig = m.metrics.to_json()
        row = {k: fig.get(k) for k in KEYS}
        row["stderr"] = None if m.stderr is None else {k: m.stderr.get(k) for k in KEYS}
        row["spp"] = m.spp
        if name in made:
            row["seconds_to_make"] = made[name][1]
            row["cost_iterations"] = None if per_it is None else made[name][1] / per_it
            row.update(made[name][2])
        entry["results"][name] = row
        print(name, {k: round(v, 4) if v is not None else None for k, v in row.items() if k in KEYS}, flush=True)
    if ev.sample is not None:
        pairs = [(n, "continuous") for n in made] + [(n, "blue-noise") for n in made if n != "blue-noise"]
        pairs += [(n, f"{n} continuous") for n in made if f"{n} continuous" in values]
        pairs += [(n, a.reference) for n in made if a.reference in made and n not in (a.reference, "blue-noise")]
        pairs += [(f"refine-{n[8:]}", n) for n in made if n.startswith("control-") and f"refine-{n[8:]}" in made]
        entry["differences"] = sampled.differences(values, pairs, ev.sample)
        for k, v in entry["differences"].items():
            print(k, {f: (round(d["value"], 4), round(d["stderr"], 4)) for f, d in v.items() if d["value"] is not None})
        entry["ssim_channels"] = channels
        entry["delta_e_bins"] = delta_e_bins(ev, values, vol, list(made))
    entry["seconds"] = time.perf_counter() - t_start
    entry.update(machine())
    add_study_entry("printed_refine.json", a.name, entry)


if __name__ == "__main__":
    main()
