"""A spatial preconditioner for the gradient: a few explicit diffusion steps over the free voxels' 6-neighbour
grid ("large steps" for voxel fields, cf. Nicolet et al. 2021, who precondition mesh gradients by (I + λL)⁻¹).

Why: the loss sees a voxel's mixture only through light that has scattered over several voxels, so its curvature
is small at voxel-scale spatial frequencies, while a few-spp gradient puts as much noise there as anywhere. Plain
steps therefore let the mixture random-walk at those frequencies: the mottle of issue 13 (in flat regions the
prediction carries ~1 (ΔL*)² of texel-scale power that the target has no trace of). Diffusing the step damps each
spatial frequency by its heat-kernel factor: the noise injected at voxel scale shrinks by that factor, while the
low frequencies (the colour of a region) move at the full step. The preconditioner is symmetric positive
definite, so the fixed points of the descent are unchanged: detail at voxel scale is still reached, only more
slowly (README, "Print quality").

Steps: ``g <- g + a * sum_nb (g_nb - g)`` with a = 1/8 (stable for 6 neighbours: every eigenvalue of the step lies
in [-1/2, 1]), repeated ``k = ceil(4 sigma²)`` times, so the kernel's variance along each axis is 2 a k >= sigma²
(voxel units). Voxels that are not free (fixed shares, outside the object) are not neighbours: the diffusion
has no flux across them (Neumann boundary), so it never leaks a gradient into voxels that cannot use it.
"""
from __future__ import annotations

import math

import numpy as np

ALPHA = 0.125


def diffusion_steps(sigma: float) -> int:
    """Number of explicit steps whose kernel has a standard deviation of at least ``sigma`` voxels."""
    return 0 if sigma <= 0 else math.ceil(sigma * sigma / (2 * ALPHA))


class GradientSmoother:
    """Diffuses per-free-voxel arrays (F, N) over the free voxels' 6-neighbourhood (the loop in the Rust core,
    ``inkopt_core::smooth``: parallel, no memory beyond one copy of the values, thread-count independent).

    grad_index: (z, y, x) int32, each voxel's row among the free voxels (-1: not free), rows numbered in grid
    order, as ``Parameterization.grad_index`` (kept by reference, not copied); ``sigma``: kernel width in voxels
    (> 0).
    """

    def __init__(self, grad_index: np.ndarray, sigma: float):
        if not sigma > 0:
            raise ValueError(f"smoothing width must be positive, got {sigma}")
        self.steps = diffusion_steps(sigma)
        self.grad_index = np.ascontiguousarray(grad_index, np.int32)

    def __call__(self, g: np.ndarray) -> np.ndarray:
        """The diffused copy of g (F, N) float32 (g itself is not changed)."""
        from .. import _core

        return _core.smooth_rows(self.grad_index, np.ascontiguousarray(g, np.float32), self.steps, ALPHA)
