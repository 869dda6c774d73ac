"""Evaluation of a run directory (docs/run-dir.md): how close do the continuous result, the printed (quantized)
result and the naive baselines come to the target?

``evaluate_run(DIR, options)`` (``options.EvaluateOptions``) renders, on the same render seeds
(``EVAL_SEED_OFFSET + seed``, never used by an optimisation), each result with enough samples that the Monte Carlo
noise adds at most ~0.5 to its mean ΔE76 and SSIM's and the mottle's noise correction is accurate
(``evaluation.noise.adaptive_render``: a 64-spp pilot, the noise contribution and SSIM noise ratio estimated from
it, the rest rendered with independent seeds and pooled; at most 4096 spp). An explicit ``spp`` renders exactly
that many instead:

- ``continuous``: DIR/volume.npz on the scene texels at ``spp`` samples per texel;
- ``quantized``: DIR/quantized.npz (made with default settings first if missing) on its own printer-grid
  texels (the scene's textured faces of the printer grid; meshes: one texel per printer surface voxel), at
  ``spp_printer = ceil(spp * I_scene / I_printer)`` so each scene texel's average carries about ``spp``
  samples. Each printer texel is assigned to the scene texel of the same face whose face centre is nearest in mm
  (meshes: the nearest scene texel), i.e. the scene texel whose footprint contains it, and the printer texels of
  a scene texel are averaged (a scene texel that gets none takes its nearest printer texel);
- ``baselines``: ``surface`` and ``extrusion`` (``evaluation.baselines``) dithered as a print shop would: like ours
  (same method, seed, DPI, upsampling) but without the share compensation, and rendered like ``quantized``.

Each result is compared with the scene's ``target_rgb`` by ``metrics.prediction_metrics``: ΔE76 mean and 95th
percentile, CIEDE2000 mean, mean SSIM (sigma 1.5 voxels, on the scene texels), ``delta_e76_noise``, the mean
over texels of the Monte Carlo standard error of a texel's CIELAB colour (ΔE), and ``delta_e76_rms`` with
``delta_e76_rms_denoised``: the RMS ΔE76 and an unbiased estimate of it without the render noise
(sqrt(mean(ΔE² - se²))), ``delta_e76_noise_contribution`` (the estimated inflation of the mean ΔE76 by the
noise; ``delta_e76_mean_corrected`` the mean without it), the mottle (``metrics``), and ``spp`` (samples per
scene texel, all passes), ``spp_passes``. With the baselines, ``gamut_floor_delta_e76``: the mean over texels of
the ΔE76 from the target to the nearest colour a thick homogeneous patch of the inks reaches
(``ColourTable.reachable_lab``).

Every texel or a texel sample (``evaluation.choice``): a short pilot of the continuous result on a few texels
predicts the time of both at the same accuracy of the mean ΔE76, and the evaluation takes the sample when it is
clearly faster (``texel_sample`` forces either). With a sample, every figure comes from a random sample of scene
texels and SSIM windows (``evaluation.sample``), each result rendered on the same sampled texels with the same
seeds, with each figure's standard error and the paired differences between results; no pictures and no
predictions.npz then (they need every texel: ``texel_sample`` 0).

Translucency (``evaluation.translucency``): when the scene has a translucency constraint or ``translucency_compare``
names an unconstrained run of the same target, ``translucency`` holds the diffuse transmittance and lateral
light spread per constrained region and for the whole object (and the compared run's on the same regions).

Writes DIR/evaluation.json (or ``out``), DIR/predictions.npz (every result's colours per scene texel:
``rundir.Predictions``) and, for slabs, DIR/evaluation_<face>.png per textured face: target | optimized | quantized
| surface | extrusion (sRGB); for meshes DIR/evaluation_views.png, the same rows seen from four sides. ``max_spp``
and ``time_budget`` cap the adaptive renders.

The stage is a pipeline of named steps over one ``Evaluating`` (the run, its scene, the options, the texel groups,
the render seed and time shares, each result's renders): the continuous result (and translucency, and the baselines'
layer sources) while the run's mixture is loaded, the printed results, the figures, the ``Evaluation`` and its files.

Memory: one renderer exists at a time, and nothing per grid voxel but bits. The run's mixture is read by its band
(``MixtureSource.band_volume``: 28 B per voxel that differs from the core) and dropped once the continuous result is
rendered; the printer texels, their map and one printer renderer (``printed.PrintedRenderer``: geometry built once,
each later result's labels swapped in) serve the quantized result and both baselines. No printer-grid array exists:
the quantized labels are read a layer at a time (``RunDir.load_quantized(layered=True)``), each baseline goes layer
by layer from ``baselines.BaselineLayers`` through ``printing.quantize.quantize`` into a temporary layered label
file, and the core keeps labels and distances by 8^3 bricks (a table entry for a brick of one value); the texel loss
and its figures come after the last render (docs/performance.md, "Evaluation memory").
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

from ..color import RGB, ColourMap, delta_e76, linear_to_lab
from ..errors import ParameterError
from ..io import file_digest
from ..lighting import Lighting, load_lighting
from ..loss import TexelLoss
from ..model import Quantization, Volume
from ..model.mixturefile import MixtureSource
from ..printing.quantize import printer_grid
from ..render import Renderer, RendererFactory
from ..rundir import Predictions, RunDir, SceneRecord
from ..units import dpi_of
from . import sample as sampled
from .baselines import BASELINES, BaselineLayers
from .choice import SamplingChoice, choose_sampling
from .colour_table import ColourTable, colour_table
from .halftone_choice import quantize_run_as
from .metrics import prediction_metrics
from .noise import EVAL_SEED_OFFSET, MAX_SPP, PILOT_SPP, TARGET_NOISE_DE76, Sampling
from .options import EvaluateOptions
from .outputs import picture_names, write_face_pictures, write_mesh_views
from .printed import PrintedRenderer, quantized_baselines
from .renders import (
    ContinuousSource,
    PrintedSource,
    Rendered,
    TexelGroup,
    TimeShares,
    events_per_path,
    render_result,
    texel_groups,
)
from .results import Evaluation, Measured
from .translucency import evaluate_translucency


def _pilot_render(renderer: Renderer, texels, spp: int, seed: int) -> tuple:
    """The colours (k, C) and variances of their means (k, C) of ``texels`` rendered at ``spp`` with ``seed``."""
    r = renderer.render(texels, spp, seed)
    return r.rgb, r.var_mean


@dataclass
class Evaluating:
    """What the steps of one evaluation share: the run directory ``d`` and its scene ``rec``, the ``options``, the
    ``lighting``, the log ``say`` (``progress``: whether the renders show progress bars), the targets (I, 3)
    linear and CIELAB, the renders' ``sampling`` (seed, spp, cap) and time ``shares`` (from the evaluation's
    start), what renders a volume (``factory``: ``Renderer``, or a spectral run's band renders) and the colour map
    of its C channels (``cmap``); filled in as the steps go: the ``choice`` of every texel or a texel ``sample``
    (None: every texel) and the texel ``groups`` rendered (``settle``), each rendered result's colours on the first
    group (``colours``, with the target) and renders (``renders``, by result name), the translucency figures and
    the colour table's and gamut floor's (``floor``)."""

    d: RunDir
    rec: SceneRecord
    options: EvaluateOptions
    lighting: Lighting
    say: Callable[[str], None]
    progress: bool
    target: np.ndarray
    target_lab: np.ndarray
    sampling: Sampling
    shares: TimeShares
    factory: RendererFactory = Renderer
    cmap: ColourMap = RGB
    choice: SamplingChoice | None = None
    sample: sampled.TexelSample | None = None
    groups: list[TexelGroup] = field(default_factory=list)
    colours: dict = field(default_factory=dict)
    renders: dict[str, Rendered] = field(default_factory=dict)
    translucency: dict | None = None
    floor: dict = field(default_factory=dict)

    @classmethod
    def open(cls, path, options: EvaluateOptions, log) -> Evaluating:
        """The run directory ``path`` checked (a stale quantized volume is refused before any render) and its scene
        read."""
        lighting = load_lighting(options.lighting)
        d = RunDir(path)
        d.check_quantized_current()
        rec = d.load_scene()
        target = rec.target_rgb.astype(np.float64)
        target_lab = linear_to_lab(target)  # as TexelLoss has it; the loss itself is built after the renders
        return cls(
            d=d,
            rec=rec,
            options=options,
            lighting=lighting,
            say=log or (lambda msg: None),  # the default log: nothing
            progress=log is not None,
            target=target,
            target_lab=target_lab,
            sampling=Sampling(EVAL_SEED_OFFSET + int(options.seed), options.spp, options.max_spp),
            shares=TimeShares(options.time_budget, time.perf_counter(), 0),
            colours={"target": target},
        )

    def settle(self, renderer: Renderer) -> None:
        """Every texel or a texel sample (``choice.choose_sampling``, a pilot through ``renderer`` unless the options
        force it), logged, and the texel groups every result is rendered on."""
        pilot, seed = partial(_pilot_render, renderer), self.sampling.seed
        self.choice = choose_sampling(pilot, self.rec.texels, self.target_lab, self.options, seed, self.cmap)
        self.sample = s = self.choice.sample
        self.say(self.choice.describe())
        if s is not None:
            self.say(
                f"texel sample: {len(s.points)} of {s.population} texels; {len(s.centres)} SSIM windows of "
                f"{len(s.windows)} texels; no pictures and no predictions.npz (they need every texel: texel_sample "
                "0, on the command line --texel-sample 0)"
            )
        self.groups = texel_groups(self.rec.texels, self.target_lab, s)
        self.shares.left = (2 + (2 if self.options.baselines else 0)) * len(self.groups)  # for the time budget

    def render(self, name: str, source, started: float, method: str | None) -> Rendered:
        """Result ``name`` rendered through ``source`` on every texel group (``renders.render_result``), kept for
        its figures; ``started``: when its work began, ``method``: its quantization method."""
        ads = render_result(source, self.groups, self.sampling, self.shares, self.say, self.cmap)
        self.colours[name] = ads[0].rgb
        spp_printer, per_path = source.spp_printer, events_per_path(source)
        self.renders[name] = Rendered(ads, time.perf_counter() - started, method, spp_printer, per_path)
        return self.renders[name]


@dataclass(frozen=True)
class _Grid:
    """The optimisation grid of the run: ``shape`` (z, y, x) and ``voxel_mm`` (x, y, z)."""

    shape: tuple
    voxel_mm: np.ndarray


@dataclass(frozen=True)
class _Printed:
    """The printed results' grid: the quantization settings and printer DPI, the printer texels of the whole
    object and those rendered (a texel sample's)."""

    quantization: Quantization
    dpi: tuple
    printer_texels: int
    printer_texels_rendered: int


# ----------------------------------------------------------------------------------------------- the stage
def evaluate_run(path, options: EvaluateOptions | None = None, log=None) -> Evaluation:
    """Evaluate run directory ``path`` (module docstring) as ``options`` say (default ``EvaluateOptions()``);
    returns the ``results.Evaluation`` (also written to ``options.out`` with the pictures and predictions.npz when
    ``options.write``). ``log``: callable taking one progress line (default: silent; with one, the renders show
    progress bars)."""
    options = options or EvaluateOptions()
    ev = Evaluating.open(path, options, log)
    grid, sources = _mixture_results(ev)  # the run's mixture is freed on return
    printed = _printed_results(ev, grid, sources)
    measured, diffs = _figures(ev)
    evaluation = _evaluation(ev, printed, measured, diffs)
    if options.write:
        _write(ev, evaluation)
    return evaluation


def _mixture_results(ev: Evaluating) -> tuple[_Grid, dict]:
    """What needs the run's mixture (by its band, ``MixtureSource.band_volume``, unless translucency or the renderer
    needs it whole; dropped on return): the continuous result, translucency, the baselines' layer sources by name."""
    o, asked = ev.options, ev.options.translucency
    translucency = bool(asked if asked is not None else ev.rec.translucency is not None or o.translucency_compare)
    vol = band_mixture = None  # read by the band, or whole below
    if not translucency and ev.factory is Renderer:  # a spectral run's band renders swap whole media in
        with MixtureSource(ev.d.volume_file(), "evaluate") as src:
            if src.inside is not None:  # an unmasked volume (a slab) renders by the unmasked walk: whole
                vol, band_mixture = src.band_volume()
        del src  # and its inside mask's bytes (the volume keeps its bits)
    vol = ev.d.load_volume() if vol is None else vol
    _render_continuous(ev, vol, band_mixture)
    del band_mixture
    if translucency:
        compare, seed = o.translucency_compare, ev.sampling.seed
        ev.translucency = evaluate_translucency(vol, ev.rec, compare, seed, o.threads, ev.lighting, log=ev.say)
    sources = _baseline_sources(ev, vol) if o.baselines else {}
    return _Grid(vol.shape, vol.voxel_mm), sources


def _render_continuous(ev: Evaluating, vol: Volume, band_mixture: np.ndarray | None = None) -> None:
    """The continuous result: ``vol`` (``band_mixture``: its band's (K, N) mixture, its medium a placeholder) on
    the scene texels after their choice (``Evaluating.settle``: its seconds include the pilot); renderer freed."""
    started = time.perf_counter()
    renderer = ev.factory(vol, ev.options.threads, ev.lighting)
    if band_mixture is not None:
        renderer.set_mixture(vol.band.index, band_mixture)
    ev.settle(renderer)
    source = ContinuousSource(renderer, ev.groups, ev.progress)
    rendered = ev.render("continuous", source, started, None)
    spps = " + ".join(f"{len(g.texels)} texels x {ad.spp} spp" for g, ad in zip(ev.groups, rendered.ads))
    ev.say(f"continuous: {spps} in {rendered.seconds:.1f} s, {rendered.events_per_path:.0f} events per path")


def _baseline_sources(ev: Evaluating, vol: Volume) -> dict[str, BaselineLayers]:
    """The colour table (``options.table`` or built), its entry and the gamut floor (``ev.floor``), and each
    baseline's mixture layer by layer: no (z, y, x, N) baseline mixture is ever whole."""
    started, o = time.perf_counter(), ev.options
    table = o.table
    if table is None:
        table = colour_table(vol.inks, vol.g, vol.ior, patch_mm=o.patch_mm, threads=o.threads, progress=ev.progress)
    ev.say(
        f"colour table: {len(table.lab)} patches of {table.patch_mm:g} mm, step 1/{table.step}, "
        + ("(cached)" if table.cached else f"built in {table.seconds:.0f} s")
    )
    ev.floor = _gamut_floor(ev, table, started)
    fixed = ev.rec.fixed_share(vol.inks, vol.shape)
    return {
        name: BaselineLayers(name, vol, ev.rec.texels, ev.target, fixed, table, refine=o.refine) for name in BASELINES
    }


def _gamut_floor(ev: Evaluating, table: ColourTable, started: float) -> dict:
    """evaluation.json's ``colour_table`` and the gamut floor: the ΔE76 from each target to the nearest colour the
    inks reach (mean and 95th percentile)."""
    entry = {
        "entries": len(table.lab),
        "patch_mm": table.patch_mm,
        "step": table.step,
        "max_stderr": float(table.stderr.max()),
        "refine": bool(ev.options.refine),
        "key": table.key,
        "cached": table.cached,
        "build_seconds": table.seconds,
        "seconds": time.perf_counter() - started,
    }
    de = delta_e76(table.reachable_lab(ev.target), ev.target_lab)
    return {
        "colour_table": entry,
        "gamut_floor_delta_e76": float(de.mean()),
        "gamut_floor_delta_e76_p95": float(np.percentile(de, 95)),
    }


def _quantized_volume(ev: Evaluating, shape: tuple) -> tuple[Volume, Quantization]:
    """DIR/quantized.npz and its settings; made first with ``inkopt quantize``'s defaults (and ``options.method``)
    when missing. A method other than ``options.method`` is refused."""
    d, method = ev.d, ev.options.method
    if d.has_quantized():
        qvol = d.load_quantized(layered=True)
        q = qvol.quantization or Quantization()
        if method is not None and method != q.method:
            raise ParameterError(
                f"{d.quantized_path} was quantized with '{q.method}', not `method` '{method}'; quantize the run "
                f"again with '{method}' or leave `method` out"
            )
        return qvol, q
    t0 = time.perf_counter()  # inkopt quantize's defaults, layer by layer as that command does
    q, threads = Quantization() if method is None else Quantization(method), ev.options.threads
    ev.say(quantize_run_as(d, q, threads=threads, log=ev.say)[-1])  # its last line: the compensation's choice
    qvol = d.load_quantized(layered=True)
    q, seconds = qvol.quantization, time.perf_counter() - t0
    ev.say(f"quantized {shape} -> {qvol.shape} ({q.method}) in {seconds:.1f} s; wrote {d.quantized_path}")
    return qvol, q


def _printed_results(ev: Evaluating, grid: _Grid, sources: dict) -> _Printed:
    """The quantized result and the baselines (``sources``, emptied as they are quantized) on one printer
    renderer: its printer texels and their map are made once for all (``printed.PrintedRenderer``)."""
    qvol, q = _quantized_volume(ev, grid.shape)
    dpi = tuple(q.dpi or tuple(float(v) for v in dpi_of(qvol.voxel_mm)))
    t0 = time.perf_counter()
    sub = None if ev.sample is None else ev.sample.groups
    how = dict(threads=ev.options.threads, lighting=ev.lighting, groups=sub, factory=ev.factory)
    printer = PrintedRenderer(qvol, ev.rec.texels, grid.voxel_mm, ev.rec.kind, **how)
    meta = dict(
        voxel_mm=qvol.voxel_mm,
        inks=qvol.inks,
        g=qvol.g,
        ior=qvol.ior,
        normals=qvol.normals,
        boundary=qvol.boundary,
        origin_mm=qvol.origin_mm,
        quantization=q,
    )
    _render_printed(ev, printer, "quantized", qvol, t0, q.method)
    del qvol  # its memory-mapped labels
    if sources:
        _render_baselines(ev, printer, sources, grid, dpi, meta)
    printer.use(None)  # freed before the figures
    return _Printed(q, dpi, printer.all_printer_texels, printer.printer_texels_rendered)


def _render_printed(ev: Evaluating, printer: PrintedRenderer, name: str, labels_vol: Volume, t0: float, method: str):
    """Printed result ``name``: ``labels_vol`` on the printer texels (the first builds the printer renderer, the
    others swap in their labels)."""
    printer.use(labels_vol)
    rendered = ev.render(name, PrintedSource(printer, ev.progress), t0, method)
    spps = " + ".join(f"{len(m[0])} printer texels x {ad.spp} spp" for m, ad in zip(printer.maps, rendered.ads))
    ev.say(f"{name}: {spps} in {rendered.seconds:.1f} s, {rendered.events_per_path:.0f} events per path")


def _render_baselines(ev: Evaluating, printer: PrintedRenderer, sources: dict, grid: _Grid, dpi: tuple, meta: dict):
    """Each baseline quantized like ours (``printed.quantized_baselines``: the settings of quantized.npz
    ``meta["quantization"]``, uncompensated) into a temporary layered label file and rendered from it as the
    quantized result is: no printer-grid array."""
    shape_p = printer_grid(grid.shape, grid.voxel_mm, dpi=dpi)[0]
    if shape_p != printer.shape:
        raise ValueError(f"{ev.d.quantized_path} has a printer grid of {printer.shape}, its settings give {shape_p}")
    for name, labels, t0 in quantized_baselines(sources, grid.voxel_mm, shape_p, dpi, meta):
        _render_printed(ev, printer, name, labels, t0, meta["quantization"].method)


def _figures(ev: Evaluating) -> tuple[dict[str, Measured], dict | None]:
    """Every rendered result's figures (by name, in render order), after all renders; with a texel sample (figures
    on its window texels) also the paired differences between results."""
    sample = ev.sample
    target = ev.target if sample is None else ev.target[sample.windows]
    loss = TexelLoss(target, ev.groups[-1].texels.pos_vox, sigma=sampled.SIGMA)
    values = {}  # a sample's per-texel values by result, for the paired differences
    measured = {name: _measured(ev, loss, ev.renders.pop(name), values, name) for name in list(ev.renders)}
    if sample is None:
        return measured, None
    pairs = [("continuous", "quantized")] + [("quantized", name) for name in measured if name in BASELINES]
    return measured, sampled.differences(values, pairs, sample)


def _measured(ev: Evaluating, loss: TexelLoss, rendered: Rendered, values: dict, name: str) -> Measured:
    """One result's figures from its renders (a sample's: its per-texel values are kept in ``values``)."""
    r, ad = rendered, rendered.ads[0]
    if ev.sample is None:
        m = prediction_metrics(loss, ad.rgb, ad.var)
        return Measured(m, ad.spp, ad.passes, r.seconds, r.method, r.spp_printer, r.events_per_path)
    win = r.ads[1]
    values[name] = sampled.per_texel(loss, (win.rgb, win.var), (ad.rgb, ad.var), ev.groups[0].target_lab, ev.sample)
    m, err = sampled.sampled_figures(loss, values[name], ev.sample)
    return Measured(
        m, ad.spp, ad.passes, r.seconds, r.method, r.spp_printer, r.events_per_path, err, win.spp, win.passes
    )


def _evaluation(ev: Evaluating, printed: _Printed, measured: dict, diffs: dict | None) -> Evaluation:
    """The ``Evaluation`` of the figures."""
    cont, quantized = measured.pop("continuous"), measured.pop("quantized")
    rendered = printed.printer_texels_rendered
    sample = None if ev.sample is None else {**ev.sample.to_json(), "printer_texels_rendered": rendered}
    return Evaluation(
        spp=cont.spp,
        seed=int(ev.options.seed),
        texels=len(ev.rec.texels),
        kind=ev.rec.kind,
        spp_adaptive=ev.options.spp is None,
        noise_target_delta_e76=TARGET_NOISE_DE76,
        noise_target_ssim_ratio=ev.groups[-1].ssim_ratio,
        spp_pilot=PILOT_SPP,
        spp_max=MAX_SPP,
        lighting=ev.lighting.describe(),
        continuous=cont,
        quantization={**printed.quantization.to_json(), "dpi": list(printed.dpi), **ev.d.compensation_choice()},
        printer_texels=printed.printer_texels,
        quantized=quantized,
        seconds=time.perf_counter() - ev.shares.started,
        translucency=ev.translucency,
        **ev.floor,
        baselines=measured if ev.options.baselines else None,
        volume_digest=ev.d.volume_digest(),
        quantized_digest=ev.d.quantized_digest(),
        texel_sample=sample,
        differences=diffs,
        sampling_choice=ev.choice.to_json(),
    )


def _write(ev: Evaluating, evaluation: Evaluation) -> None:
    """The evaluation file and, with every texel rendered, the pictures (named after it) and predictions.npz."""
    d, rec = ev.d, ev.rec
    out = d.evaluation_path if ev.options.out is None else Path(ev.options.out)
    if ev.sample is not None:  # per-texel colours of the sampled texels only: no pictures, no predictions
        d.write_evaluation(evaluation.to_json(), out)
        return
    d.evaluation_picture_targets(out, picture_names(rec))  # nothing here replaces a picture it did not write
    if rec.faces:
        evaluation.pictures = write_face_pictures(d, rec, ev.colours, out.stem)
    elif rec.mesh is not None:
        evaluation.pictures = write_mesh_views(d, rec, ev.colours, out.stem, ev.say)
    d.write_evaluation(evaluation.to_json(), out)
    results = {"continuous": evaluation.continuous, "quantized": evaluation.quantized, **(evaluation.baselines or {})}
    spp_of = {name: m.spp for name, m in results.items()}
    colours = {name: ev.colours[name] for name in spp_of}
    d.save_predictions(Predictions(colours, "evaluation", spp_of, file_digest(d.volume_path), ev.lighting.describe()))
