"""Gradient descent on the ink mixture: settings (``config``), variables (``param``), update rules
(``optimizers``), the step's spatial preconditioner (``smooth``) and the iteration loop with checkpoints
(``loop``)."""

from .checkpoint import History
from .config import OPTIMIZERS, PARAMS, SCENE_DEFAULTS, OptimizeConfig, default_lr
from .loop import Optimization, iteration_seeds
from .optimizers import AdaGrad, Adam, ExponentiatedGradient, make_optimizer
from .param import BASELINE_INITS, Parameterization, initial_free_mixture
from .smooth import GradientSmoother

__all__ = [
    "OPTIMIZERS",
    "PARAMS",
    "OptimizeConfig",
    "default_lr",
    "History",
    "Optimization",
    "iteration_seeds",
    "AdaGrad",
    "Adam",
    "ExponentiatedGradient",
    "make_optimizer",
    "BASELINE_INITS",
    "Parameterization",
    "initial_free_mixture",
    "GradientSmoother",
    "SCENE_DEFAULTS",
]
