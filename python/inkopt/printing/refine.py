"""Refinement on the printed prediction: a few final iterations of the run's optimisation in which the loss is taken
on the quantized labels' render instead of the continuous mixture's ("straight through" the dither).

The optimiser's result is the mixture whose continuous render is closest to the target; the print is a halftone of
it, and its render differs from the continuous one by the halftone's own error (a texel's few printer voxels of each
ink, seen through the scattering, are not their mean). Each refinement iteration therefore:

1. quantizes the current mixture with the settings ``q`` (blue noise by default; ``quantize.quantize_volume``);
2. renders those labels at printer resolution onto the scene texels (``texelmap``: as the evaluation's printed
   results are rendered) with ``REFINE_SPP`` samples per scene texel;
3. takes the run's loss (``loss.TexelLoss`` with the run's weights) and its adjoint dE/dC at that printed prediction;
4. multiplies the adjoint into the gradient pass of the continuous mixture (``GRADIENT_SPP`` samples per texel,
   a different seed), the run's own chain rule to its variables, and takes an exponentiated-gradient step of
   ``REFINE_STEP`` (the step of the most influential voxels in logit units: the run's final, decayed step),
   diffused over the free voxels by the run's smoothing width as the run's steps are.

The continuous mixture is the straight-through stand-in for the labels' derivative: the labels change where the
mixture crosses a dither threshold, and the mixture moves in the direction that lowers the printed loss. The fixed
ink shares (a white core, translucent regions) stay as they are. Random numbers are keyed by ``q.seed`` and the
iteration (renders are bit-identical for any thread count; the step kernels are too), so a refinement is
deterministic. Conventions: docs/conventions.md.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..color import delta_e76
from ..loss import TexelLoss
from ..model import FixedShares, Quantization, Texels, Volume, mix_grad
from ..optim.optimizers import make_optimizer
from ..optim.param import Parameterization, free_part
from ..optim.smooth import GradientSmoother
from ..render import Renderer
from .quantize import quantize_volume
from .texelmap import average_to_scene, map_texels, printer_texels

#: samples per scene texel of each iteration's printed render (shared by its printer texels)
REFINE_SPP = 16
#: samples per texel of each iteration's gradient pass on the continuous mixture
GRADIENT_SPP = 16
#: the exponentiated-gradient step in logit units of the most influential voxels: the run's default step (2.0)
#: after the step decay's three halvings, where a run ends
REFINE_STEP = 0.25
#: the refinement's render seeds start here (apart from the run's and the evaluation's)
SEED_OFFSET = 2**61


@dataclass(frozen=True)
class PrintedLoss:
    """What the printed prediction is compared with: the scene's ``texels`` (I), their linear RGB targets
    ``target_rgb`` (I, 3) float32, the scene ``kind`` ("mesh" or a box kind: how printer texels map onto scene
    texels), the run's loss weights ``gamma`` (3,) and its smoothing width ``smooth`` in voxels (0: none) and its
    fixed ink shares ``fixed_share`` (None: none)."""

    texels: Texels
    target_rgb: np.ndarray
    kind: str
    gamma: tuple
    smooth: float = 0.0
    fixed_share: FixedShares | None = None


def refine_seeds(seed: int, it: int) -> tuple[int, int]:
    """(printed render seed, gradient seed) of refinement iteration ``it``."""
    base = SEED_OFFSET + (int(seed) * 1_000_003 + 2 * int(it)) % (2**60)
    return base, base + 1


class PrintedRefinement:
    """The refinement's state over a mixture volume ``vol`` (a ``Volume`` with a mixture and inks): variables of its
    free voxels, the loss, the optimiser, the continuous renderer (geometry built once) and the printer texels' map
    (made on the first quantization). ``step()`` does one iteration; ``volume()`` is the current mixture. ``lr``:
    the step (default ``REFINE_STEP``); ``spp``: the printed render's samples per scene texel and the gradient
    pass's per texel (default ``REFINE_SPP``, ``GRADIENT_SPP``)."""

    def __init__(
        self,
        vol: Volume,
        target: PrintedLoss,
        q: Quantization,
        threads: int | None = None,
        lr: float = REFINE_STEP,
        spp: tuple[int, int] = (REFINE_SPP, GRADIENT_SPP),
    ):
        mix = vol.require_mixture("the printed refinement").mixture
        self.base, self.target, self.q, self.threads = vol, target, replace(q, refine=0), threads
        fs = target.fixed_share
        if fs is None:
            fs = FixedShares.none(vol.shape, len(vol.inks))
        self.param = Parameterization("softmax", fs, threads)
        rows = np.asarray(mix, np.float32).reshape(-1, len(vol.inks))[self.param.free_index]
        self.x = self.param.variables_for(free_part(rows, self.param.fixed_f, self.param.share_f))
        self.loss = TexelLoss(np.asarray(target.target_rgb, np.float32), target.texels.pos_vox, gamma=target.gamma)
        self.opt = make_optimizer("eg", lr, self.x.shape, threads)
        self.spp = spp
        self.smoother = None
        if target.smooth > 0:
            self.smoother = GradientSmoother(self.param.shape, self.param.free_index, target.smooth, threads=threads)
        self.continuous = Renderer(vol, threads)
        self.printer: Renderer | None = None
        self.maps = None
        self.iteration = 0
        #: per iteration: the printed prediction's loss and mean ΔE76 (at ``spp[0]``, noise included), seconds
        self.history: list[dict] = []

    def volume(self) -> Volume:
        """The current mixture as a volume of the input's geometry."""
        return self.base.with_mixture(self.param.mixture(self.x))

    def printed(self, seed: int) -> tuple[np.ndarray, np.ndarray]:
        """The current mixture quantized by ``q`` and rendered at printer resolution: (rgb (I, 3), variance of the
        mean (I, 3)) float64 per scene texel."""
        labels = quantize_volume(self.volume(), self.q)
        if self.printer is None:
            ptex = printer_texels(labels, self.target.texels, self.target.kind)
            per_face = self.target.kind != "mesh"
            to_scene, stand_in = map_texels(ptex, labels.voxel_mm, self.target.texels, self.base.voxel_mm, per_face)
            self.maps, self.printer = (ptex, to_scene, stand_in), Renderer(labels, self.threads)
        else:
            self.printer.set_volume(labels)
        ptex, to_scene, stand_in = self.maps
        n = len(self.target.texels)
        res = self.printer.render(ptex, max(1, int(np.ceil(self.spp[0] * n / len(ptex)))), seed)
        return average_to_scene(res.rgb.astype(np.float64), res.var_mean.astype(np.float64), to_scene, stand_in, n)

    def step(self) -> dict:
        """One iteration (module docstring); returns its history entry."""
        t0 = time.perf_counter()
        render_seed, grad_seed = refine_seeds(self.q.seed, self.iteration)
        rgb, var = self.printed(render_seed)
        lr = self.loss(rgb.astype(np.float32), var.astype(np.float32), all_terms=False)
        de = float(delta_e76(lr.lab, self.loss.target_lab).mean())
        for lo, hi in self.param.chunks():
            self.continuous.set_mixture(self.param.free_index[lo:hi], self.param.free_rows(self.x[lo:hi], lo))
        gs, ga, _ = self.continuous.gradient(
            self.target.texels, lr.grad.astype(np.float32), self.spp[1], grad_seed, grad_index=self.param.free_index
        )
        g_x = np.empty_like(self.x)
        for lo, hi in self.param.chunks():
            g_rho = mix_grad(gs[lo:hi], ga[lo:hi], self.base.inks)
            g_x[lo:hi] = self.param.backward(self.x[lo:hi], g_rho, natural=self.opt.natural, lo=lo)
        del gs, ga
        x_new = self.opt.step(self.x, g_x).astype(np.float32, copy=False)
        if self.smoother is not None:
            step = self.smoother.apply(np.subtract(x_new, self.x, out=x_new))
            x_new = np.add(self.x, step, out=step)
        self.x = x_new
        self.iteration += 1
        entry = {"loss": float(lr.value), "delta_e76": de, "seconds": time.perf_counter() - t0}
        self.history.append(entry)
        return entry


def refine_mixture(
    vol: Volume, target: PrintedLoss, q: Quantization, threads: int | None = None, log: Callable | None = None
) -> tuple[Volume, list[dict]]:
    """``q.refine`` iterations of the printed refinement of the mixture volume ``vol`` (module docstring); returns
    the refined mixture volume (same geometry and inks) and the iterations' history (loss, ΔE76 of the printed
    prediction before each step, at ``REFINE_SPP``; seconds). ``log``: a line per iteration."""
    ref = PrintedRefinement(vol, target, q, threads)
    for _ in range(int(q.refine)):
        e = ref.step()
        if log is not None:
            log(
                f"printed refinement {ref.iteration}/{q.refine}: printed loss {e['loss']:.5f}, ΔE76 "
                f"{e['delta_e76']:.2f} (before the step), {e['seconds']:.1f} s"
            )
    return ref.volume(), ref.history
