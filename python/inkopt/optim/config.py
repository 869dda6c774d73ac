"""Settings of an optimisation run (docs/method.md §6) and their checks."""

from __future__ import annotations

from dataclasses import dataclass, replace

from ..errors import ParameterError

PARAMS = ("sigmoid", "softmax")
OPTIMIZERS = ("eg", "adam", "adagrad")
GRAD_METHODS = ("replay", "li1")
#: Settings whose default depends on the scene kind, used where the config leaves them None
#: (``OptimizeConfig.for_scene``; measured in experiments/results/printable.json and mesh_convergence.json,
#: docs/experiments.md).
#: ``adjoint_ema``: slabs 0.8, the adjoint's bias on dark colours needs the samples (0.5 cost the zebra chart 0.6
#: and the astronaut 1.0 mean ΔE76 at 300 iterations). Meshes 0.5: with 0.8 the lagging average and the momentum
#: make a delayed feedback loop and the run oscillates (Spot 10 mm, 60 iterations: training ΔE76 swings 17-24,
#: final 18.0 / SSIM 0.806 below the start's 0.834; with 0.5 it falls steadily to 11.6 / SSIM 0.877).
#: ``smooth``: slabs 1.5 (3 gained nothing on the demo slab); meshes 3: on Spot the flat regions' mottle grows
#: with the iterations at 1.5 (10 mm, 60 iterations: 0.55 (ΔL*)²; 3: 0.25, ΔE76 and SSIM slightly better too).
#: ``init``: white on both. On meshes the extrusion baseline is a better start for a short run (Spot 20 mm: its start
#: read 14.1 noise-corrected ΔE76 at 33 spp, bench/results/time_to_quality.json ``spot20/extrusion_lr1_budget55m``,
#: against white's noise-free 27.7), but from it the runs measured so far improved more slowly
#: (43 iterations: 11.0, bench/results/time_to_quality.json; 60 iterations from white: 9.76,
#: experiments/results/mesh_convergence.json), so white stays the default; a mesh's deadline run goes coarse to fine
#: from the extrusion baseline (``coarse.DEADLINE_MESH_START``).
#: ``finish_smooth``: meshes 1. A mesh result carries voxel-scale variation under flat texels that the loss barely
#: sees (its curvature is small there) and that no later step removes: averaging the last 10-40 iterates of a
#: coarse stage changed nothing, while one pass of the step's smoothing over a Spot 20 mm deadline result lowered
#: the mottle 0.34 -> 0.13 (ΔL*)² and raised SSIM 0.909 -> 0.920 for +0.07 ΔE76 (256-spp renders,
#: experiments/results/finish_smooth.json; docs/experiments.md, "Finishing smoothing"). Not ``FINISH_AUTO``: the
#: run's own choice kept the pass on every mesh-suite cell it ran (the duck, box, eyeball, checker, coin and orange
#: at 20 mm, the duck at 10 mm; Spot at 20 mm; bench/results/mesh_suite.json, variant ``finish-auto``) and costs a
#: render of every texel, 2-16 s of a 5-minute job (docs/quality.md, "The finishing smoothing decided by the run").
#: Slabs 0: not measured there.
#: ``colour_term``: meshes "linear", the mean ΔE76 the suite's targets and users' figures are stated in. On the mesh
#: suite's duck, box and eyeball at 20 mm with the medium budget (whole coarse-to-fine jobs, both stages with the
#: term, against the default cells of the same budget; each pair's prints evaluated on the same 1500 texels with the
#: same seeds, so the baselines are the same renders) the print with it against the print with "squared": ΔE76
#: −0.01, −0.27, −0.17; ΔE2000 −0.04, −0.29, −0.07; SSIM +0.002, −0.001, +0.005 (each difference's standard error
#: at most 0.11-0.14 ΔE76, 0.10-0.12 ΔE2000, 0.005-0.011 SSIM): no figure worse, the box better in both ΔE beyond
#: twice that bound (experiments/results/colour_term_cells.json; docs/quality.md, "The colour term as the figure the
#: targets are stated in"). Slabs "squared": not measured there.
SCENE_DEFAULTS = {
    "slab": {"adjoint_ema": 0.8, "smooth": 1.5, "init": "white", "finish_smooth": 0, "colour_term": "squared"},
    "mesh": {"adjoint_ema": 0.5, "smooth": 3.0, "init": "white", "finish_smooth": 1, "colour_term": "linear"},
}
#: ``finish_smooth`` "auto" (``--finish-smooth auto``): the result is the last iterate after one pass of the step's
#: smoothing, or the last iterate itself where the run's paired render of both says the pass raises the loss beyond
#: its noise (``evaluation.finish.choose_finish``)
FINISH_AUTO = -1
#: starts that are already close to the target: a volume file's mixture or a print-shop baseline
COLD_INITS = ("white", "random")
#: The default step of a warm start (any init but ``COLD_INITS``) relative to a cold one's: the exponentiated
#: gradient's step scale is set by the first gradients, which are smaller near the optimum, so the nominal step
#: moves a warm start's voxels as far as a cold start's and first undoes part of what the start had: Spot 20 mm
#: from the extrusion baseline got worse over its first iterations at lr 2 (a run stopped, not in a results file:
#: docs/experiments.md, "Deadlines on Spot 20 mm").
#: A quarter rather than a half: the 27-minute Spot 40 mm job from the extrusion baseline printed 9.19 / 7.61 /
#: 0.930 (ΔE76 corrected / ΔE2000 / SSIM) at lr 0.5 against 9.65 / 8.08 / 0.923 at lr 1, the extrusion baseline
#: 10.78 / 8.40 / 0.928; the 7m45s Spot 20 mm job, whose fine stage starts warm, 10.03 / 9.24 / 0.930 against
#: 10.13 / 9.25 / 0.925 (docs/experiments.md, "A warm start's step").
WARM_LR_FACTOR = 0.25


@dataclass(frozen=True)
class OptimizeConfig:
    """Every setting of an optimisation run (frozen). Settings left to the scene kind are None until
    ``for_scene(kind)`` resolves them; ``Optimization`` takes a resolved config only (``resolved``), so a run has one
    configuration, read-only."""

    #: with the step decay, the zebra chart and the astronaut photograph gain 0.3 and 0.55 mean ΔE76 from 200 to 300
    #: iterations (experiments/results/convergence_{zebra,astronaut}.json); the reference slab's 300 take ~4 min
    #: on 2 cores (experiments/results/printable.json)
    iterations: int = 300
    #: samples per texel of the gradient pass (unbiased at any spp; fewer is noisier)
    spp: int = 4
    #: samples per texel of the forward render that the adjoint dE/dC is evaluated at. dE/dC is a nonlinear
    #: function of C (CIELAB is steep near black): evaluated at a few-spp estimate its expectation is biased, for
    #: dark colours even in sign (docs/experiments.md), so the adjoint gets more samples than the gradient.
    #: 0: no forward renders after the first iteration; the adjoint is evaluated at the running average of the
    #: earlier gradient passes' estimates: cheaper iterations, each worth less. On the demo slab about equal quality
    #: at equal time (400 such iterations in 84 s against 300 of the default in 86 s:
    #: experiments/results/convergence_demo.json, entries ``forward0_ema0.9_400`` and ``nosmooth_300``); on Spot
    #: 20 mm worse at equal time (bench/results/time_to_quality.json, ``spot20/extrusion_lr1_fwd0_budget55m``
    #: against ``spot20/extrusion_lr1_budget55m``).
    forward_spp: int = 16
    #: loss weights (colour, SSIM, edges). Colour only by default: the SSIM term evaluated on a Monte Carlo
    #: estimate is biased towards lower contrast (the estimate's noise inflates its local variance), which on a
    #: black/white zebra chart lowered SSIM (docs/experiments.md).
    gamma: tuple[float, float, float] = (1.0, 0.0, 0.0)
    #: the colour term's form (``loss.COLOUR_TERMS``): "squared", the mean ΔE76² (the paper's), or "linear", the
    #: mean ΔE76 the figures report. None: the scene kind's (``SCENE_DEFAULTS``).
    colour_term: str | None = None
    lr: float | None = None  # default per optimizer: see default_lr
    optimizer: str = "eg"
    param: str = "softmax"
    #: "white" (97 % white), "random", "surface" or "extrusion" (a print-shop baseline), or a path to a volume
    #: .npz with a mixture. None: the scene kind's (``SCENE_DEFAULTS``).
    init: str | None = None
    seed: int = 0
    grad_method: str = "replay"
    checkpoint_every: int = 10
    include_specular: bool = True
    #: Per-iteration decay of the sample-weighted running average of the prediction that the adjoint is evaluated
    #: at (0: this iteration's forward render only). The mixture changes slowly, so averaging over iterations
    #: multiplies the adjoint's samples (~ (forward_spp + spp) / (1 - decay)) at no rendering cost, but lags the
    #: mixture by ~decay / (1 - decay) iterations. None: the scene kind's value (``SCENE_DEFAULTS``, ``for_scene``).
    adjoint_ema: float | None = None
    #: Width (voxels) of the spatial preconditioner of the step (``optim/smooth.py``): the step is diffused over
    #: the free voxels under texels where the target is flat, damping the voxel-scale noise that shows as mottle
    #: (0: off). None: the scene kind's value (``SCENE_DEFAULTS``): 1.5 on slabs: on the demo slab, the astronaut
    #: photograph and the reference slab it improves every noise-free figure over 0.7 and no smoothing, 3 gains
    #: nothing more there (experiments/results/convergence_*.json); 3 on meshes (Spot's flat-region mottle halves,
    #: experiments/results/mesh_convergence.json). Smoothing everywhere instead of under flat texels only
    #: cost the photograph ~0.9 mean ΔE76, widening the set by 4 voxels around flat texels ~0.5
    #: (experiments/results/convergence_astronaut.json, ``smooth0.7_everywhere_200``, ``smooth1.5_dilate4_200``).
    smooth: float | None = None
    #: Passes of the smoothing operator of ``smooth`` (same width and guide) applied to the result after the last
    #: iteration (the variables x, not a step): removes the voxel-scale variation in flat regions that the
    #: iterations leave behind. The checkpoints keep the unsmoothed iterate, so a continued run steps on from
    #: where the iterations were. 0: off (also without smoothing); ``FINISH_AUTO``: one pass where the run's own
    #: render says it lowers the loss (``evaluation.finish``); None: the scene kind's (``SCENE_DEFAULTS``).
    finish_smooth: int | None = None
    #: Guide of the smoothing: the target-colour difference (ΔE76) at which the smoothing between two voxels falls
    #: to 1/e, so it stays within regions of one target colour; with a guide, only voxels under flat texels
    #: (``TexelLoss.flat``) are smoothed (0: no guide, smooth everywhere and across the target's edges too).
    smooth_edge: float = 4.0
    #: Step decay (``optimizers.step_factor``): over the run's last ``decay`` fraction of iterations the step size
    #: halves ``DECAY_HALVINGS`` (3) times in equal stages (0: a constant step). With a constant step the mixtures
    #: keep moving about the optimum by an amount that grows with the step, which SSIM sees as voxel-to-voxel
    #: variation; chosen by measurement (experiments/results/convergence_{zebra,astronaut}.json).
    decay: float = 0.25
    #: The run length the step decay is planned for (None: ``iterations``). A run stopped early on purpose and
    #: continued later (``inkopt select-inks``' rungs) sets the full length here, so that every part steps as the
    #: one uninterrupted run would.
    schedule_iterations: int | None = None
    #: Stop when done (``optim/stopping.py``): once the training ΔE76 is not expected to fall by more than
    #: ``stop_gain`` over the next ``stop_horizon`` iterations, the step decay begins and the run ends after it;
    #: ``iterations`` is then the maximum (0: run all ``iterations``).
    stop_gain: float = 0.2
    stop_horizon: int = 50
    #: Seconds the whole run may take, set-up and final evaluation included (None: no deadline): the step decay is
    #: placed so that the run ends by then (``optim/stopping.py``).
    time_budget: float | None = None

    def validate(self) -> None:
        if self.iterations < 0:
            raise ParameterError(f"`iterations` must be >= 0, got {self.iterations}")
        if self.spp < 1:
            raise ParameterError(f"`spp` must be >= 1, got {self.spp}")
        if self.forward_spp < 0:
            raise ParameterError(f"`forward_spp` must be >= 0, got {self.forward_spp}")
        if self.param not in PARAMS:
            raise ParameterError(f"unknown `param` '{self.param}'; use one of {PARAMS}")
        if self.optimizer not in OPTIMIZERS:
            raise ParameterError(f"unknown `optimizer` '{self.optimizer}'; use one of {OPTIMIZERS}")
        if self.grad_method not in GRAD_METHODS:
            raise ParameterError(f"unknown `grad_method` '{self.grad_method}'; use one of {GRAD_METHODS}")
        if self.optimizer == "eg" and self.param != "softmax":
            raise ParameterError("the exponentiated-gradient `optimizer` works on the softmax `param` only")
        if self.lr is not None and not self.lr > 0:
            raise ParameterError(f"`lr` (the step size) must be positive, got {self.lr}")
        if self.checkpoint_every < 1:
            raise ParameterError("`checkpoint_every` must be >= 1")
        # at most 4 voxels: 2 x 32 diffusion passes per iteration, already blurry
        if self.smooth is not None and not 0.0 <= self.smooth <= 4.0:
            raise ParameterError(f"`smooth` (the smoothing width) must lie in [0, 4] voxels, got {self.smooth}")
        if self.finish_smooth is not None and not FINISH_AUTO <= self.finish_smooth <= 8:
            raise ParameterError(f"`finish_smooth` passes must lie in 0..8 (or be auto), got {self.finish_smooth}")
        if not 0.0 <= self.smooth_edge < float("inf"):
            raise ParameterError(f"`smooth_edge` must be >= 0 (dE76), got {self.smooth_edge}")
        if self.schedule_iterations is not None and self.schedule_iterations < self.iterations:
            raise ParameterError(
                f"`schedule_iterations` ({self.schedule_iterations}) must be at least `iterations` ({self.iterations})"
            )
        if not 0.0 <= self.decay < 1.0:
            raise ParameterError(f"`decay` must lie in [0, 1) (a fraction of the iterations), got {self.decay}")
        if not 0.0 <= self.stop_gain < float("inf"):
            raise ParameterError(f"`stop_gain` must be >= 0 (dE76; 0: run every iteration), got {self.stop_gain}")
        if self.stop_horizon < 1:
            raise ParameterError(f"`stop_horizon` must be >= 1 iteration, got {self.stop_horizon}")
        if self.time_budget is not None and not 0.0 < self.time_budget < float("inf"):
            raise ParameterError(f"`time_budget` must be a positive number of seconds, got {self.time_budget}")
        if self.adjoint_ema is not None and not 0.0 <= self.adjoint_ema < 1.0:
            raise ParameterError(f"`adjoint_ema` must lie in [0, 1), got {self.adjoint_ema}")
        from ..loss import COLOUR_TERMS

        if self.colour_term is not None and self.colour_term not in COLOUR_TERMS:
            raise ParameterError(f"`colour_term` must be one of {', '.join(COLOUR_TERMS)}, got '{self.colour_term}'")

    def for_scene(self, kind: str) -> OptimizeConfig:
        """This config with the settings it leaves to the scene (those of ``SCENE_DEFAULTS`` that are None) set for a
        scene of ``kind`` ("slab" or "mesh")."""
        if kind not in SCENE_DEFAULTS:
            raise ValueError(f"unknown scene kind '{kind}'; use one of {tuple(SCENE_DEFAULTS)}")
        # in the default's type (float, int, str), so that the checkpoint key of an explicit integer (``smooth=3``)
        # equals the default's
        resolved = {
            k: type(v)(v if getattr(self, k) is None else getattr(self, k)) for k, v in SCENE_DEFAULTS[kind].items()
        }
        return replace(self, **resolved)

    @property
    def resolved(self) -> bool:
        """Whether the settings left to the scene kind are set, in their defaults' types (``for_scene``)."""
        return all(
            type(getattr(self, k)) is type(v)  # noqa: E721 (int 3 and float 3.0 give different checkpoint keys)
            for k, v in SCENE_DEFAULTS["slab"].items()
        )

    @property
    def schedule_length(self) -> int:
        """The run length the step decay is planned for."""
        return self.iterations if self.schedule_iterations is None else self.schedule_iterations

    @property
    def step_size(self) -> float:
        """``lr``, else the optimiser's default (``default_lr``), times ``WARM_LR_FACTOR`` for a warm start."""
        if self.lr is not None:
            return self.lr
        warm = self.init is not None and self.init not in COLD_INITS
        return default_lr(self.optimizer) * (WARM_LR_FACTOR if warm else 1.0)


def default_lr(optimizer: str) -> float:
    """Step sizes in logit units (eg: of the most influential voxels) that converge in ~200-300 iterations on
    the test charts (experiments/results/convergence_*.json)."""
    return {"eg": 2.0, "adagrad": 0.5, "adam": 0.1}[optimizer]
