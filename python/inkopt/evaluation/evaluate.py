"""Evaluation of a run directory (docs/run-dir.md): how close do the continuous result, the printed (quantized)
result and the naive baselines come to the target?

``evaluate_run(DIR)`` renders, on the same render seeds (``EVAL_SEED_OFFSET + seed``, never used by an
optimisation), each result with enough samples that the Monte Carlo noise adds at most ~0.5 to its mean ΔE76 and
SSIM's and the mottle's noise correction is accurate (``evaluation.noise.adaptive_render``: a 64-spp pilot, the
noise contribution and SSIM noise ratio estimated from it, the rest rendered
with independent seeds and pooled; at most 4096 spp). An explicit ``spp`` renders exactly that many instead:

- ``continuous``: DIR/volume.npz on the scene texels at ``spp`` samples per texel;
- ``quantized``: DIR/quantized.npz (made with default settings first if missing) on its own printer-grid
  texels (the scene's textured faces of the printer grid; meshes: one texel per printer surface voxel), at
  ``spp_printer = ceil(spp * I_scene / I_printer)`` so each scene texel's average carries about ``spp``
  samples. Each printer texel is assigned to the scene texel of the same face whose face centre is nearest in mm
  (meshes: the nearest scene texel), i.e. the scene texel whose footprint contains it, and the printer texels of
  a scene texel are averaged (a scene texel that gets none takes its nearest printer texel);
- ``baselines``: ``surface`` and ``extrusion`` (``evaluation.baselines``) quantized exactly like ours (same method,
  seed, DPI, upsampling) and rendered like ``quantized``.

Each result is compared with the scene's ``target_rgb`` by ``metrics.prediction_metrics``: ΔE76 mean and 95th
percentile, CIEDE2000 mean, mean SSIM (sigma 1.5 voxels, on the scene texels), ``delta_e76_noise``, the mean
over texels of the Monte Carlo standard error of a texel's CIELAB colour (ΔE), and ``delta_e76_rms`` with
``delta_e76_rms_denoised``: the RMS ΔE76 and an unbiased estimate of it without the render noise
(sqrt(mean(ΔE² - se²))), ``delta_e76_noise_contribution`` (the estimated inflation of the mean ΔE76 by the
noise; ``delta_e76_mean_corrected`` the mean without it), the mottle (``metrics``), and ``spp`` (samples per
scene texel, all passes), ``spp_passes``. With the baselines, ``gamut_floor_delta_e76``: the mean over texels of
the ΔE76 from the target to the nearest colour a thick homogeneous patch of the inks reaches
(``ColourTable.reachable_lab``).

Large objects (above ``sample.AUTO_SAMPLE_TEXELS`` scene texels, or ``texel_sample``): every figure comes from a
random sample of scene texels and SSIM windows (``evaluation.sample``), each result rendered on the same sampled
texels with the same seeds, with each figure's standard error and the paired differences between results; no
pictures and no predictions.npz then.

Translucency (``evaluation.translucency``): when the scene has a translucency constraint or ``translucency_compare``
names an unconstrained run of the same target, ``translucency`` holds the diffuse transmittance and lateral
light spread per constrained region and for the whole object (and the compared run's on the same regions).

Writes DIR/evaluation.json (or ``out``), DIR/predictions.npz (every result's colours per scene texel:
``rundir.Predictions``) and, for slabs, DIR/evaluation_<face>.png per textured face: target | optimized | quantized
| surface | extrusion (sRGB); for meshes DIR/evaluation_views.png, the same rows seen from four sides. ``max_spp``
and ``time_budget`` cap the adaptive renders.

Memory: one renderer exists at a time. The run's mixture is dropped once the continuous result (and translucency)
is rendered; the printer texels, their map and one printer renderer (``printed.PrintedRenderer``: geometry built
once, each later result's labels swapped in) serve the quantized result and both baselines (same printer grid and
inside voxels); each baseline goes layer by layer from ``baselines.BaselineLayers``
through ``printing.quantize.quantize`` into one printer label grid (1 byte per printer voxel), never as a whole
(z, y, x, N) mixture; the texel loss and its figures come after the last render. The peak is then the larger of
the continuous render and one printer renderer's build (docs/performance.md, "Evaluation memory").
"""

from __future__ import annotations

import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ..color import delta_e76, linear_to_lab
from ..io import file_digest, write_png
from ..lighting import Lighting, load_lighting
from ..loss import TexelLoss
from ..model import Quantization, Volume
from ..pictures import panels
from ..printing.quantize import DEFAULT_DPI, DEFAULT_LAYER_UM, band_order, printer_grid, quantize
from ..printing.stream import quantize_run
from ..render import Renderer
from ..rundir import Predictions, RunDir, SceneRecord
from ..units import dpi_of
from . import sample as sampled
from .baselines import BASELINES, BaselineLayers
from .colour_table import DEFAULT_PATCH_MM, ColourTable, colour_table
from .metrics import prediction_metrics
from .noise import EVAL_SEED_OFFSET, MAX_SPP, PILOT_SPP, SSIM_NOISE_RATIO, TARGET_NOISE_DE76, adaptive_render
from .printed import PrintedRenderer
from .results import Evaluation, Measured
from .translucency import evaluate_translucency
from .translucency import table_lines as translucency_lines

DEFAULT_SPP = None  # adaptive


def per_path(walks: dict) -> float:
    """Mean scattering and interface events per path of a result's renders (0 before any)."""
    return walks["events"] / walks["paths"] if walks.get("paths") else 0.0


# ----------------------------------------------------------------------------------------------- pictures
def write_face_pictures(d: RunDir, rec: SceneRecord, results: dict, stem: str = "evaluation") -> list[str]:
    """DIR/<stem>_<face>.png (target | optimized | quantized | baselines) for every textured face of a slab;
    returns the file names."""
    items = [("target", results["target"]), ("optimized", results["continuous"]), ("quantized", results["quantized"])]
    items += [(k, results[k]) for k in ("surface", "extrusion") if k in results]
    names = []
    for face in rec.faces:
        if face in rec.pix:
            path = d.evaluation_picture_path(face, stem)
            write_png(path, panels(items, rec.pix[face]))
            names.append(path.name)
    return names


def write_mesh_views(d: RunDir, rec: SceneRecord, results: dict, stem: str = "evaluation", say=None) -> list[str]:
    """DIR/<stem>_views.png of a mesh run: target, optimized, quantized and baseline rows from four sides
    (``scenes.mesh.views.result_views``); none (and a log line) when the mesh file cannot be read any more."""
    from ..scenes.mesh.views import result_views

    names = [("target", "target"), ("optimized", "continuous"), ("quantized", "quantized")]
    names += [(k, k) for k in ("surface", "extrusion") if k in results]
    path = d.evaluation_picture_path("views", stem)
    try:
        result_views(rec.mesh, rec.texels.normal, [(label, results[k]) for label, k in names], path)
    except ValueError as exc:
        (say or (lambda msg: None))(f"no views picture: {exc}")
        return []
    return [path.name]


# ----------------------------------------------------------------------------------------------- the stage
def evaluate_run(
    path,
    spp: int | None = DEFAULT_SPP,
    seed: int = 0,
    method: str | None = None,
    threads=None,
    baselines: bool = True,
    refine: bool = True,
    patch_mm: float = DEFAULT_PATCH_MM,
    table: ColourTable | None = None,
    write: bool = True,
    lighting: Lighting | str | None = None,
    log=None,
    translucency: bool | None = None,
    translucency_compare=None,
    max_spp: int = MAX_SPP,
    time_budget: float | None = None,
    out=None,
    texel_sample: int | None = None,
    sample_windows: int | None = None,
) -> Evaluation:
    """Evaluate run directory ``path`` (module docstring); returns the ``results.Evaluation`` (also written to
    DIR/evaluation.json with the face pictures when ``write``). ``spp``: None = adaptive (module docstring),
    else exactly that many samples per scene texel. ``method``: quantization method of ours (when
    quantized.npz is missing) and of the baselines; None = that of quantized.npz, else blue-noise.
    table: the baselines' colour table (default ``colour_table(inks, g, ior, patch_mm)``, cached).
    ``lighting``: the display lighting every result is rendered under (``inkopt.lighting``; default uniform; the
    baselines' colour table stays a uniform-light property of the inks).
    ``log``: callable taking one progress line (default: silent). ``translucency``: measure translucency (None:
    if the scene is constrained or ``translucency_compare``, an unconstrained run directory, is given).
    ``max_spp``: the adaptive renders' cap; ``time_budget``: seconds for all the adaptive renders together, shared
    out evenly among the results still to render. ``out``: the evaluation file (default DIR/evaluation.json; its
    pictures are named after it, e.g. ``out`` E.json: E_top.png, E_views.png), so earlier ones can be kept.
    ``texel_sample``, ``sample_windows``: figures from a random sample of that many scene texels and SSIM windows
    (``evaluation.sample``; ``sample.sample_size``: 0 texels renders every texel, None is the default)."""
    lighting = load_lighting(lighting)
    say = log or (lambda msg: None)
    if spp is not None and spp < 1:
        raise ValueError(f"--spp must be at least 1, got {spp}")
    d = RunDir(path)
    out = d.evaluation_path if out is None else Path(out)
    if out.suffix != ".json":
        raise ValueError(f"--out must name a .json file, got {out}")
    d.check_quantized_current()  # before any render: a stale quantized volume is refused in one line
    vol = d.load_volume()
    rec = d.load_scene()
    stex, kind = rec.texels, rec.kind
    target = rec.target_rgb.astype(np.float64)
    t_all = time.perf_counter()
    target_lab = linear_to_lab(target)  # as TexelLoss has it; the loss itself is built after the renders
    colours = {"target": target}
    rseed = EVAL_SEED_OFFSET + int(seed)
    texel_sample, sample_windows = sampled.sample_size(texel_sample, sample_windows, len(stex))
    # the texel groups rendered, each with its texels, their targets and noise targets (ΔE76, SSIM ratio)
    sample, groups = None, [(stex, target_lab, TARGET_NOISE_DE76, SSIM_NOISE_RATIO)]
    if texel_sample:
        sample = sampled.TexelSample.draw(stex, texel_sample, sample_windows, rseed)
        points, windows = (stex.subset(g) for g in sample.groups)
        groups = [(points, target_lab[sample.points], TARGET_NOISE_DE76, np.inf)]
        groups += [(windows, target_lab[sample.windows], np.inf, sampled.SAMPLE_SSIM_NOISE_RATIO)]
        say(
            f"texel sample: {len(sample.points)} of {len(stex)} texels; {len(sample.centres)} SSIM windows of "
            f"{len(sample.windows)} texels"
        )
    todo = [(2 + (2 if baselines else 0)) * len(groups)]  # adaptive renders still to do, for the time budget
    renders = {}  # name -> ([AdaptiveResult per group], seconds, quantization method, walks)

    def rendered(name: str, render, seconds_from: float, method: str | None, walks: dict, done=None):
        """Adaptive (or fixed-spp) render of one result on each texel group (``render(spp, seed, group)``), kept
        for its figures. ``walks``: the render's counts (``spp`` printer samples of a printed result's first group,
        ``paths``, ``events``), filled in by ``render``. ``done`` (called once the renders are over): frees the
        result's renderer."""
        ads = []
        for g, (_, lab, target_de, ratio) in enumerate(groups):
            budget = None
            if time_budget is not None:
                budget = max(time_budget - (time.perf_counter() - t_all), 0.0) / max(todo[0], 1)
            todo[0] -= 1
            ad = adaptive_render(
                lambda n, s, g=g: render(n, s, g),
                lab,
                rseed,
                spp,
                target=target_de,
                max_spp=max_spp,
                log=say,
                time_budget=budget,
                ratio=ratio,
            )
            ads.append(ad)
        if done is not None:
            done()
        colours[name] = ads[0].rgb
        renders[name] = (ads, time.perf_counter() - seconds_from, method, walks)
        return renders[name]

    t0 = time.perf_counter()
    renderer = Renderer(vol, threads, lighting)

    walks = {"paths": 0, "events": 0}

    def continuous(n: int, s: int, g: int):
        r = renderer.render(groups[g][0], n, s, progress=log is not None)
        walks["paths"], walks["events"] = walks["paths"] + r.paths, walks["events"] + r.events
        return r.rgb, r.var_mean, n

    def free_continuous():
        nonlocal renderer
        renderer = None  # freed before the figures and the next renderer

    ads, seconds, _, _ = rendered("continuous", continuous, t0, None, walks, done=free_continuous)
    spps = " + ".join(f"{len(tx)} texels x {ad.spp} spp" for (tx, *_), ad in zip(groups, ads))
    say(f"continuous: {spps} in {seconds:.1f} s, {per_path(walks):.0f} events per path")
    tr = None
    if translucency or (translucency is None and (rec.translucency is not None or translucency_compare)):
        tr = evaluate_translucency(vol, rec, translucency_compare, rseed, threads, lighting, log=say)

    floor, base, sources = {}, None, {}
    if baselines:
        t0 = time.perf_counter()
        if table is None:
            table = colour_table(vol.inks, vol.g, vol.ior, patch_mm=patch_mm, threads=threads, progress=log is not None)
        say(
            f"colour table: {len(table.lab)} patches of {table.patch_mm:g} mm, step 1/{table.step}, "
            + ("(cached)" if table.cached else f"built in {table.seconds:.0f} s")
        )
        floor["colour_table"] = {
            "entries": len(table.lab),
            "patch_mm": table.patch_mm,
            "step": table.step,
            "max_stderr": float(table.stderr.max()),
            "refine": bool(refine),
            "key": table.key,
            "cached": table.cached,
            "build_seconds": table.seconds,
            "seconds": time.perf_counter() - t0,
        }
        de = delta_e76(table.reachable_lab(target), target_lab)
        floor["gamut_floor_delta_e76"] = float(de.mean())
        floor["gamut_floor_delta_e76_p95"] = float(np.percentile(de, 95))
        fixed = rec.fixed_share(vol.inks, vol.shape)
        # layer by layer: no (z, y, x, N) baseline mixture is ever whole
        sources = {name: BaselineLayers(name, vol, stex, target, fixed, table, refine=refine) for name in BASELINES}
    shape, vmm = vol.shape, vol.voxel_mm
    vol = None  # the mixture is not needed any more: freed before the printer-resolution renders

    if d.has_quantized():
        qvol = d.load_quantized()
        q = qvol.quantization or Quantization()
        if method is not None and method != q.method:
            raise ValueError(
                f"{d.quantized_path} was quantized with '{q.method}', not '{method}'; rerun 'inkopt "
                f"quantize {d} --method {method}' or omit --method"
            )
    else:
        t0 = time.perf_counter()  # inkopt quantize's defaults, layer by layer as that command does
        quantize_run(
            d, method=method or "blue-noise", dpi=DEFAULT_DPI, layer_um=DEFAULT_LAYER_UM, seed=0, upsample="nearest"
        )
        qvol = d.load_quantized()
        q = qvol.quantization
        say(
            f"quantized {shape} -> {qvol.shape} ({q.method}) in {time.perf_counter() - t0:.1f} s; "
            f"wrote {d.quantized_path}"
        )
    dpi = tuple(q.dpi or tuple(float(v) for v in dpi_of(qvol.voxel_mm)))
    t0 = time.perf_counter()
    sub = None if sample is None else sample.groups
    printer = PrintedRenderer(qvol, stex, vmm, kind, threads, lighting, sub)  # texels and maps shared by all

    def printed(name: str, labels_vol: Volume, t0: float) -> None:
        info = {"spp": 0}
        printer.use(labels_vol)  # the first builds the printer renderer, the others swap in their labels

        def render(n: int, s: int, g: int):
            rgb, var, spp_p = printer(n, s, progress=log is not None, group=g)
            info.update(spp=info["spp"] + (spp_p if g == 0 else 0), paths=printer.paths, events=printer.events)
            return rgb, var, spp_p

        ads, seconds, _, _ = rendered(name, render, t0, q.method, info)
        spps = " + ".join(f"{len(m[0])} printer texels x {ad.spp} spp" for m, ad in zip(printer.maps, ads))
        say(f"{name}: {spps} in {seconds:.1f} s, {per_path(info):.0f} events per path")

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
    printed("quantized", qvol, t0)
    qvol = None  # its memory-mapped labels
    if sources:
        shape_p = printer_grid(shape, vmm, dpi=dpi)[0]
        if shape_p != printer.shape:
            raise ValueError(f"{d.quantized_path} has a printer grid of {printer.shape}, its settings give {shape_p}")
        for name in list(sources):
            t0 = time.perf_counter()  # quantized exactly like ours, into one printer-grid label array
            src = sources.pop(name)
            labels, _ = quantize(
                src,
                vmm,
                method=q.method,
                dpi=dpi,
                inside=src.inside,
                seed=q.seed,
                upsample=q.upsample,
                out=np.empty(shape_p, np.uint8),
                order=band_order(q, meta["inks"], meta["g"], meta["ior"]),  # as ours was, from its file
            )
            src = None
            printed(name, Volume.from_labels(labels=labels, **meta), t0)
            labels = None
    printer.use(None)  # freed before the figures
    n_ptex, n_ptex_rendered, printer = printer.all_printer_texels, printer.printer_texels_rendered, None
    # the figures of every result, after all renders (a sample's: on its window texels)
    loss = TexelLoss(target if sample is None else target[sample.windows], groups[-1][0].pos_vox, sigma=sampled.SIGMA)
    values = {}  # a sample's per-texel values by result, for the paired differences

    def figures(name: str) -> Measured:
        ads, seconds, method, walks = renders.pop(name)
        ad, m, err, win = ads[0], None, None, {}
        if sample is None:
            m = prediction_metrics(loss, ad.rgb, ad.var)
        else:
            pts = (ad.rgb, ad.var)
            values[name] = sampled.per_texel(loss, (ads[1].rgb, ads[1].var), pts, groups[0][1], sample)
            m, err = sampled.sampled_figures(loss, values[name], sample)
            win = dict(spp_windows=ads[1].spp, spp_windows_passes=ads[1].passes)
        return Measured(m, ad.spp, ad.passes, seconds, method, walks.get("spp"), per_path(walks), err, **win)

    cont, quantized = figures("continuous"), figures("quantized")
    if baselines:
        base = {name: figures(name) for name in BASELINES}
    loss = None  # freed before the pictures
    diffs = None
    if sample is not None:
        pairs = [("continuous", "quantized")] + [("quantized", name) for name in (base or {})]
        diffs = sampled.differences(values, pairs, sample)
    ev = Evaluation(
        spp=cont.spp,
        seed=int(seed),
        texels=len(stex),
        kind=kind,
        spp_adaptive=spp is None,
        noise_target_delta_e76=TARGET_NOISE_DE76,
        noise_target_ssim_ratio=groups[-1][3],
        spp_pilot=PILOT_SPP,
        spp_max=MAX_SPP,
        lighting=lighting.describe(),
        continuous=cont,
        quantization={**asdict(q), "dpi": list(dpi)},
        printer_texels=n_ptex,
        quantized=quantized,
        seconds=time.perf_counter() - t_all,
        translucency=tr,
        **floor,
        baselines=base,
        volume_digest=d.volume_digest(),
        quantized_digest=d.quantized_digest(),
        texel_sample=None if sample is None else {**sample.to_json(), "printer_texels_rendered": n_ptex_rendered},
        differences=diffs,
    )
    if write and sample is not None:  # per-texel colours of the sampled texels only: no pictures, no predictions
        say("texel sample: no pictures and no predictions.npz (they need every texel's colour)")
        d.write_evaluation(ev.to_json(), out)
    elif write:
        stem = out.stem
        if rec.faces:
            ev.pictures = write_face_pictures(d, rec, colours, stem)
        elif rec.mesh is not None:
            ev.pictures = write_mesh_views(d, rec, colours, stem, say)
        d.write_evaluation(ev.to_json(), out)
        names = ["continuous", "quantized", *(base or {})]
        spp_of = {"continuous": cont.spp, "quantized": quantized.spp, **{k: m.spp for k, m in (base or {}).items()}}
        d.save_predictions(
            Predictions(
                {n: colours[n] for n in names}, "evaluation", spp_of, file_digest(d.volume_path), lighting.describe()
            )
        )
    return ev


def table_lines(ev: Evaluation) -> list[str]:
    """A plain-text table of an evaluation."""
    nan = float("nan")

    def num(v):
        return nan if v is None else v

    lines = [
        f"{'result':<20}{'dE76 mean':>10}{'dE76 p95':>10}{'dE2000':>9}{'SSIM':>8}{'noise':>8}"
        f"{'rms w/o noise':>15}{'noise in mean':>14}{'mottle':>8}{'spp':>6}{'s':>7}"
    ]
    for name, r in ev.results():
        m = r.metrics
        lines.append(
            f"{name:<20}{m.delta_e76_mean:>10.2f}{m.delta_e76_p95:>10.2f}"
            f"{m.delta_e2000_mean:>9.2f}{m.ssim:>8.3f}{num(m.delta_e76_noise):>8.2f}"
            f"{num(m.delta_e76_rms_denoised):>15.2f}{num(m.delta_e76_noise_contribution):>14.2f}"
            f"{num(m.mottle_l2):>8.2f}{r.spp:>6}{r.seconds:>7.1f}"
        )
    lines += sampled.sample_lines(ev)
    c = ev.continuous.metrics
    if c.flat_texels:
        lines.append(
            f"mottle: high-frequency L* power, (dL*)^2, on {c.flat_texels} texels where the target is "
            f"flat (target's own: {c.mottle_l2_target:.2f})"
        )
    if ev.translucency is not None:
        lines += translucency_lines(ev.translucency)
    if ev.gamut_floor_delta_e76 is not None:
        lines.append(
            f"gamut floor: mean dE76 from the target to the nearest colour the inks reach in a "
            f"{ev.colour_table['patch_mm']:g} mm patch: {ev.gamut_floor_delta_e76:.2f}"
        )
    return lines
