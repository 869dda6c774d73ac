"""Update rules on the optimisation variables x (F, N), one class per optimiser with named hyperparameters.

Each has ``update(x, g, into_g=False)``, which changes x (or, with ``into_g``, writes the step x' - x into g) and its
own state arrays in place, ``step(x, g) -> x'`` (the same update on copies: x' a new array, and state arrays replaced
rather than changed), ``state() -> dict`` and ``load(dict)`` (checkpoint arrays ``opt_m``, ``opt_v``, ``opt_t``, the
same keys for every optimiser so that checkpoints stay readable), and ``natural``: whether it wants the
mirror-descent direction (``Parameterization.backward(natural=True)``) instead of dE/dx.

The element-wise updates run over blocks of ``ROWS`` rows and make no (F, N) temporaries: the exponentiated
gradient's in the Rust core, AdaGrad's and Adam's in numpy; each block computes exactly what the whole-array
expression would, so ``update`` and ``step`` agree bit for bit. In place, a step of F free voxels needs no memory
beyond x, the state and g (``step`` adds a new x and new state arrays: 40 B per free voxel for 5 inks).
``threads``: of the Rust kernels (default all cores; results do not depend on it).
"""

from __future__ import annotations

import numpy as np

from ..threads import check_threads

#: rows per block of the element-wise updates
ROWS = 1 << 18


def _blocks(n: int):
    return (slice(lo, lo + ROWS) for lo in range(0, max(n, 1), ROWS))


def _rows(a) -> np.ndarray:
    """a as a 2-D array of rows (its last axis the columns; a 1-D array as one column)."""
    a = np.asarray(a)
    return a.reshape(len(a) if a.size == 0 else -1, a.shape[-1]) if a.ndim >= 2 else a.reshape(-1, 1)


class _Moments:
    """First/second moment arrays and the step count, saved in checkpoints."""

    natural = False

    def __init__(self, lr: float, shape, v_shape=None, threads: int | None = None):
        self.lr, self.t, self.threads = float(lr), 0, check_threads(threads)
        self.m = np.zeros(shape, np.float32)
        self.v = np.zeros(shape if v_shape is None else v_shape, np.float32)

    def state(self) -> dict:
        return {"opt_m": self.m, "opt_v": self.v, "opt_t": np.int64(self.t)}

    def load(self, d) -> None:
        self.m, self.v, self.t = np.array(d["opt_m"]), np.array(d["opt_v"]), int(d["opt_t"])  # own copies

    def update(self, x: np.ndarray, g: np.ndarray, into_g: bool = False) -> None:
        """One step from x (F, N) float32 with gradient g (F, N) float32, in place: x becomes x' (or, with
        ``into_g``, g becomes the step x' - x in float32 and x is left as it is), the state arrays are changed in
        place and ``t`` advances."""
        self.t += 1
        self._prepare(g)
        for b in _blocks(len(x)):
            x_new = self._block(x[b], g[b], b)
            if into_g:
                np.subtract(x_new, x[b], out=g[b])
            else:
                x[b] = x_new

    def step(self, x: np.ndarray, g: np.ndarray) -> np.ndarray:
        """x' (a new array) of one step from x with gradient g; the state arrays are replaced, not changed in
        place, so that references to the old ones keep the state before the step."""
        self.m, self.v = (np.array(a, self._dtype(a, g)) for a in (self.m, self.v))
        x_new = np.array(x, self._dtype(x, g))
        self.update(x_new, g)
        return x_new

    @staticmethod
    def _dtype(a: np.ndarray, g: np.ndarray):
        """The dtype of a new x or state array made from ``a`` in a step with gradient ``g``."""
        return np.result_type(a, g)

    def _prepare(self, g: np.ndarray) -> None:
        """What a step computes over the whole gradient before its blocks (after ``t`` advanced)."""

    def _block(self, x: np.ndarray, g: np.ndarray, b: slice) -> np.ndarray:
        """x' of the rows ``b`` (x and g: those rows), the state's rows ``b`` updated in place."""
        raise NotImplementedError


class ExponentiatedGradient(_Moments):
    """Exponentiated gradient (mirror descent on the simplex) with momentum.

    ``g`` is the natural direction. The step is ``lr * m / s``: ``m`` the bias-corrected momentum average
    (``beta``) of g, and ``s`` the step scale, the MEAN of the 99th percentile of |g| over the first ``warmup``
    iterations, then frozen (kept in ``v[0]``). The most influential voxels move by about ``lr`` per iteration;
    voxels that barely affect the surface (deep ones) move in proportion to their influence instead of
    random-walking on their gradient noise as under per-coordinate normalisation.

    ``held_rows``: rows of voxels that are not variables but belong to the percentile's population with a zero
    gradient (the core below a shell, ``Optimization``): the percentile is taken over the object's inside voxels,
    not only the free ones, so a shell run, whose free voxels are the surface's, steps as far as the run with every
    voxel free does (its deep voxels' |g| lie far below the 99th percentile); 0 (every voxel free) leaves the
    percentile that of g alone, bit for bit. Spot 20 mm with a 1 mm shell stepped 0.82 times as far as the all-free
    run over the free voxels alone, 0.99 times with its core counted (bench/results/step_scale_spot.json).

    The update and the percentile run in the Rust core (``inkopt_core::kernels::step``, on ``threads`` threads,
    default all cores), in float32 exactly as numpy evaluates ``x - lr * (m / bias) / s`` and ``np.percentile``:
    without the whole-array temporaries of numpy or the copy of |g| that its percentile partitions (the timings
    that moved them: docs/experiments.md, "Speed and memory").
    """

    natural = True

    def __init__(
        self,
        lr: float,
        shape,
        beta: float = 0.8,
        warmup: int = 5,
        percentile: float = 99.0,
        threads: int | None = None,
        held_rows: int = 0,
    ):
        super().__init__(lr, shape, v_shape=(1,), threads=threads)
        self.beta, self.warmup, self.percentile, self.held_rows = beta, warmup, percentile, int(held_rows)

    @staticmethod
    def _dtype(a: np.ndarray, g: np.ndarray):
        return np.float32  # the Rust step's

    def _prepare(self, g: np.ndarray) -> None:
        if self.t <= self.warmup:
            g2 = np.ascontiguousarray(_rows(g), np.float32)
            zeros = self.held_rows * g2.shape[1]
            scale = abs_percentile(g2, self.percentile, self.threads, zeros) if g2.size else 0.0
            self.v[0] += (scale - self.v[0]) / self.t

    def _block(self, x: np.ndarray, g: np.ndarray, b: slice) -> np.ndarray:
        from .. import _core

        bias, scale = 1 - self.beta**self.t, self.v[0] + 1e-30
        rows = (np.ascontiguousarray(_rows(a), np.float32) for a in (x, self.m[b], g))
        x_new, m_new = _core.momentum_step(*rows, self.beta, self.lr, bias, float(scale), self.threads)
        self.m[b] = m_new.reshape(self.m[b].shape)
        return x_new.reshape(np.shape(x))


def abs_percentile(g: np.ndarray, q: float, threads: int | None = None, zeros: int = 0) -> float:
    """``np.percentile(np.abs(g), q)`` (its default, linear method, bit for bit) of a float32 array g (rows, n) with
    at least one entry, from two exact order statistics (``_core.abs_order_statistics``) instead of a partitioned
    copy of |g|; with ``zeros``, of g and that many more entries of 0 (without making them)."""
    from .. import _core

    n, qf = g.size + zeros, q / 100
    virtual = (n - 1) * qf  # numpy's virtual index of the linear method, in its order of operations
    lo = int(np.clip(np.floor(virtual), 0, n - 1))
    hi = min(lo + 1, n - 1)
    t = virtual - lo
    ranks = [max(lo - zeros, 0), max(hi - zeros, 0)]  # below rank `zeros` the entries are the zeros
    a, b = (np.float32(v) for v in _core.abs_order_statistics(g, ranks, threads))
    a, b = (np.float32(0.0) if r < zeros else v for r, v in ((lo, a), (hi, b)))
    d = np.float32(b - a)
    return float(a + d * t) if t < 0.5 else float(b - d * (1 - t))


class AdaGrad(_Moments):
    """AdaGrad (the paper): per-coordinate steps ``lr * g / sqrt(sum g²)``."""

    def __init__(self, lr: float, shape, eps: float = 1e-8, threads: int | None = None):
        super().__init__(lr, shape, threads=threads)
        self.eps = eps

    def _block(self, x: np.ndarray, g: np.ndarray, b: slice) -> np.ndarray:
        v = self.v[b] + g * g
        self.v[b] = v
        return x - self.lr * g / (np.sqrt(v) + self.eps)


class Adam(_Moments):
    """Adam with bias correction."""

    def __init__(
        self, lr: float, shape, beta1: float = 0.9, beta2: float = 0.999, eps: float = 1e-8, threads: int | None = None
    ):
        super().__init__(lr, shape, threads=threads)
        self.beta1, self.beta2, self.eps = beta1, beta2, eps

    def _block(self, x: np.ndarray, g: np.ndarray, b: slice) -> np.ndarray:
        b1, b2 = self.beta1, self.beta2
        c1, c2 = 1 - b1**self.t, 1 - b2**self.t
        m = b1 * self.m[b] + (1 - b1) * g
        v = b2 * self.v[b] + (1 - b2) * g * g
        self.m[b], self.v[b] = m, v
        return x - self.lr * (m / c1) / (np.sqrt(v / c2) + self.eps)


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


def make_optimizer(kind: str, lr: float, shape, threads: int | None = None, held_rows: int = 0):
    """The optimiser named ``kind`` (``OptimizeConfig.optimizer``) with its default hyperparameters; ``threads``: of
    its Rust kernels (default all cores; results do not depend on it); ``held_rows``: the voxels held fixed that
    the exponentiated gradient's step scale counts with a zero gradient (``ExponentiatedGradient``)."""
    if kind not in OPTIMIZER_CLASSES:
        raise ValueError(f"unknown optimizer '{kind}'; use one of {tuple(OPTIMIZER_CLASSES)}")
    if kind == "eg":
        return ExponentiatedGradient(lr, shape, threads=threads, held_rows=held_rows)
    return OPTIMIZER_CLASSES[kind](lr, shape, threads=threads)
