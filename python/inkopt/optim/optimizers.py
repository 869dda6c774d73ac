"""Update rules on the optimisation variables x (F, N), one class per optimiser with named hyperparameters.

Each has ``step(x, g) -> x'`` (x' a new array the optimiser keeps no reference to, which the loop may change in place;
it replaces its state arrays rather than changing them in place, so a snapshot of references restores an
interrupted step exactly), ``state() -> dict`` and ``load(dict)`` (checkpoint arrays ``opt_m``,
``opt_v``, ``opt_t``, the same keys for every optimiser so that checkpoints stay readable), and ``natural``: whether it
wants the mirror-descent direction (``Parameterization.backward(natural=True)``) instead of dE/dx.

The element-wise updates run over blocks of rows into the new arrays, so that a big object's step makes no
(F, N) temporaries beyond its results (each block computes exactly what the whole-array expression would).
"""

from __future__ import annotations

import numpy as np

#: rows per block of the element-wise updates
ROWS = 1 << 18


def _blocks(n: int):
    return (slice(lo, lo + ROWS) for lo in range(0, max(n, 1), ROWS))


class _Moments:
    """First/second moment arrays and the step count, saved in checkpoints."""

    natural = False

    def __init__(self, lr: float, shape, v_shape=None):
        self.lr, self.t = float(lr), 0
        self.m = np.zeros(shape, np.float32)
        self.v = np.zeros(shape if v_shape is None else v_shape, np.float32)

    def state(self) -> dict:
        return {"opt_m": self.m, "opt_v": self.v, "opt_t": np.int64(self.t)}

    def load(self, d) -> None:
        self.m, self.v, self.t = np.array(d["opt_m"]), np.array(d["opt_v"]), int(d["opt_t"])  # own copies


class ExponentiatedGradient(_Moments):
    """Exponentiated gradient (mirror descent on the simplex) with momentum.

    ``g`` is the natural direction. The step is ``lr * m / s``: ``m`` the bias-corrected momentum average
    (``beta``) of g, and ``s`` the step scale, the MEAN of the 99th percentile of |g| over the first ``warmup``
    iterations, then frozen (kept in ``v[0]``). The most influential voxels move by about ``lr`` per iteration;
    voxels that barely affect the surface (deep ones) move in proportion to their influence instead of
    random-walking on their gradient noise as under per-coordinate normalisation.
    """

    natural = True

    def __init__(self, lr: float, shape, beta: float = 0.8, warmup: int = 5, percentile: float = 99.0):
        super().__init__(lr, shape, v_shape=(1,))
        self.beta, self.warmup, self.percentile = beta, warmup, percentile

    def step(self, x: np.ndarray, g: np.ndarray) -> np.ndarray:
        self.t += 1
        if self.t <= self.warmup:
            scale = float(np.percentile(np.abs(g), self.percentile, overwrite_input=True)) if g.size else 0.0
            self.v = self.v.copy()  # a new array: state is replaced, never changed in place
            self.v[0] += (scale - self.v[0]) / self.t
        m_new = np.empty(self.m.shape, np.result_type(self.m, g))  # the dtypes of the whole-array expression
        x_new = np.empty(x.shape, np.result_type(x, m_new, self.v))
        bias, scale = 1 - self.beta**self.t, self.v[0] + 1e-30
        for b in _blocks(len(x)):
            m = self.beta * self.m[b] + (1 - self.beta) * g[b]
            m_new[b] = m
            x_new[b] = x[b] - self.lr * (m / bias) / scale
        self.m = m_new
        return x_new


class AdaGrad(_Moments):
    """AdaGrad (the paper): per-coordinate steps ``lr * g / sqrt(sum g²)``."""

    def __init__(self, lr: float, shape, eps: float = 1e-8):
        super().__init__(lr, shape)
        self.eps = eps

    def step(self, x: np.ndarray, g: np.ndarray) -> np.ndarray:
        self.t += 1
        v_new = np.empty(self.v.shape, np.result_type(self.v, g))
        x_new = np.empty(x.shape, np.result_type(x, g, v_new))
        for b in _blocks(len(x)):
            v = self.v[b] + g[b] * g[b]
            v_new[b] = v
            x_new[b] = x[b] - self.lr * g[b] / (np.sqrt(v) + self.eps)
        self.v = v_new
        return x_new


class Adam(_Moments):
    """Adam with bias correction."""

    def __init__(self, lr: float, shape, beta1: float = 0.9, beta2: float = 0.999, eps: float = 1e-8):
        super().__init__(lr, shape)
        self.beta1, self.beta2, self.eps = beta1, beta2, eps

    def step(self, x: np.ndarray, g: np.ndarray) -> np.ndarray:
        self.t += 1
        b1, b2 = self.beta1, self.beta2
        c1, c2 = 1 - b1**self.t, 1 - b2**self.t
        m_new = np.empty(self.m.shape, np.result_type(self.m, g))
        v_new = np.empty(self.v.shape, np.result_type(self.v, g))
        x_new = np.empty(x.shape, np.result_type(x, m_new, v_new))
        for b in _blocks(len(x)):
            m = b1 * self.m[b] + (1 - b1) * g[b]
            v = b2 * self.v[b] + (1 - b2) * g[b] * g[b]
            m_new[b], v_new[b] = m, v
            x_new[b] = x[b] - self.lr * (m / c1) / (np.sqrt(v / c2) + self.eps)
        self.m, self.v = m_new, v_new
        return x_new


#: Halvings of the step size over the decay phase (:func:`step_factor`): the last steps are an eighth of the first
DECAY_HALVINGS = 3


def step_factor(iteration: int, iterations: int, decay: float, halvings: int = DECAY_HALVINGS) -> float:
    """Factor on the step size at ``iteration`` (0-based) of a run of ``iterations``: 1 until the run's last
    ``decay`` fraction, then halved ``halvings`` times in equal stages ("step decay"; 0 or no decay: always 1).

    Why: a constant step with stochastic gradients does not settle at the optimum but keeps the mixtures moving
    about it by an amount that grows with the step, and that voxel-to-voxel variation is what SSIM's structure term
    sees (on a black-and-white chart as chroma from stripe to stripe). Halving the step a few times at the end lets
    the mixtures settle (experiments/results/convergence_{zebra,astronaut}.json, docs/experiments.md). A function
    of the iteration and the run's length only, so a resumed run steps exactly as an uninterrupted one of the same
    length.
    """
    start = (1.0 - decay) * iterations
    if decay <= 0 or iteration < start:
        return 1.0
    return 0.5 ** min(halvings, 1 + int(halvings * (iteration - start) / (decay * iterations)))


OPTIMIZER_CLASSES = {"eg": ExponentiatedGradient, "adagrad": AdaGrad, "adam": Adam}


def make_optimizer(kind: str, lr: float, shape):
    """The optimiser named ``kind`` (``OptimizeConfig.optimizer``) with its default hyperparameters."""
    if kind not in OPTIMIZER_CLASSES:
        raise ValueError(f"unknown optimizer '{kind}'; use one of {tuple(OPTIMIZER_CLASSES)}")
    return OPTIMIZER_CLASSES[kind](lr, shape)
