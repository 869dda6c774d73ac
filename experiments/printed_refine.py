"""The halftone's cost and what keeps it, side by side on one run: the continuous mixture, blue noise (the default
quantization), the printed refinement after N iterations (``printing.refine``: blue noise of a mixture refined on the
printed prediction) and other dithers, all evaluated at equal settings in one session on one texel set (the
evaluation's own choice of every texel or a texel sample, its adaptive noise-free sampling; no baselines), with the
paired differences of every printed result against the continuous one and against blue noise (on a texel sample),
the seconds each candidate took to make and that cost as a ratio to one optimisation iteration's passes (forward 16
spp + gradient 4 spp, the defaults) measured in the same session. Writes the entry NAME of
experiments/results/printed_refine.json.

    .venv/bin/python experiments/printed_refine.py NAME RUN [--refine 3,6] [--control] [--methods M[:UPSAMPLE],...]
        [--texel-sample N] [--threads T]

``--control``: also the same steps with the loss on the continuous render (``control-N``: their blue-noise print)
and the refined mixtures rendered continuous (``refine-N continuous``), with the paired differences refine-N -
control-N and refine-N - refine-N continuous; ``--control-only``: the control without the refinement.
``--methods``: other quantizations, each METHOD[:UPSAMPLE][/ORDER][+comp[1][tP]] (e.g. ``blue-noise:linear``,
``blue-noise/tint-first``: the inks' order in the bands, ``Quantization.ink_order``; ``+comp``: the shares
pre-compensated for the halftone, ``printing.compensate``, with its factors against other inks; ``+comp1``: with each
ink's factor against the base alone, the other inks counted as base (what ``--compensate`` does); ``t0.05``: the
correction tapered below a share of 0.05; its seconds are those of a cached compensation when one is cached, else they
include measuring it).
"""

import argparse
import contextlib
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

KEYS = ("delta_e76_mean_corrected", "delta_e2000_mean", "ssim", "mottle_l2")


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


def quantization(spec: str) -> tuple[Quantization, dict]:
    """``METHOD[:UPSAMPLE][/ORDER][+comp[1][tP]]`` -> (the settings, the compensation's changes for
    ``compensation_variant``; ``ORDER``: ``Quantization.ink_order``, e.g. ``tint-first``):
    ``+comp`` the shares compensated with the factors against other inks (``ShareCompensation.pairs``), ``+comp1``
    with each ink's factor against the base alone (the other inks counted as base: what ``Quantization.compensate``
    applies), ``tP`` (e.g. ``+compt0.05``) with the correction tapered below the share P
    (``ShareCompensation.taper``); no ``+comp``: uncompensated."""
    head, comp, tail = spec.partition("+comp")
    head, _, order = head.partition("/")
    m, _, up = head.partition(":")
    single, _, taper = tail.partition("t")
    changes = {"pairs": single != "1"} | ({"taper": float(taper)} if taper else {})
    q = Quantization(m, upsample=up or "nearest", ink_order=order or "lightness", compensate=bool(comp))
    return q, changes


@contextlib.contextmanager
def compensation_variant(changes: dict):
    """Within it, ``quantize`` uses the measured compensation with ``changes`` (fields of ``ShareCompensation``)."""
    full = Q.share_compensation
    with mock.patch.object(Q, "share_compensation", lambda *a, **k: replace(full(*a, **k), **changes)):
        yield


def candidates(vol, rd, refine: list[int], methods: list[str], control, threads, log, settings=None):
    """(name -> (labels volume, seconds to make it, extra record), name -> refined mixture volume rendered
    continuous (with the control only)); refinements share one run of the largest count. ``control``: False, True
    (the refinement and its control) or "only" (the control alone)."""
    out, mixtures = {}, {}
    t0 = time.perf_counter()
    out["blue-noise"] = (quantize_volume(vol, Quantization()), time.perf_counter() - t0, {})
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
                labels = quantize_volume(ref.volume(), Quantization())
                seconds = sum(h["seconds"] for h in ref.history) + time.perf_counter() - t0
                out[f"{label}-{ref.iteration}"] = (labels, seconds, {"history": list(ref.history)})
                if control is True and label == "refine":
                    mixtures[f"refine-{ref.iteration} continuous"] = ref.volume()
    return out, mixtures


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name")
    ap.add_argument("run")
    ap.add_argument("--refine", default="3,6")
    ap.add_argument("--methods", default="")
    ap.add_argument("--control", action="store_true", help="also the control (ContinuousRefinement)")
    ap.add_argument("--control-only", action="store_true", help="the control without the refinement")
    ap.add_argument("--texel-sample", type=int, default=None)
    ap.add_argument("--step", type=float, default=REFINE_STEP, help="the refinement's step (printing.refine)")
    ap.add_argument("--spp", type=int, default=REFINE_SPP, help="its printed render's and gradient pass's spp")
    ap.add_argument("--threads", type=int, default=None)
    a = ap.parse_args()
    refine = sorted(int(v) for v in a.refine.split(",") if v)
    methods = [m for m in a.methods.split(",") if m]
    opts = EvaluateOptions(baselines=False, texel_sample=a.texel_sample, threads=a.threads, write=False)
    t_start = time.perf_counter()
    ev = E.Evaluating.open(a.run, opts, lambda s: print(s, flush=True))
    ev.progress = False
    vol = ev.d.load_volume()
    E._render_continuous(ev, vol)
    per_it = iteration_seconds(vol, ev.rec.texels, a.threads)
    print(f"one optimisation iteration's passes: {per_it:.1f} s", flush=True)
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
            row["cost_iterations"] = made[name][1] / per_it
            row.update(made[name][2])
        entry["results"][name] = row
        print(name, {k: round(v, 4) if v is not None else None for k, v in row.items() if k in KEYS}, flush=True)
    if ev.sample is not None:
        pairs = [(n, "continuous") for n in made] + [(n, "blue-noise") for n in made if n != "blue-noise"]
        pairs += [(n, f"{n} continuous") for n in made if f"{n} continuous" in values]
        pairs += [(f"refine-{n[8:]}", n) for n in made if n.startswith("control-") and f"refine-{n[8:]}" in made]
        entry["differences"] = sampled.differences(values, pairs, ev.sample)
        for k, v in entry["differences"].items():
            print(k, {f: (round(d["value"], 4), round(d["stderr"], 4)) for f, d in v.items() if d["value"] is not None})
    entry["seconds"] = time.perf_counter() - t_start
    entry.update(machine())
    add_study_entry("printed_refine.json", a.name, entry)


if __name__ == "__main__":
    main()
