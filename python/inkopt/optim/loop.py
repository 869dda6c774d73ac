"""Gradient descent on the ink mixture of every voxel (method.md §3 and §6).

Variables: for every *free* voxel an unconstrained vector x (N inks), mapped to a mixture by
``sigmoid`` (the paper: sigmoid, then per-voxel normalisation) or ``softmax``. Constraints are fixed ink shares:
a voxel's mixture is ``fixed_share + (1 - sum(fixed_share)) * p(x)``; a voxel whose fixed share sums to 1 is not
a variable at all (a white core below a shell, masks), and a share below 1 fixes part of the mixture (e.g. 80 %
transparent ink in a translucent region, the rest optimised).

One iteration: mixture -> coefficients -> forward render (seed a) -> loss and dE/dC -> path-replay gradient pass
(seed b != a, so the adjoint's noise and the gradient's noise are independent) -> dE/dsigma -> dE/drho -> dE/dx ->
AdaGrad or Adam step. Seeds are derived from (seed, iteration), renders and gradients are bit-identical for any
thread count, so a run resumed from a checkpoint continues exactly as if it had not stopped.
"""
from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from .loss import TexelLoss, delta_e76
from .materials import InkTable, mix_grad
from .render import Renderer
from .volume import Texels, Volume, save_npz

PARAMS = ("sigmoid", "softmax")
EG_WARMUP = 5  # iterations over which the exponentiated-gradient step scale is measured
OPTIMIZERS = ("eg", "adam", "adagrad")


@dataclass
class OptimizeConfig:
    iterations: int = 200
    #: samples per texel of the gradient pass (unbiased at any spp; fewer is noisier)
    spp: int = 4
    #: samples per texel of the forward render that the adjoint dE/dC is evaluated at. dE/dC is a nonlinear
    #: function of C (CIELAB is steep near black): evaluated at a few-spp estimate its expectation is biased, for
    #: dark colours even in sign (measured: bench/README), so the adjoint gets more samples than the gradient.
    forward_spp: int = 16
    #: loss weights (colour, SSIM, edges). Colour only by default: the SSIM term evaluated on a Monte Carlo
    #: estimate is biased towards lower contrast (the estimate's noise inflates its local variance), which on a
    #: black/white zebra chart lowered SSIM from 0.66 to 0.44 (README, "Known limits").
    gamma: tuple[float, float, float] = (1.0, 0.0, 0.0)
    lr: float | None = None  # default per optimizer: see default_lr
    optimizer: str = "eg"
    param: str = "softmax"
    init: str = "white"  # "white" (97 % white), "random", or a path to a volume .npz with a mixture
    seed: int = 0
    grad_method: str = "replay"
    checkpoint_every: int = 10
    include_specular: bool = True
    #: Per-iteration decay of the sample-weighted running average of the prediction that the adjoint is evaluated
    #: at (0: this iteration's forward render only). The mixture changes slowly, so averaging over iterations
    #: multiplies the adjoint's samples (~ (forward_spp + spp) / (1 - decay)) at no rendering cost.
    adjoint_ema: float = 0.8

    def validate(self) -> None:
        if self.iterations < 0:
            raise ValueError(f"iterations must be >= 0, got {self.iterations}")
        if self.spp < 1 or self.forward_spp < 1:
            raise ValueError(f"spp and forward spp must be >= 1, got {self.spp}, {self.forward_spp}")
        if self.param not in PARAMS:
            raise ValueError(f"unknown parameterisation '{self.param}'; use one of {PARAMS}")
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"unknown optimizer '{self.optimizer}'; use one of {OPTIMIZERS}")
        if self.grad_method not in ("replay", "li1"):
            raise ValueError(f"unknown gradient method '{self.grad_method}'; use replay or li1")
        if self.optimizer == "eg" and self.param != "softmax":
            raise ValueError("the exponentiated-gradient optimizer works on the softmax parameterisation")
        if self.lr is not None and not self.lr > 0:
            raise ValueError(f"learning rate must be positive, got {self.lr}")
        if self.checkpoint_every < 1:
            raise ValueError("checkpoint_every must be >= 1")
        if not 0.0 <= self.adjoint_ema < 1.0:
            raise ValueError(f"adjoint_ema must lie in [0, 1), got {self.adjoint_ema}")

    @property
    def step_size(self) -> float:
        return self.lr if self.lr is not None else default_lr(self.optimizer)


def default_lr(optimizer: str) -> float:
    """Step sizes in logit units (eg: of the most influential voxels) that converge in ~100-200 iterations on
    the test charts (see bench/)."""
    return {"eg": 2.0, "adagrad": 0.5, "adam": 0.1}[optimizer]


# ----------------------------------------------------------------------------------------- parameterisation
class Parameterization:
    """Maps variables x (F, N) of the free voxels to the full mixture (z, y, x, N), and gradients back.

    fixed_share: (z, y, x, N) float32 ink shares the optimiser may not change (all zero: everything free).
    """

    def __init__(self, kind: str, fixed_share: np.ndarray):
        if kind not in PARAMS:
            raise ValueError(f"unknown parameterisation '{kind}'")
        fixed_share = np.asarray(fixed_share, np.float32)
        total = fixed_share.sum(-1)
        if np.any(fixed_share < 0) or np.any(total > 1 + 1e-5):
            raise ValueError("fixed ink shares must be non-negative and sum to at most 1 per voxel")
        self.kind = kind
        self.fixed_share = fixed_share
        self.free_share = np.clip(1.0 - total, 0.0, 1.0)
        self.free_index = np.flatnonzero(self.free_share.reshape(-1) > 1e-6)
        self.n_inks = fixed_share.shape[-1]
        # Gradient slot of every voxel (-1: not a variable), for the renderer's sparse gradient.
        self.grad_index = np.full(fixed_share.shape[:3], -1, np.int32)
        self.grad_index.reshape(-1)[self.free_index] = np.arange(len(self.free_index), dtype=np.int32)

    @property
    def n_free(self) -> int:
        return len(self.free_index)

    def _p(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Free-part mixture p (F, N) and an auxiliary array for the backward pass."""
        if self.kind == "softmax":
            e = np.exp(x - x.max(axis=1, keepdims=True))
            p = e / e.sum(axis=1, keepdims=True)
            return p, p
        s = 1.0 / (1.0 + np.exp(-x))
        return s / s.sum(axis=1, keepdims=True), s

    def mixture(self, x: np.ndarray) -> np.ndarray:
        rho = self.fixed_share.copy().reshape(-1, self.n_inks)
        p, _ = self._p(x)
        rho[self.free_index] += self.free_share.reshape(-1)[self.free_index, None] * p
        return rho.reshape(self.fixed_share.shape)

    def backward(self, x: np.ndarray, grad_rho: np.ndarray, natural: bool = False) -> np.ndarray:
        """dE/dx (F, N) from dE/drho, given per free voxel (F, N) or for the whole grid (z, y, x, N).
        ``natural``: the mirror-descent direction on the simplex instead (softmax only): g - <g, p>, the
        exponentiated-gradient step in logit space."""
        g = grad_rho.reshape(-1, self.n_inks)
        if len(g) != self.n_free:
            g = g[self.free_index]
        g = g * self.free_share.reshape(-1)[self.free_index, None]
        p, aux = self._p(x)
        centred = g - np.sum(g * p, axis=1, keepdims=True)
        if natural:
            if self.kind != "softmax":
                raise ValueError("the natural (exponentiated-gradient) direction needs the softmax parameterisation")
            return centred.astype(np.float32)
        if self.kind == "softmax":
            return (p * centred).astype(np.float32)
        s = aux
        return (centred * s * (1.0 - s) / s.sum(axis=1, keepdims=True)).astype(np.float32)

    def variables_for(self, p: np.ndarray) -> np.ndarray:
        """Variables x (F, N) whose free-part mixture is p (F, N) (entries clipped to [1e-6, 1])."""
        p = np.clip(np.asarray(p, np.float64), 1e-6, 1.0)
        p /= p.sum(axis=1, keepdims=True)
        if self.kind == "softmax":
            return np.log(p).astype(np.float32)
        return np.log(p / (1.0 - p + 1e-12)).astype(np.float32)  # sigmoid(x) = p, and sum(p) = 1


BASELINE_INITS = ("surface", "extrusion")


def initial_free_mixture(inks: InkTable, param: Parameterization, init: str, seed: int,
                         baseline: Callable[[str], np.ndarray] | None = None) -> np.ndarray:
    """The free part's starting mixture (F, N): 97 % white + the rest split over the other inks (paper), a seeded
    random mixture, a print-shop baseline ("surface" or "extrusion", see ``baselines``; ``baseline(kind)`` returns
    its full (z, y, x, N) mixture), or the mixture of an earlier result file."""
    n, f = len(inks), param.n_free
    if init == "white":
        if "white" not in inks.names:
            raise ValueError("--init white needs a 'white' ink in the ink set; use --init random")
        p = np.full((f, n), 0.03 / max(n - 1, 1), np.float64)
        p[:, inks.index("white")] = 0.97 if n > 1 else 1.0
        return p
    if init == "random":
        return np.random.default_rng(seed).dirichlet(np.ones(n), size=f)
    if init in BASELINE_INITS:
        if baseline is None:
            raise ValueError(f"--init {init} needs the run's texels and targets")
        rho = np.asarray(baseline(init), np.float64).reshape(-1, n)[param.free_index]
        fixed = param.fixed_share.reshape(-1, n)[param.free_index]
        share = param.free_share.reshape(-1)[param.free_index, None]
        p = np.clip(rho - fixed, 0.0, None) / share
        total = p.sum(1, keepdims=True)
        return np.where(total > 0, p / np.where(total > 0, total, 1.0), 1.0 / n)
    vol = Volume.load(init)
    if vol.form != "mixture" or vol.inks.names != inks.names:
        raise ValueError(f"--init {init}: needs a mixture volume with inks {list(inks.names)}")
    if vol.shape != param.fixed_share.shape[:3]:
        raise ValueError(f"--init {init}: volume shape {vol.shape} differs from {param.fixed_share.shape[:3]}")
    return vol.mixture.reshape(-1, n)[param.free_index].astype(np.float64)


# ----------------------------------------------------------------------------------------- optimizers
class Optimizer:
    """Steps on the variables; state arrays are saved in checkpoints.

    - ``eg``: exponentiated gradient (mirror descent on the simplex) with momentum. ``g`` is the natural direction
      (``Parameterization.backward(natural=True)``); the step is lr * m / s with m the momentum average (0.8) and s
      a running average (0.9) of the 99th percentile of |g|: the most influential voxels move by about lr per
      iteration, voxels that barely affect the surface (deep ones) move in proportion to their influence instead of
      random-walking on their gradient noise as under per-coordinate normalisation.
    - ``adagrad`` (the paper) and ``adam``: per-coordinate normalised steps on dE/dx.
    """

    def __init__(self, kind: str, lr: float, shape):
        self.kind, self.lr, self.t = kind, lr, 0
        self.m = np.zeros(shape, np.float32)
        self.v = np.zeros(shape if kind != "eg" else (1,), np.float32)

    @property
    def natural(self) -> bool:
        return self.kind == "eg"

    def step(self, x: np.ndarray, g: np.ndarray) -> np.ndarray:
        self.t += 1
        if self.kind == "eg":
            b1 = 0.8
            if self.t <= EG_WARMUP:  # the step scale: mean over the first iterations, then frozen
                scale = float(np.percentile(np.abs(g), 99)) if g.size else 0.0
                self.v[0] += (scale - self.v[0]) / self.t
            self.m = b1 * self.m + (1 - b1) * g
            mh = self.m / (1 - b1 ** self.t)
            return x - self.lr * mh / (self.v[0] + 1e-30)
        if self.kind == "adagrad":
            self.v += g * g
            return x - self.lr * g / (np.sqrt(self.v) + 1e-8)
        b1, b2 = 0.9, 0.999
        self.m = b1 * self.m + (1 - b1) * g
        self.v = b2 * self.v + (1 - b2) * g * g
        mh = self.m / (1 - b1 ** self.t)
        vh = self.v / (1 - b2 ** self.t)
        return x - self.lr * mh / (np.sqrt(vh) + 1e-8)

    def state(self) -> dict:
        return {"opt_m": self.m, "opt_v": self.v, "opt_t": np.int64(self.t)}

    def load(self, d) -> None:
        self.m, self.v, self.t = np.asarray(d["opt_m"]), np.asarray(d["opt_v"]), int(d["opt_t"])


# ----------------------------------------------------------------------------------------- the loop
@dataclass
class History:
    loss: list = field(default_factory=list)
    e1: list = field(default_factory=list)
    e2: list = field(default_factory=list)
    e3: list = field(default_factory=list)
    delta_e76: list = field(default_factory=list)
    seconds: list = field(default_factory=list)
    render_s: list = field(default_factory=list)
    gradient_s: list = field(default_factory=list)
    loss_s: list = field(default_factory=list)
    step_s: list = field(default_factory=list)

    def append(self, **kw):
        for k, v in kw.items():
            getattr(self, k).append(float(v))

    def arrays(self) -> dict:
        return {f"hist_{k}": np.asarray(v, np.float64) for k, v in asdict(self).items()}

    @classmethod
    def from_arrays(cls, d) -> "History":
        return cls(**{k: [float(x) for x in d[f"hist_{k}"]] for k in asdict(cls()) if f"hist_{k}" in d})


def iteration_seeds(seed: int, it: int) -> tuple[int, int]:
    """(forward seed, gradient seed) of iteration ``it``: distinct, and independent of everything else."""
    base = (int(seed) * 1_000_003 + 2 * int(it)) % (2**63)
    return base, base + 1


class Optimization:
    """An optimisation run over a volume's mixture.

    base: a mixture Volume giving the geometry and ink table (its mixture is ignored); texels and target_rgb
    (I, 3) linear; fixed_share (z, y, x, N) float32 or None.
    """

    def __init__(self, base: Volume, texels: Texels, target_rgb: np.ndarray, cfg: OptimizeConfig,
                 fixed_share: np.ndarray | None = None, threads: int | None = None):
        cfg.validate()
        if base.inks is None:
            raise ValueError("the volume needs an ink table")
        self.base, self.texels, self.cfg, self.threads = base, texels, cfg, threads
        self.target = np.asarray(target_rgb, np.float32)
        shape = base.shape + (len(base.inks),)
        self.param = Parameterization(cfg.param, np.zeros(shape, np.float32) if fixed_share is None else fixed_share)
        self.loss = TexelLoss(self.target, texels.pos_vox, gamma=cfg.gamma)
        self.x = self.param.variables_for(self._initial_free_mixture())
        self.opt = Optimizer(cfg.optimizer, cfg.step_size, self.x.shape)
        self.iteration = 0
        self.history = History()
        self.c_avg: np.ndarray | None = None  # running average of the prediction (I, 3)
        self.c_weight = 0.0                     # its effective number of samples per texel
        self.c_var: np.ndarray | None = None    # the variance of the running average (I, 3)

    def _initial_free_mixture(self) -> np.ndarray:
        return initial_free_mixture(self.base.inks, self.param, self.cfg.init, self.cfg.seed, self._baseline)

    def _baseline(self, kind: str) -> np.ndarray:
        """The full mixture of a print-shop baseline for this run's texels (colour table cached on disk)."""
        from . import baselines

        scene = {**self.texels.to_arrays(), "target_rgb": self.target, "fixed_share": self.param.fixed_share}
        make = baselines.surface_baseline if kind == "surface" else baselines.extrusion_baseline
        return make(self.base, scene, progress=True)

    def initial_volume(self) -> Volume:
        """The run's starting point as a volume (recomputed from the configuration: same after a resume)."""
        return self.base.with_mixture(self.param.mixture(self.param.variables_for(self._initial_free_mixture())))

    # -------------------------------------------------------------- state
    def mixture(self) -> np.ndarray:
        return self.param.mixture(self.x)

    def volume(self) -> Volume:
        return self.base.with_mixture(self.mixture())

    def config_key(self) -> str:
        """What must match for a checkpoint to be resumable (not the iteration count)."""
        d = asdict(self.cfg)
        d.pop("iterations")
        d.pop("checkpoint_every")
        d.update(shape=list(self.base.shape), inks=list(self.base.inks.names), texels=len(self.texels),
                 free=self.param.n_free)
        return json.dumps(d, sort_keys=True)

    def save_checkpoint(self, path: Path) -> None:
        extra = {} if self.c_avg is None else {"c_avg": self.c_avg, "c_weight": np.float64(self.c_weight),
                                                "c_var": self.c_var}
        save_npz(path, {"x": self.x, "iteration": np.int64(self.iteration), **extra,
                        "config_key": np.array(self.config_key()), **self.opt.state(), **self.history.arrays()},
                 compressed=False)

    def load_checkpoint(self, path: Path) -> None:
        d = np.load(path, allow_pickle=False)
        if str(d["config_key"]) != self.config_key():
            raise ValueError(f"checkpoint {path} was made with different settings; rerun without --resume or "
                             "with the original settings")
        self.x = np.asarray(d["x"], np.float32)
        self.iteration = int(d["iteration"])
        self.opt.load(d)
        self.history = History.from_arrays(d)
        self.c_avg = np.asarray(d["c_avg"], np.float32) if "c_avg" in d else None
        self.c_weight = float(d["c_weight"]) if "c_weight" in d else 0.0
        self.c_var = np.asarray(d["c_var"], np.float32) if "c_var" in d else None

    # -------------------------------------------------------------- one step
    def step(self) -> dict:
        cfg = self.cfg
        t0 = time.perf_counter()
        fwd_seed, grad_seed = iteration_seeds(cfg.seed, self.iteration)
        renderer = Renderer(self.volume(), self.threads)
        res = renderer.render(self.texels, cfg.forward_spp, fwd_seed, cfg.include_specular)
        t1 = time.perf_counter()
        c = self._average(res.rgb, res.var_mean, cfg.forward_spp, decay=True)
        lr = self.loss(c, self.c_var)
        de = float(delta_e76(lr.lab, self.loss.target_lab).mean())
        t2 = time.perf_counter()
        gs, ga, gres = renderer.gradient(self.texels, lr.grad.astype(np.float32), cfg.spp, grad_seed,
                                         cfg.include_specular, cfg.grad_method, grad_index=self.param.grad_index)
        # The gradient pass's own estimate joins the average only now, after its gradient is taken, so the
        # adjoint never correlates with the noise of the gradient it multiplies.
        self._average(gres.rgb, gres.var_mean, cfg.spp, decay=False)
        t3 = time.perf_counter()
        g_x = self.param.backward(self.x, mix_grad(gs, ga, self.base.inks), natural=self.opt.natural)
        self.x = self.opt.step(self.x, g_x).astype(np.float32)
        self.iteration += 1
        t4 = time.perf_counter()
        self.history.append(loss=lr.value, e1=lr.e1, e2=lr.e2, e3=lr.e3, delta_e76=de, seconds=t4 - t0,
                            render_s=t1 - t0, gradient_s=t3 - t2, loss_s=t2 - t1, step_s=t4 - t3)
        return {"loss": lr.value, "delta_e76": de}

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
            self.c_var = ((w_old ** 2 * self.c_var + spp ** 2 * var) / tot ** 2).astype(np.float32)
            self.c_weight = tot
        return self.c_avg

    def start(self, out: Path, resume: bool, log=print) -> Path:
        """Create the run directory ``out`` and, with ``resume``, continue from its checkpoint if there is one.
        Returns the checkpoint path for :meth:`run`."""
        ckpt = Path(out) / "checkpoint.npz"
        Path(out).mkdir(parents=True, exist_ok=True)
        if resume and ckpt.is_file():
            self.load_checkpoint(ckpt)
            log(f"resuming at iteration {self.iteration} from {ckpt}")
        elif resume:
            log(f"no checkpoint in {out}; starting from scratch")
        return ckpt

    def run(self, checkpoint: Path | None = None, progress: bool = False) -> None:
        """Iterate up to ``cfg.iterations`` (continuing from ``self.iteration``), checkpointing every
        ``cfg.checkpoint_every`` iterations and at the end (and on Ctrl-C, after the current iteration)."""
        bar = None
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=self.cfg.iterations, initial=self.iteration, unit="it", desc="optimize")
        try:
            while self.iteration < self.cfg.iterations:
                info = self.step()
                if checkpoint is not None and self.iteration % self.cfg.checkpoint_every == 0:
                    self.save_checkpoint(checkpoint)
                if bar is not None:
                    bar.set_postfix(loss=f"{info['loss']:.3g}", dE76=f"{info['delta_e76']:.2f}")
                    bar.update(1)
        except KeyboardInterrupt:
            if checkpoint is not None:
                self.save_checkpoint(checkpoint)
            raise
        finally:
            if bar is not None:
                bar.close()
        if checkpoint is not None:
            self.save_checkpoint(checkpoint)


def evaluate_prediction(loss: TexelLoss, rgb: np.ndarray, var: np.ndarray | None = None) -> dict:
    """Quality figures of a prediction (I, 3) linear RGB against the loss's target; ``var`` (I, 3), the
    prediction's Monte Carlo variance, makes SSIM an estimate for the noise-free prediction."""
    from .loss import delta_e2000

    r = loss(rgb, var)
    de = delta_e76(r.lab, loss.target_lab)
    return {"delta_e76_mean": float(de.mean()), "delta_e76_p95": float(np.percentile(de, 95)),
            "delta_e2000_mean": float(delta_e2000(r.lab, loss.target_lab).mean()),
            "ssim": float(loss.ssim_mean(rgb, var)), "loss": r.value, "e1": r.e1, "e2": r.e2, "e3": r.e3}
