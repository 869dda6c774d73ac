"""Ink-set selection (``inkopt select-inks``): which ``choose`` of the candidate inks, printed with the ``always``
inks, reproduce a target best (the paper's application: 6 candidates choose 4 plus black and white = 15 sets).

Every subset is a normal optimisation run (``run.run_optimisation``) in ``DIR/runs/<name>/``, all with the same
settings and seed. Sets are compared by the run's loss at its final figures: the training objective evaluated on
the final mixture rendered at the evaluation spp with the evaluation seed (``report.json`` "loss"), a low-noise
figure, at the same iteration count for all sets of a rung.

- ``brute``: every subset runs ``iterations``; ranked by that loss.
- ``halving`` (successive halving, ``plan_rungs``): of 5 or more sets, every set first runs a quarter of the
  budget (``FIRST_RUNG``), a quarter of the sets (``FIRST_KEEP``, rounded up) go on to half the budget, half of
  those to the full budget, where the final figures decide. Of 2-4 sets: half the budget, then the better half.
  Intermediate rungs rank a set by its training loss at the rung's end (``rank_loss``: free, no rendering, and
  low-noise, a running average of ~100 spp); a power-law extrapolation of the training loss to the full budget
  (``extrapolate_loss``) ranked worse on the recorded searches and is not used. The first rung is long and cuts
  deep, rather than many short rungs that each halve: after a few iterations the sets are still leaving the white
  start, and a rung of 1 or 2 iterations ranks by little more than how fast a set leaves it. Runs resume and
  continue exactly, so a rung's history is a prefix of brute force's run of the set and the final runs are brute
  force's runs; ``simulate`` replays a plan on brute force's records exactly, which is how the rule is tested on
  recorded 35-set searches (tests/inksets/test_rung_rule.py, docs/select-inks.md). The evaluation renders of
  intermediate rungs (``rung_eval_spp``) only give their figures and pictures.

Work is counted in texel-samples (``rung_work``): iterations x texels x (spp + forward spp), plus the evaluation
renders of every rung (the result, and on a set's first rung its start, eval spp each). The search's state
(``selection_state.json``) is saved atomically after every finished run, so ``resume`` continues an interrupted
selection.
"""

from __future__ import annotations

import json
import math
import shutil
from dataclasses import dataclass, field
from itertools import combinations
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from ..io import FORMAT_KEY, load_npz, save_npz, upgrade_format, write_json
from ..model import TRANSPARENT_INKS
from ..model.inks import INK_LIBRARY
from ..optim import OptimizeConfig
from ..printing.profiles import printer_profile
from ..rundir import RunDir
from ..scenes import build_scene
from ..scenes.spec import SceneSpec
from .backends import Serial, config_dict, run_candidate, threads_per_run

STRATEGIES = ("halving", "brute")
STATE, SELECTION, PICTURE = "selection_state.json", "selection.json", "selection.png"
SELECTION_FORMAT = 1  # selection.json; version 0 (no format_version) has the same keys
RULE = "halving: rungs of 1/4, 1/2 and the full budget keeping 1/4 then half; ranked by the training loss"
_EXPONENTS = np.linspace(0.05, 3.0, 60)


def extrapolate_loss(hist, total: int, start: float = 0.5) -> float:
    """The loss a run with training-loss history ``hist`` (one value per iteration from the start) is predicted
    to reach at iteration ``total``: loss(t) = a + b t^-c fitted by least squares to the last ``1 - start`` of the
    history (a, b >= 0; c on a fixed grid in [0.05, 3], a, b in closed form: deterministic, no optimiser), the
    fit's value at ``total``. Fewer than 3 points: the last value.

    Not what the rungs rank by: on the recorded 35-set searches (experiments/results/select_inks_35*.json) it ranks
    the sets worse than their last training loss does (the fit follows the history's wiggles), e.g. the best set
    18th of 35 after 10 of 40 iterations, where the last training loss puts it 2nd. ``simulate(..., rank=...)``
    compares the two."""
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


#: the first rung runs this fraction of the budget: long enough that the sets have left the white start's descent
#: and their order has settled (on the recorded astronaut search the Spearman correlation of the training loss with
#: the final loss over the 35 sets is 0.69 after 1 of 40 iterations, 0.82 after 5, 0.95 after 10)
FIRST_RUNG = 0.25
#: after the first rung, this fraction of the sets goes on (rounded up); after the middle rung, half of those
FIRST_KEEP = 0.25


def plan_rungs(n: int, total: int, strategy: str = "halving") -> list[tuple[int, int]]:
    """(iterations, sets kept after it) per rung for ``n`` sets and a budget of ``total`` iterations.

    ``brute`` (or one set): one rung, every set to ``total``. ``halving`` of up to 4 sets: half the budget, then
    the better half (rounded up) to the full budget. Of 5 or more: three rungs, ``FIRST_RUNG`` x total, twice that
    and total; every set runs the first, k1 = ceil(``FIRST_KEEP`` x n) (at least 2) go on to the second, k2 =
    ceil(k1 / 2) to the full budget, where the final figures decide. The iterations run, in units of n x total:
    FIRST_RUNG + FIRST_RUNG k1 / n + (1 - 2 FIRST_RUNG) k2 / n = 0.38 for 15 sets, 0.39 for 35 (plus the
    evaluation renders)."""
    if strategy == "brute" or n <= 1:
        return [(int(total), 1)]
    if n <= 4:
        return [(max(1, round(total / 2)), math.ceil(n / 2)), (int(total), 1)]
    k1 = max(2, math.ceil(FIRST_KEEP * n))
    k2 = math.ceil(k1 / 2)
    b0 = max(1, round(FIRST_RUNG * total))
    b1 = max(b0, round(2 * FIRST_RUNG * total))
    return [(b0, k1), (b1, k2), (int(total), 1)]


def rank_loss(hist, total: int | None = None) -> float:
    """What an intermediate rung ranks a set by: its training loss after the rung's last iteration (``hist``: one
    value per iteration; ``total``, the full budget, is not used: see ``extrapolate_loss`` for why it is not
    extrapolated). The training loss is taken on a running average of the renders, so it is already smoothed."""
    return float(np.asarray(hist, np.float64)[-1])


def rung_work(iterations: int, spp_per_iteration: int, eval_spp: int, fresh: bool) -> int:
    """Samples per texel of one set's rung: ``iterations`` x (spp + forward spp), and the evaluation at
    ``eval_spp`` of the result (and of the start when the run is ``fresh``: a resumed run keeps its start's
    figures)."""
    return int(iterations * spp_per_iteration + eval_spp * (2 if fresh else 1))


def simulate(sets: dict, plan, total: int, spp_per_iteration: int, rung_eval_spp: int, eval_spp: int, rank=rank_loss):
    """The outcome of a rung ``plan`` (``plan_rungs``) from brute force's records: ``sets`` maps a name to
    ``{"hist_loss": [...] (``total`` values), "loss": final loss}``. Halving's runs resume and continue exactly, so
    a rung's history is a prefix of brute force's and its final runs are brute force's runs: the outcome is exact.
    ``rank(hist, total)``: what intermediate rungs rank by. Returns (winner's name, work in samples per texel)."""
    alive, done, work = sorted(sets), {n: 0 for n in sets}, 0
    for k, (budget, keep) in enumerate(plan):
        last = k == len(plan) - 1
        for n in alive:
            work += rung_work(budget - done[n], spp_per_iteration, eval_spp if last else rung_eval_spp, done[n] == 0)
            done[n] = budget
        score = {n: sets[n]["loss"] if last else rank(sets[n]["hist_loss"][:budget], total) for n in alive}
        alive = sorted(alive, key=lambda n: (score[n], n))[:keep]
    return alive[0], work


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
        for what, names in (("`candidates`", self.candidates), ("`always`", self.always)):
            if len(set(names)) != len(names):
                raise ParameterError(f"{what} lists an ink twice: {','.join(names)}")
        unknown = [n for n in self.candidates + self.always if n not in INK_LIBRARY]
        if unknown:
            raise ValueError(f"unknown ink(s) {','.join(unknown)}; known: {','.join(sorted(INK_LIBRARY))}")
        both = [n for n in self.candidates if n in self.always]
        if both:
            raise ParameterError(f"ink(s) {','.join(both)} are in both `candidates` and `always`")
        if not 1 <= self.choose <= len(self.candidates):
            raise ParameterError(
                f"`choose` {self.choose} needs at least {max(self.choose, 1)} candidates and at least "
                f"1; got {len(self.candidates)} ({','.join(self.candidates) or 'none'})"
            )
        n = self.choose + len(self.always)
        prof = printer_profile(self.printer) if self.printer is not None else None
        if prof is not None and prof.max_materials is not None and n > prof.max_materials:
            raise ParameterError(
                f"`choose` {self.choose} plus {len(self.always)} `always` inks make {n} inks but "
                f"{prof.name} holds {prof.max_materials} materials per job; choose fewer or use "
                "a `printer` with more material slots"
            )
        self.cfg.validate()
        if self.cfg.iterations < 1:
            raise ParameterError("`iterations` must be at least 1")
        if self.cfg.init == "white" and "white" not in self.always:
            raise ParameterError(
                "`init` white needs 'white' in `always` (every set starts 97 % white); add it or use `init` random"
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
        return [b for b, _ in self.plan()]

    def plan(self) -> list[tuple[int, int]]:
        """(iterations, sets kept after it) of every rung: ``plan_rungs``."""
        return plan_rungs(len(self.subsets()), self.cfg.iterations, self.strategy)

    def key(self) -> str:
        """What must match for ``resume`` (everything; the settings as the target's scene kind resolves them, so
        that searches started before a setting was left to the kind still resume)."""
        cfg = config_dict(self.cfg.for_scene(self.target.kind))
        for name in ("stop_gain", "stop_horizon", "time_budget"):  # runs of a selection end at their budgets
            cfg.pop(name)
        return json.dumps(
            {
                "target": self.target.to_json(),
                "candidates": self.candidates,
                "choose": self.choose,
                "always": self.always,
                "cfg": cfg,
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
            raise ParameterError(
                "`translucency` needs a transparent ink ('transparent' or 'clear') in every set; add it to `always`"
            )
        sets = [InkTable.from_names(self.inks(s)) for s in self.subsets()]
        for inks in sets:
            self.target.validate(inks)
        if self.target.kind == "slab":
            build_scene(self.target, sets[0])

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
        raise ParameterError(
            f"{out} holds a selection made with different settings; rerun without `resume` or "
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
    plan, alive = sel.plan(), sel.subsets()
    budgets = [b for b, _ in plan]
    log(
        f"{sel.strategy}: {len(alive)} ink sets, rungs of {budgets} iterations keeping "
        f"{[keep for _, keep in plan]} sets, {backend.name} execution"
    )
    done_iters: dict[str, int] = {}
    for k, (budget, keep) in enumerate(plan):
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
            res["texel_samples"] = res["texels"] * rung_work(
                budget - start, sel.cfg.spp + sel.cfg.forward_spp, rung["eval_spp"], start == 0
            )
            hist = res.pop("hist_loss")
            res["train_loss"] = rank_loss(hist)
            rung["results"][name] = res
            write_json(out / STATE, state)
            log(
                f"  {name}: {budget} iterations, loss {res['loss']:.5g} at {rung['eval_spp']} spp, ΔE76 "
                f"{res['delta_e76_mean']:.2f}"
                + ("" if last else f"; training loss {res['train_loss']:.5g} (what this rung ranks by)")
            )
        for s in alive:
            done_iters[set_name(s)] = budget
        by = "loss" if last else "train_loss"  # the final figures, else the training loss
        ranked = sorted(alive, key=lambda s: (rung["results"][set_name(s)][by], set_name(s)))
        alive = ranked[:keep]
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
