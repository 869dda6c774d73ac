"""Ink-set selection (``inkopt select-inks``): which ``choose`` of the candidate inks, printed with the ``always``
inks, reproduce a target best (the paper's application: 6 candidates choose 4 plus black and white = 15 sets).

Every subset is a normal optimisation run (``run.run_optimisation``) in ``DIR/runs/<name>/``, all with the same
settings and seed. Sets are compared by the run's loss at its final figures: the training objective evaluated on
the final mixture rendered at the evaluation spp with the evaluation seed (``report.json`` "loss"), a low-noise
figure, at the same iteration count for all sets of a rung.

- ``brute``: every subset runs ``iterations``; ranked by that loss.
- ``halving`` (successive halving with learning-curve extrapolation): with r = ceil(log2(n)) rungs of budgets
  iterations / 2^(r-1-k), every subset first runs the smallest budget and the better half (rounded up) continues
  to the next, resuming from its checkpoint (a resumed run continues exactly). Two changes to the textbook rule,
  both measured on the paper's setup (docs/select-inks.md, experiments/results/select_inks*.json):

  * intermediate rungs rank sets by their *predicted* loss at the full budget, not by their loss now: a power law
    loss(t) = a + b t^-c (a, b >= 0) fitted to the second half of the set's training-loss history (the first half
    is the descent from the white start, whose speed says little about where a set ends) and evaluated at
    ``iterations`` (learning-curve extrapolation, as in hyperparameter search: Domhan et al. 2015). The training
    loss is free (no rendering) and low-noise (a running average of ~100 spp);
  * with r >= 3 the rung before the last is dropped: the survivors of the rung before it (4 of 15) all run the full
    budget and the final evaluation (``eval_spp``) decides among them. The final sets' losses at the full budget
    differ from any earlier estimate by several per cent (the optimiser oscillates), so the last cut is made on
    the final figures only, among more sets; skipping the half-budget rung pays for it.

  Its final runs are the same as brute force's runs of those sets. The evaluation renders of intermediate rungs
  (``rung_eval_spp``) only give their figures and pictures.

Work is counted in texel-samples: iterations x texels x (spp + forward spp), plus the two evaluation renders of
every rung (the final and the initial mixture, eval spp each). The search's state (``selection_state.json``) is
saved atomically after every finished run, so ``resume`` continues an interrupted selection.
"""

from __future__ import annotations

import json
import math
import shutil
from dataclasses import dataclass, field
from itertools import combinations
from pathlib import Path

import numpy as np

from ..io import FORMAT_KEY, load_npz, save_npz, upgrade_format, write_json
from ..model import TRANSPARENT_INKS
from ..model.inks import INK_LIBRARY
from ..optim import OptimizeConfig
from ..printing.profiles import printer_profile
from ..rundir import RunDir
from ..scenes.spec import SceneSpec
from .backends import Serial, config_dict, run_candidate, threads_per_run

STRATEGIES = ("halving", "brute")
STATE, SELECTION, PICTURE = "selection_state.json", "selection.json", "selection.png"
SELECTION_FORMAT = 1  # selection.json; version 0 (no format_version) has the same keys
RULE = "halving: power-law extrapolation of the second half of the training loss; no half-budget rung"
_EXPONENTS = np.linspace(0.05, 3.0, 60)


def extrapolate_loss(hist, total: int, start: float = 0.5) -> float:
    """The loss a run with training-loss history ``hist`` (one value per iteration from the start) is predicted
    to reach at iteration ``total``: loss(t) = a + b t^-c fitted by least squares to the last ``1 - start`` of the
    history (a, b >= 0; c on a fixed grid in [0.05, 3], a, b in closed form: deterministic, no optimiser), the
    fit's value at ``total``. Fewer than 3 points: the last value."""
    h = np.asarray(hist, np.float64)
    s = int(len(h) * start)
    t, y = np.arange(s + 1, len(h) + 1, dtype=np.float64), h[s:]
    if len(y) < 3:
        return float(h[-1])
    best = (math.inf, float(h[-1]))
    for c in _EXPONENTS:
        g = t**-c
        a, b = np.linalg.lstsq(np.stack([np.ones_like(g), g], 1), y, rcond=None)[0]
        if b < 0:
            a, b = y.mean(), 0.0
        if a < 0:
            a, b = 0.0, float(g @ y / (g @ g))
        sse = float(((a + b * g - y) ** 2).sum())
        if sse < best[0]:
            best = (sse, float(a + b * total**-c))
    return best[1]


@dataclass
class Selection:
    """What to search. ``target``: the scene's spec (``scenes.spec.SlabSpec`` or ``MeshSpec``; every candidate's
    run builds it with its inks); ``cfg``: the optimiser settings of every run (``cfg.iterations``: the full
    budget); ``printer``: a ``printing.profiles`` key whose slots bound the set."""

    target: SceneSpec
    candidates: list[str]
    choose: int
    always: list[str]
    cfg: OptimizeConfig = field(default_factory=OptimizeConfig)
    strategy: str = "halving"
    eval_spp: int = 256
    rung_eval_spp: int = 16
    printer: str | None = "j750"

    def __post_init__(self):
        self.candidates = _names(self.candidates)
        self.always = _names(self.always)

    def validate(self) -> None:
        """One-line ValueErrors for everything that can be checked before any work starts."""
        if self.strategy not in STRATEGIES:
            raise ValueError(f"unknown strategy '{self.strategy}'; use one of {list(STRATEGIES)}")
        for what, names in (("--candidates", self.candidates), ("--always", self.always)):
            if len(set(names)) != len(names):
                raise ValueError(f"{what} lists an ink twice: {','.join(names)}")
        unknown = [n for n in self.candidates + self.always if n not in INK_LIBRARY]
        if unknown:
            raise ValueError(f"unknown ink(s) {','.join(unknown)}; known: {','.join(sorted(INK_LIBRARY))}")
        both = [n for n in self.candidates if n in self.always]
        if both:
            raise ValueError(f"ink(s) {','.join(both)} are in both --candidates and --always")
        if not 1 <= self.choose <= len(self.candidates):
            raise ValueError(
                f"--choose {self.choose} needs at least {max(self.choose, 1)} candidates and at least "
                f"1; got {len(self.candidates)} ({','.join(self.candidates) or 'none'})"
            )
        n = self.choose + len(self.always)
        prof = printer_profile(self.printer) if self.printer is not None else None
        if prof is not None and prof.max_materials is not None and n > prof.max_materials:
            raise ValueError(
                f"--choose {self.choose} plus {len(self.always)} --always inks make {n} inks but "
                f"{prof.name} holds {prof.max_materials} materials per job; choose fewer or use "
                "a --printer with more material slots"
            )
        self.cfg.validate()
        if self.cfg.iterations < 1:
            raise ValueError("--iterations must be at least 1")
        if self.cfg.init == "white" and "white" not in self.always:
            raise ValueError(
                "--init white needs 'white' in --always (every set starts 97 % white); add it or use --init random"
            )
        if self.rung_eval_spp < 1 or self.eval_spp < 1:
            raise ValueError("evaluation spp must be at least 1")
        self._check_target()

    def subsets(self) -> list[tuple[str, ...]]:
        """The chosen part of every set, in candidate order."""
        return list(combinations(self.candidates, self.choose))

    def inks(self, subset) -> list[str]:
        return list(subset) + self.always

    def budgets(self) -> list[int]:
        """The iteration count of every rung (one rung for brute force)."""
        n, total = len(self.subsets()), self.cfg.iterations
        if self.strategy == "brute" or n == 1:
            return [total]
        r = math.ceil(math.log2(n))
        b = [max(1, round(total / 2 ** (r - 1 - k))) for k in range(r)]
        return b[:-2] + b[-1:] if r >= 3 else b

    def key(self) -> str:
        """What must match for ``resume`` (everything; the settings as the target's scene kind resolves them, so
        that searches started before a setting was left to the kind still resume)."""
        cfg = self.cfg.for_scene(self.target.kind)
        return json.dumps(
            {
                "target": self.target.to_json(),
                "candidates": self.candidates,
                "choose": self.choose,
                "always": self.always,
                "cfg": config_dict(cfg),
                "strategy": self.strategy,
                "eval_spp": self.final_eval_spp,
                "rung_eval_spp": self.rung_eval_spp,
                "rule": RULE,
            },
            sort_keys=True,
        )

    def _check_target(self) -> None:
        """The target's inputs, with every set's inks (each must honour the constraints: white for a mesh's
        core, a transparent ink for translucency). A slab's pictures and mask are read once (readable, sizes
        matching); a mesh is voxelized only in the runs."""
        from ..model import InkTable

        if self.target.translucency is not None and not set(TRANSPARENT_INKS) & set(self.always):
            raise ValueError(
                "--translucency needs a transparent ink ('transparent' or 'clear') in every set; add it to --always"
            )
        sets = [InkTable.from_names(self.inks(s)) for s in self.subsets()]
        for inks in sets:
            self.target.validate(inks)
        if self.target.kind == "slab":
            self.target.build(sets[0])

    @property
    def final_eval_spp(self) -> int:
        """The last rung's evaluation spp: always a fixed count, so that the work is known in advance."""
        return int(self.eval_spp)


def _names(names) -> list[str]:
    if isinstance(names, str):
        names = names.split(",")
    return [n.strip().lower() for n in names if n.strip()]


def set_name(subset) -> str:
    return "+".join(subset)


def _load_state(out: Path, sel: Selection, resume: bool) -> dict:
    fresh = {"key": sel.key(), "rungs": []}
    path = out / STATE
    if not resume or not path.is_file():
        return fresh
    state = json.loads(path.read_text())
    if state.get("key") != sel.key():
        raise ValueError(
            f"{out} holds a selection made with different settings; rerun without --resume or "
            "with the original settings"
        )
    return state


def run_selection(sel: Selection, out, backend=None, *, resume: bool = False, log=print) -> dict:
    """Run the search into ``out``; returns selection.json's content (also written, with selection.png and
    ``out/winner/``)."""
    sel.validate()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    backend = backend or Serial()
    state = _load_state(out, sel, resume)
    budgets, alive = sel.budgets(), sel.subsets()
    log(f"{sel.strategy}: {len(alive)} ink sets, rungs of {budgets} iterations, {backend.name} execution")
    done_iters: dict[str, int] = {}
    for k, budget in enumerate(budgets):
        last = k == len(budgets) - 1
        if k == len(state["rungs"]):
            state["rungs"].append(
                {"iterations": budget, "eval_spp": sel.final_eval_spp if last else sel.rung_eval_spp, "results": {}}
            )
        rung = state["rungs"][k]
        todo = [s for s in alive if set_name(s) not in rung["results"]]
        threads = threads_per_run(backend, len(todo))
        # every rung steps as the full run would (step decay planned for the full budget), so intermediate rungs
        # take constant steps and a final run is the same as brute force's run of that set
        cfg = {**config_dict(sel.cfg), "iterations": budget, "schedule_iterations": sel.cfg.iterations}
        tasks = [
            {
                "spec": sel.target,
                "inks": sel.inks(s),
                "cfg": cfg,
                "out": str(out / "runs" / set_name(s)),
                "resume": resume or k > 0,
                "eval_spp": rung["eval_spp"],
                "threads": threads,
            }
            for s in todo
        ]
        for s, res in zip(todo, backend.map(run_candidate, tasks)):
            name = set_name(s)
            save_npz(out / "predictions" / f"{name}.npz", {"rgb": res.pop("prediction")})
            start = done_iters.get(name, 0)
            res["texel_samples"] = res["texels"] * (
                (budget - start) * (sel.cfg.spp + sel.cfg.forward_spp) + 2 * rung["eval_spp"]
            )
            hist = res.pop("hist_loss")
            res["train_loss"] = hist[-1]
            res["predicted_loss"] = extrapolate_loss(hist, sel.cfg.iterations)
            rung["results"][name] = res
            write_json(out / STATE, state)
            log(
                f"  {name}: {budget} iterations, loss {res['loss']:.5g}, ΔE76 {res['delta_e76_mean']:.2f}"
                + ("" if last else f", predicted loss at {sel.cfg.iterations}: {res['predicted_loss']:.5g}")
            )
        for s in alive:
            done_iters[set_name(s)] = budget
        by = "loss" if last else "predicted_loss"  # the final figures, else the extrapolated training loss
        ranked = sorted(alive, key=lambda s: (rung["results"][set_name(s)][by], set_name(s)))
        alive = ranked[:1] if last else ranked[: math.ceil(len(ranked) / 2)]
    return _finish(sel, out, state, alive[0], log)


def _finish(sel: Selection, out: Path, state: dict, winner, log) -> dict:
    latest, work, rung_of = {}, {}, {}
    for k, rung in enumerate(state["rungs"]):
        for name, res in rung["results"].items():
            latest[name], rung_of[name] = res, k
            work[name] = work.get(name, 0) + res["texel_samples"]
    names = {set_name(s): s for s in sel.subsets()}
    order = sorted(latest, key=lambda n: (-rung_of[n], latest[n]["loss"], n))
    cands = [
        {
            "inks": sel.inks(names[n]),
            "iterations": latest[n]["iterations"],
            "loss": latest[n]["loss"],
            "delta_e76_mean": latest[n]["delta_e76_mean"],
            "delta_e2000_mean": latest[n]["delta_e2000_mean"],
            "ssim": latest[n]["ssim"],
            "texel_samples": work[n],
        }
        for n in order
    ]
    wname = set_name(winner)
    result = {
        "strategy": sel.strategy,
        "candidates": cands,
        "winner": {"inks": sel.inks(winner), "loss": latest[wname]["loss"]},
        "texel_samples": int(sum(work.values())),
        FORMAT_KEY: SELECTION_FORMAT,
    }
    _copy_run(out / "runs" / wname, out / "winner")
    write_json(out / SELECTION, result)
    from .figures import selection_figure

    rec = RunDir(out / "winner").load_scene()
    preds = [(c, load_npz(out / "predictions" / f"{n}.npz")["rgb"]) for c, n in zip(cands, order)]
    selection_figure(out / PICTURE, rec, preds)
    log(
        f"winner: {','.join(result['winner']['inks'])} (loss {result['winner']['loss']:.5g}); "
        f"{result['texel_samples']:.3g} texel-samples"
    )
    return result


def load_selection(out) -> dict:
    """selection.json of selection directory ``out`` (a one-line ValueError if missing or of a format version
    this inkopt does not read)."""
    path = Path(out) / SELECTION
    if not path.is_file():
        raise ValueError(f"{path} does not exist (the selection has not finished)")
    return upgrade_format(
        json.loads(path.read_text()), kind="ink-set selection", where=path, current=SELECTION_FORMAT, upgrades={0: dict}
    )


def _copy_run(src: Path, dst: Path) -> None:
    """``dst`` becomes a copy of run directory ``src`` (replaced whole: copied beside it, then renamed)."""
    tmp = dst.with_name(dst.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    shutil.copytree(src, tmp)
    shutil.rmtree(dst, ignore_errors=True)
    tmp.rename(dst)
