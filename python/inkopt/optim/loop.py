"""The optimisation loop: gradient descent on the ink mixture of every voxel (docs/method.md §3 and §6).

One iteration: mixture -> coefficients -> forward render (seed a) -> loss and dE/dC -> path-replay gradient pass
(seed b != a, so the adjoint's noise and the gradient's noise are independent) -> dE/dsigma -> dE/drho -> dE/dx ->
optimiser step (``optimizers``), diffused where the target is flat (``smooth``; ``OptimizeConfig.smooth``). The loss is
taken on a running average of the renders (``adjoint_ema``); with ``forward_spp`` 0 there is no forward render
after the first iteration, and the adjoint is evaluated at the average of the earlier gradient passes' own
estimates (cheaper iterations, each worth less: docs/experiments.md). One
:class:`~inkopt.render.Renderer` serves the whole run: geometry and thread pool are set up once and only the free
voxels' media are overwritten each iteration. Seeds are derived from (seed, iteration), and
renders and gradients are bit-identical for any thread count, so a run resumed from a checkpoint continues exactly
as if it had not stopped.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ..color import delta_e76
from ..errors import ParameterError
from ..lighting import Lighting, load_lighting
from ..model import FixedShares, Volume, mix_grad
from ..render import Renderer, RendererFactory, TexelRenderer
from ..scenes import Scene
from ..spectral.viewing import Viewing
from .checkpoint import History, check_state, read_checkpoint, write_checkpoint
from .config import COLD_INITS, OptimizeConfig
from .interrupt import interrupt_deferred
from .optimizers import make_optimizer, step_factor
from .param import Parameterization, initial_free_mixture
from .progress import ProgressLines, changed_settings
from .smooth import GradientSmoother, flat_texel_guide
from .stopping import Reserve, Schedule

#: samples per texel of the first iteration's forward render of a run without forward passes (forward_spp 0)
START_FORWARD_SPP = 16


def iteration_seeds(seed: int, it: int) -> tuple[int, int]:
    """(forward seed, gradient seed) of iteration ``it``: distinct, and independent of everything else."""
    base = (int(seed) * 1_000_003 + 2 * int(it)) % (2**63)
    return base, base + 1


class Optimization:
    """An optimisation run over a scene's mixture.

    ``scene``: what is optimised (``scenes.Scene``: its base ``volume`` gives the geometry and ink table (its
    medium is ignored), ``texels``, ``target_rgb`` (I, 3) linear and ``fixed_share``, the (z, y, x, N) fixed ink
    shares, ``model.FixedShares`` or None). ``cfg``: the run's settings, resolved for the scene's kind
    (``OptimizeConfig.for_scene``), read as they are. ``baseline(kind)`` -> (z, y, x, N) mixture of a print-shop
    baseline (an array, or its layers: ``evaluation.baselines.baseline_layers``), needed only for ``cfg.init``
    "surface" or "extrusion" (the run driver supplies it); ``lighting``: the display lighting the prediction is
    rendered under (``inkopt.lighting``; default uniform). ``renderer_factory(volume, threads, lighting)``: what
    renders (default ``Renderer``; e.g. texel shards on Ray, ``inkopt.distributed.RayShards.renderer``, with
    identical results). ``started``: when this invocation began (``time.perf_counter()``; default now), from which
    the run's wall time counts. ``viewing``: spectral or RGB and the lights (``spectral.viewing.Viewing``; default
    RGB): a spectral table's prediction is its B bands (``c_avg`` (I, B)), its loss taken under the lights.
    """

    def __init__(
        self,
        scene: Scene,
        cfg: OptimizeConfig,
        *,
        threads: int | None = None,
        baseline: Callable[[str], np.ndarray] | None = None,
        lighting: Lighting | str | None = None,
        renderer_factory: RendererFactory | None = None,
        started: float | None = None,
        viewing: Viewing | None = None,
    ):
        if not cfg.resolved:
            raise ValueError(f"the settings must be resolved for a {scene.kind} first: cfg.for_scene({scene.kind!r})")
        cfg.validate()
        base, texels, fixed_share = scene.volume, scene.texels, scene.fixed_share
        self.viewing, self._make = viewing or Viewing(), renderer_factory or Renderer  # builds the renderer
        self.lighting = load_lighting(lighting)
        if base.inks is None:
            raise ValueError("the volume needs an ink table")
        self.base, self.texels, self.cfg, self.threads, self.baseline = base, texels, cfg, threads, baseline
        self.target = np.asarray(scene.target_rgb, np.float32)
        if fixed_share is None:
            fixed_share = FixedShares.none(base.shape, len(base.inks))
        self.param = Parameterization(cfg.param, fixed_share, threads)
        self.param.share_index(None if base.band is None else base.band.index)
        self.loss = self.viewing.loss(self.target, texels.pos_vox, cfg.gamma, cfg.colour_term)
        self.release_unread_operators()
        # what the run optimises towards and under which constraints: part of the checkpoint key
        h = hashlib.sha256(self.target.tobytes())
        self.param.fixed_share.digest(h)  # the dense array's bytes, a layer at a time
        self._problem_digest = h.hexdigest()[:16]
        self.x = self.initial_variables()
        # the inside voxels held fixed (a shell's core) join the step scale's population with a zero gradient
        held = 0 if base.inside is None else max(base.inside.count - self.param.n_free, 0)
        self.opt = make_optimizer(cfg.optimizer, cfg.step_size, self.x.shape, threads, held_rows=held)
        self.smoother = self._smoother()
        self._renderer: TexelRenderer | None = None
        self.iteration = 0
        self.history = History()
        self.schedule = Schedule.for_config(cfg)  # where the run ends (the step decay is planned for it)
        # the start's and a print-shop baseline's evaluated figures (``keep_start_figures``,
        # ``keep_baseline_figures``; kept in the checkpoints so a resume need not render them again)
        self.start_figures: dict | None = None
        self.baseline_figures: dict | None = None  # baseline kind -> figures
        # wall time of the run's earlier invocations (up to their last checkpoint) and this one's start
        self.wall_seconds_before = 0.0
        self.invocation_start = time.perf_counter() if started is None else started
        self.c_avg: np.ndarray | None = None  # running average of the prediction (I, C)
        self.c_weight = 0.0  # its effective number of samples per texel
        self.c_var: np.ndarray | None = None  # the variance of the running average (I, C)
        #: the last step's render statistics (``RenderResult.stats()``: paths, events, seconds, ...) per pass
        self.last_passes: dict = {}

    def _smoother(self) -> GradientSmoother | None:
        """The step's spatial preconditioner (``cfg.smooth``; None when off), guided by the target's flat texels
        down to ``MAX_DEPTH`` when ``cfg.smooth_edge`` is set."""
        cfg, threads, p = self.cfg, self.threads, self.param
        if not cfg.smooth > 0:
            return None
        guide = rows = None
        if cfg.smooth_edge > 0:  # guided: the free voxels under flat texels only, down to MAX_DEPTH
            rows, guide = flat_texel_guide(p.shape, p.free_index, self.texels.pos_vox, self.loss, threads)
        return GradientSmoother(p.shape, p.free_index, cfg.smooth, guide, cfg.smooth_edge, rows, threads)

    def keep_start_figures(self, figures: dict) -> None:
        """Keep the start's evaluated figures (``delta_e76_mean``, ``ssim``, ``delta_e76_mean_corrected``,
        ``eval_spp``) with the run: they are written into every later checkpoint."""
        self.start_figures = dict(figures)

    def keep_baseline_figures(self, kind: str, figures: dict) -> None:
        """Keep print-shop baseline ``kind``'s evaluated figures (as ``keep_start_figures``'s) with the run."""
        self.baseline_figures = {**(self.baseline_figures or {}), kind: dict(figures)}

    def release_unread_operators(self) -> None:
        """Free the loss's sparse operators when no step reads them (later calls apply them a block at a time)."""
        if not self.loss.needs_operators:
            self.loss.release_operators()

    def _initial_free_mixture(self, init: str | None = None) -> np.ndarray:
        init = self.cfg.init if init is None else init
        return initial_free_mixture(self.base.inks, self.param, init, self.cfg.seed, self.baseline)

    def initial_variables(self, init: str | None = None) -> np.ndarray:
        """The run's starting variables x (F, N) (recomputed from the configuration: same after a resume), or
        those of the start ``init`` names (e.g. "extrusion": what a run started from that baseline renders)."""
        return self.param.variables_for(self._initial_free_mixture(init), reuse=True)  # made for this call

    def initial_volume(self) -> Volume:
        """The run's starting point as a volume (the whole grid's mixture: see :meth:`renderer` for a render)."""
        return self.base.with_mixture(self.param.mixture(self.initial_variables()))

    # -------------------------------------------------------------- state
    def mixture(self) -> np.ndarray:
        return self.param.mixture(self.x)

    def mixture_slabs(self):
        """The current mixture in z slabs (``Parameterization.mixture_slabs``)."""
        return self.param.mixture_slabs(self.x)

    def volume(self) -> Volume:
        return self.base.with_mixture(self.mixture())

    def config_key(self) -> str:
        """What must match for a checkpoint to be resumable (not the iteration count): the settings, the grid,
        inks, texels, free voxels, a digest of the targets and fixed shares, and the lighting, as JSON."""
        d = asdict(self.cfg)
        for name in ("iterations", "checkpoint_every", "stop_gain", "stop_horizon", "time_budget", "finish_smooth"):
            d.pop(name)  # when the run ends and what is done after it, not how it steps (the plan is checkpointed)
        if not d["smooth"]:  # without smoothing its edge guide does nothing
            d.pop("smooth_edge")
        if d["lr"] is None and self.cfg.init not in COLD_INITS:  # a warm start's default step: written out
            d["lr"] = self.cfg.step_size
        d.update(
            shape=list(self.base.shape),
            inks=list(self.base.inks.names),
            texels=len(self.texels),
            free=self.param.n_free,
            problem=self._problem_digest,
            lighting=self.lighting.key(),
        )
        d.update({"viewing": self.viewing.key()} if self.viewing.spectral else {})  # the RGB path's key is unchanged
        return json.dumps(d, sort_keys=True)

    def save_checkpoint(self, path: Path) -> None:
        kept = {"start_figures": self.start_figures, "baseline_figures": self.baseline_figures}  # JSON objects
        extra = {k: np.array(json.dumps(v)) for k, v in kept.items() if v}
        if self.c_avg is not None:
            extra.update(c_avg=self.c_avg, c_weight=np.float64(self.c_weight), c_var=self.c_var)
        extra.update(self.viewing.checkpoint_entries())  # a spectral run's band plan
        write_checkpoint(
            path,
            {
                "x": self.x,
                "iteration": np.int64(self.iteration),
                **extra,
                "config_key": np.array(self.config_key()),
                **self.opt.state(),
                **self.history.arrays(),
                **self.schedule.to_arrays(),
                "wall_seconds": np.float64(self.wall_seconds()),
            },
        )

    def wall_seconds(self) -> float:
        """The run's wall time so far across resumes: earlier invocations up to their last checkpoint, plus this
        one since the Optimization was made."""
        return self.wall_seconds_before + time.perf_counter() - self.invocation_start

    def load_checkpoint(self, path: Path) -> None:
        d = read_checkpoint(path)
        per_texel = (len(self.texels), self.loss.channels)
        shapes = {"x": self.x.shape, "opt_m": self.opt.m.shape, "opt_v": self.opt.v.shape}
        check_state(d, path, {**shapes, "c_avg": per_texel, "c_var": per_texel})  # all or nothing is restored
        self.viewing, self._renderer = self.viewing.resumed(d), None  # the run's own band plan (before the key)
        old, new = json.loads(str(d["config_key"])), json.loads(self.config_key())
        if old != new:
            raise ParameterError(
                f"checkpoint {path} was made with different settings ({changed_settings(old, new)}); rerun "
                "without `resume` or with the original settings"
            )
        self.x = np.asarray(d["x"], np.float32)
        self.iteration = int(d["iteration"])
        self.opt.load(d)
        self.history = History.from_arrays(d)
        self.schedule.load(d, self.cfg)
        # a checkpoint without the wall time: at least the iterations' own time
        self.wall_seconds_before = (
            float(d["wall_seconds"]) if "wall_seconds" in d else float(np.sum(self.history.seconds))
        )
        self.start_figures = json.loads(str(d["start_figures"])) if "start_figures" in d else None
        self.baseline_figures = json.loads(str(d["baseline_figures"])) if "baseline_figures" in d else None
        self.c_avg = np.asarray(d["c_avg"], np.float32) if "c_avg" in d else None
        self.c_weight = float(d["c_weight"]) if "c_weight" in d else 0.0
        self.c_var = np.asarray(d["c_var"], np.float32) if "c_var" in d else None

    # -------------------------------------------------------------- one step
    def renderer(self, x: np.ndarray | None = None) -> TexelRenderer:
        """The run's renderer, set to the mixture of variables ``x`` (F, N) (default: the current ones; e.g.
        :meth:`initial_variables` to render the start without a grid-sized volume). It is built once from the
        fixed shares (an object with an inside mask: the base volume, whose medium is then replaced at every
        inside voxel that is not a variable; else the base geometry with the fixed shares as its mixture); every
        iteration then overwrites only the free voxels' media (``Renderer.set_mixture``), so no grid-sized mixture
        or coefficient array is made per step."""
        if self._renderer is None:
            if self.viewing.needs_pilot:  # a spectral run's band plan: a pilot render of its current mixture
                self.viewing = self.viewing.planned(self.volume(), self.texels, self.threads, self.lighting, self._make)
            fs, make = self.param.fixed_share, self.viewing.renderer_factory(self._make)
            if self.base.inside is not None:
                self._renderer = make(self.base, self.threads, self.lighting)
                held = self.param.held_index(self.base)
                for block in np.array_split(held, max(1, len(held) >> 20)):  # ~1 M voxels at a time
                    self._renderer.set_mixture(block, fs.at(block))
                del held
            else:
                self._renderer = make(self.base.with_mixture(fs.dense()), self.threads, self.lighting)
        x = self.x if x is None else x
        for lo, hi in self.param.chunks():  # in pieces: no (F, N) temporaries for a big object
            self._renderer.set_mixture(self.param.free_index[lo:hi], self.param.free_rows(x[lo:hi], lo))
        return self._renderer

    def release_renderer(self) -> None:
        """Drop the run's renderer (its medium: 24 B per inside voxel); a later :meth:`step` or :meth:`renderer`
        builds a new one, with identical results."""
        self._renderer = None

    def _snapshot(self) -> tuple:
        """References to what a step changes: x and the optimiser's state arrays, which it changes in place only
        at its end, with the iteration count, where an interrupt cannot stop it (``interrupt_deferred``)."""
        o = self.opt
        return (self.x, self.iteration, self.c_avg, self.c_var, self.c_weight, o.m, o.v, o.t, len(self.history.loss))

    def _restore(self, snap: tuple) -> None:
        o = self.opt
        self.x, self.iteration, self.c_avg, self.c_var, self.c_weight, o.m, o.v, o.t, n = snap
        for name in asdict(self.history):
            del getattr(self.history, name)[n:]

    def step(self) -> dict:
        cfg = self.cfg
        t0 = time.perf_counter()
        fwd_seed, grad_seed = iteration_seeds(cfg.seed, self.iteration)
        renderer = self.renderer()
        forward, passes = cfg.forward_spp > 0 or self.c_avg is None, {"forward": None}
        if forward:  # without forward passes (forward_spp 0) only the first iteration renders one
            spp0 = cfg.forward_spp or START_FORWARD_SPP
            res = renderer.render(self.texels, spp0, fwd_seed, cfg.include_specular)
            self._average(res.rgb, res.var_mean, spp0, decay=True)
            passes["forward"] = res.stats()
            del res
        t1 = time.perf_counter()
        lr = self.loss(self.c_avg, self.c_var, all_terms=False)  # the terms it optimises; the evaluation has all
        de = float(delta_e76(lr.lab, self.loss.target_lab).mean())
        adjoint, terms = lr.grad.astype(np.float32), dict(loss=lr.value, e1=lr.e1, e2=lr.e2, e3=lr.e3)
        del lr  # its per-texel arrays: not beside the gradient pass's sums (the step's peak)
        t2 = time.perf_counter()
        index = self.param.free_index
        gs, ga, gres = renderer.gradient(
            self.texels, adjoint, cfg.spp, grad_seed, cfg.include_specular, cfg.grad_method, grad_index=index
        )
        # The gradient pass's own estimate joins the average only now, after its gradient is taken, so the
        # adjoint never correlates with the noise of the gradient it multiplies.
        self._average(gres.rgb, gres.var_mean, cfg.spp, decay=not forward)
        passes["gradient"] = gres.stats()
        del gres, adjoint
        t3 = time.perf_counter()
        g_x = np.empty_like(self.x)
        for lo, hi in self.param.chunks():  # dE/dsigma -> dE/drho -> dE/dx in pieces (bit-identical)
            g_rho = mix_grad(gs[lo:hi], ga[lo:hi], self.viewing.table or self.base.inks)  # per band or channel
            g_x[lo:hi] = self.param.backward(self.x[lo:hi], g_rho, natural=self.opt.natural, lo=lo)
        del gs, ga
        self.opt.lr = cfg.step_size * step_factor(self.iteration, self.schedule.end, cfg.decay)
        with interrupt_deferred():  # x and the optimiser's state change in place: the step runs to its end
            # in place, no new (F, N) arrays; smoothed is the step (g_x becomes x' - x), not the gradient: the
            # optimiser's step scale stays its own
            self.opt.update(self.x, g_x, into_g=self.smoother is not None)
            if self.smoother is not None:
                np.add(self.x, self.smoother.apply(g_x), out=self.x)
            del g_x
            self.iteration += 1
            t4 = time.perf_counter()
            self.last_passes = passes
            times = dict(seconds=t4 - t0, render_s=t1 - t0, gradient_s=t3 - t2, loss_s=t2 - t1, step_s=t4 - t3)
            self.history.append(**terms, delta_e76=de, **times)
        return {"loss": terms["loss"], "delta_e76": de}

    def _average(self, rgb: np.ndarray, var: np.ndarray, spp: int, decay: bool) -> np.ndarray:
        """Add an estimate of ``spp`` samples per texel (variance ``var``) to the sample-weighted running average
        (first decaying the past by ``adjoint_ema`` if ``decay``); return the average. Its variance, kept in
        ``c_var``, lets the SSIM term remove the estimate's noise."""
        w_old = self.c_weight * (self.cfg.adjoint_ema if decay else 1.0)
        if self.c_avg is None or w_old <= 0:
            self.c_avg, self.c_var, self.c_weight = rgb.astype(np.float32), var.astype(np.float32), float(spp)
        else:
            tot = w_old + spp
            self.c_avg = ((w_old * self.c_avg + spp * rgb) / tot).astype(np.float32)
            self.c_var = ((w_old**2 * self.c_var + spp**2 * var) / tot**2).astype(np.float32)
            self.c_weight = tot
        return self.c_avg

    def resume(self, checkpoint: Path, log=print) -> bool:
        """Continue from ``checkpoint`` if it exists (True), else start from scratch (False)."""
        if Path(checkpoint).is_file():
            self.load_checkpoint(checkpoint)
            log(f"resuming at iteration {self.iteration} from {checkpoint}")
            return True
        log(f"no checkpoint {checkpoint}; starting from scratch")
        return False

    def plan(self, reserve: Reserve = 0.0) -> int:
        """Plan the run's end for the next step (``stopping.Schedule.plan``: converged, time budget, maximum) and
        return the iteration count the run stops at. ``reserve``: seconds the time budget keeps for after the
        last iteration (the final evaluation and writing), or a function giving them (``stopping.Reserve``)."""
        h = self.history
        self.schedule.plan(self.cfg, self.iteration, h.delta_e76, h.seconds, self.wall_seconds(), reserve)
        return min(self.cfg.iterations, self.schedule.end)

    def run(
        self,
        checkpoint: Path | None = None,
        progress: bool = False,
        log=None,
        log_every_s: float = 30.0,
        reserve: Reserve = 0.0,
        on_step: Callable[[Optimization], None] | None = None,
    ) -> None:
        """Iterate until the planned end (:meth:`plan`: at most ``cfg.iterations``, earlier when converged or by
        ``cfg.time_budget``, ``reserve`` seconds kept for after the iterations), continuing from
        ``self.iteration``, checkpointing every ``cfg.checkpoint_every`` iterations and at the end (and on Ctrl-C,
        after the current iteration). ``progress``: a tqdm bar (a terminal); else, with ``log``, a line
        (iteration, loss, ΔE76, ETA) after the first iteration, whenever ``log_every_s`` seconds have passed since
        the last, and after the last; and a line when the plan changes its reason (converged, time budget).
        ``on_step(self)``: called after every step (e.g. to keep snapshots of ``x``)."""
        bar, lines = None, None
        self.release_unread_operators()  # a full loss call (the start's figures) built them again
        end = self.plan(reserve)
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=end, initial=self.iteration, unit="it", desc="optimize")
        elif log is not None:
            lines = ProgressLines(end, self.iteration, log, log_every_s)
        snap, reason = None, self.schedule.reason
        try:
            while self.iteration < end:
                snap = self._snapshot()
                info = self.step()
                snap = None
                if on_step is not None:
                    on_step(self)
                end = self.plan(reserve)
                if checkpoint is not None and self.iteration % self.cfg.checkpoint_every == 0:
                    self.save_checkpoint(checkpoint)
                if self.schedule.reason != reason and log is not None:
                    reason = self.schedule.reason
                    log(self.plan_line())
                if bar is not None:
                    bar.total = end
                    bar.set_postfix(loss=f"{info['loss']:.3g}", dE76=f"{info['delta_e76']:.2f}")
                    bar.update(1)
                elif lines is not None:
                    lines.total = end
                    lines.update(self.iteration, info["loss"], info["delta_e76"])
        except KeyboardInterrupt:
            if snap is not None and self.iteration == snap[1]:  # interrupted before a step's update: back to its
                self._restore(snap)  # start, so a resume repeats it exactly (after it: the step is done)
            if checkpoint is not None:
                self.save_checkpoint(checkpoint)
            raise
        finally:
            if bar is not None:
                bar.close()
        if checkpoint is not None:
            self.save_checkpoint(checkpoint)

    def finish(self, passes: int | None = None) -> None:
        """Smooth the result: ``passes`` (None: ``cfg.finish_smooth``, auto as none) passes of the step's smoothing
        over x in place (none without smoothing), after the iterations and their checkpoint (it keeps the iterate)."""
        if self.smoother is None:
            return
        for _ in range(max(int(self.cfg.finish_smooth if passes is None else passes), 0)):
            self.x = self.smoother.apply(self.x)

    def plan_line(self) -> str:
        """One line on the run's planned end and why."""
        s, it = self.schedule, self.iteration
        if s.reason == "converged":
            return (
                f"converged at iteration {s.converged_at}: at most {s.gain:.2f} ΔE76 more expected over "
                f"{self.cfg.stop_horizon} iterations; the step decay runs to iteration {s.end}"
            )
        if s.reason == "time budget":
            return f"the time budget ends the run at iteration {s.end} (now {it}), the step decay planned for it"
        return f"the run ends at its maximum, {s.end} iterations"
