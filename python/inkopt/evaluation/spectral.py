"""``inkopt evaluate`` of a spectral run: its continuous result, its printed result and the baselines under each
light.

A spectral run (``run.run_optimisation`` with a spectral ``Viewing``) leaves its ink table in the run directory
(spectral_inks.json) and its lights in report.json (``viewing``). The evaluation is ``evaluate.evaluate_run``'s
pipeline with the band renders of that table (``spectral.render.SpectralRenderer``) in place of the RGB renderer:
the continuous result on the scene texels; the printed result (quantized.npz, made with ``inkopt quantize``'s
defaults first if missing) and the ``surface`` and ``extrusion`` baselines (their mixtures looked up in the colour
table of the run's spectral inks under the run's lights, ``spectral_table``: a print shop with the same spectral
model, choosing for the lights the print is made for; then quantized exactly like the print) on the printer texels,
averaged onto the scene texels (``printed.PrintedRenderer``). Every result is rendered with the evaluation's
seeds (``noise.EVAL_SEED_OFFSET + seed``), at the options' samples per texel or adaptively against the target
under the first light, and scored under each light asked (default: the run's) by
``evaluation.lights.light_figures``: ΔE76, ΔE2000, SSIM per light, the worst light and the colour inconstancy
between the first light and each other. Every texel or a texel sample, chosen as for RGB runs
(``choice.choose_sampling``, its pilot's colours under the first light): with a sample every figure under every
light comes from the sampled texels with its standard error, and the paired differences between the results are
given per light (``differences``); no pictures and no predictions.npz then (they need every texel), but
predictions_sample.npz: every result on the sample's points (``rundir.Predictions`` with ``texels``, the points'
scene texel indices), band values and sRGB under the first light, so their figures under any light can be taken
again.

evaluation_lights.json holds ``viewing``; with the baselines, ``colour_table`` (``evaluate``'s entry, ``spectral``
and the ``lights`` of its look-up) and ``gamut_floor``: per light asked, the mean and 95th percentile ΔE76 from the
targets to the nearest colour a thick patch of the inks shows under it; one entry per result (``continuous``,
``quantized``, ``surface``, ``extrusion``: ``light_figures``' keys with ``spp``, ``spp_passes``, ``seconds``, and
for the printed ones ``method`` and ``spp_printer``); ``print_beats_baselines`` (per light, whether the print's mean
ΔE2000 is below each baseline's); ``quantization``, ``printer_texels``, ``seconds`` and the digests of the
volume.npz and quantized.npz it was made from. predictions.npz (``rundir.Predictions``, source "evaluation") holds
every result as sRGB under the first light and as band values with the lights' band matrices
(``rundir.BandValues``), so the soft-proof page can show any light without rendering again. The pictures (the target
beside every result shown as sRGB under the first light, ``Viewing.display``) go to evaluation_lights_<face>.png
(meshes: evaluation_lights_views.png).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..color import ColourMap, delta_e76
from ..errors import ParameterError
from ..io import file_digest, write_json
from ..loss import TexelLoss
from ..model.inks import read_ink_file
from ..model.spectral import spectral_from_data
from ..render import Renderer
from ..rundir import VOLUME_DIGEST, BandValues, Predictions, RunDir
from ..spectral.allocation import BandPlan
from ..spectral.lights import NAMED, named_light, parse_lights
from ..spectral.viewing import Viewing
from . import sample as sampled
from .baselines import BASELINES
from .colour_table import ColourTable
from .evaluate import Evaluating, _mixture_results, _printed_results
from .lights import light_figures, sampled_light_figures
from .options import EvaluateOptions
from .outputs import picture_names, write_face_pictures, write_mesh_views
from .renders import Rendered
from .spectral_table import SpectralColourTable, SpectralPatches, spectral_patches
from .translucency_lights import evaluate_translucency_lights

#: the loss weights the figures' TexelLoss is built with (the figures do not depend on them)
FIGURE_GAMMA = (1.0, 0.0, 0.0)


def run_viewing(d: RunDir) -> dict | None:
    """The run's spectral ``viewing`` entry of report.json (None: an RGB run)."""
    return d.read_report().get("viewing")


def evaluate_lights(path, options: EvaluateOptions, lights: str | None = None, log=None) -> dict:
    """Figures of spectral run ``path``'s results under ``lights`` ("D65,A"; None: the run's), rendered as
    ``options`` say (``spp``, ``max_spp``, ``time_budget``, ``seed``, ``threads``, ``lighting``, ``method``,
    ``baselines``, ``table``, ``patch_mm``, ``refine``); written to evaluation_lights.json, predictions.npz and
    pictures unless ``options.write`` is False (with a texel sample: the JSON only). Returns the JSON object (module
    docstring)."""
    d = RunDir(path)
    run = run_viewing(d)
    if run is None:
        raise ParameterError(
            f"`illuminants`: {d} is an RGB run; figures under other lights need a run with a spectral ink table "
            "(`inks` vero-cmykw@spectral)"
        )
    table = spectral_from_data(read_ink_file(d.spectral_inks_path), d.spectral_inks_path)
    # the run's band plan (report.json's viewing.plan) samples every result's bands: each band stays unbiased
    plan = BandPlan.from_json(run["plan"]) if "plan" in run else None
    viewing = Viewing(table, parse_lights(lights or ",".join(run["illuminants"])), plan=plan)
    patches = None
    if options.baselines and options.table is None:  # the baselines' print shop has the spectral model too
        patches = band_patches(d, table, options, log)
        options = replace(options, table=patches.under(run_colours(d, run["illuminants"], viewing)))
    ev = Evaluating.open(path, replace(options, translucency=False), log)
    names = tuple(light.name for light in viewing.seen_under())
    ev.factory, ev.cmap = viewing.renderer_factory(Renderer, shared=True), viewing.colours()[0]  # geometry once
    ev.say(f"spectral: {table.bands} bands under {', '.join(names)}")
    grid, sources = _mixture_results(ev)  # the continuous result and the baselines' layer sources
    translucency = _translucency(ev, options, table, viewing.colours())
    printed = _printed_results(ev, grid, sources)  # the quantized result and the baselines on printer texels
    if ev.sample is None:
        loss, diffs = viewing.loss(ev.target, ev.rec.texels.pos_vox, FIGURE_GAMMA), None
        results = {name: _result_figures(loss, r, names) for name, r in ev.renders.items()}
    else:
        results, diffs = _sampled_results(ev, viewing, names)
    out = {
        "viewing": {**viewing.describe(), "headline": names[0]},
        **results,
        "print_beats_baselines": print_beats_baselines(results, names),
        "quantization": {**printed.quantization.to_json(), "dpi": list(printed.dpi)},
        "printer_texels": printed.printer_texels,
        "seconds": time.perf_counter() - ev.shares.started,
        VOLUME_DIGEST: d.volume_digest(),
        "quantized_digest": d.quantized_digest(),
        "sampling_choice": ev.choice.to_json(),
    }
    if ev.floor:
        out["colour_table"] = table_entry(ev.floor["colour_table"], options.table)
        out["gamut_floor"] = gamut_floors(options.table if patches is None else patches.under(viewing.colours()), ev)
    if translucency is not None:
        out["translucency"] = translucency
    if ev.sample is not None:
        out.update(texel_sample=ev.sample.to_json(), differences=diffs)
    if options.write:
        _write(d, ev, viewing, out, tuple(results))
    return out


def _translucency(ev: Evaluating, options: EvaluateOptions, table, colours) -> dict | None:
    """The translucency figures under each light (``translucency_lights``) when ``options`` ask for them as for an
    RGB run (``translucency`` True, or None with a constrained run or ``translucency_compare``); else None."""
    o = options
    if not (o.translucency or (o.translucency is None and (ev.rec.translucency is not None or o.translucency_compare))):
        return None
    vol = ev.d.load_volume()
    return evaluate_translucency_lights(
        vol, ev.rec, table, colours, o.translucency_compare, ev.sampling.seed, o.threads, ev.say
    )


def run_colours(d: RunDir, names, viewing: Viewing) -> tuple[ColourMap, ...]:
    """The colour maps of the run's lights ``names`` (report.json's) on ``viewing``'s bands: the evaluation's light
    of that name, else a named light, else the band matrix predictions.npz keeps for it (a light file's spectrum may
    be gone); ``viewing``'s own when one of them is found nowhere."""
    asked = {c.name: c for c in viewing.colours()}
    wl = viewing.table.wavelengths_nm
    try:
        pred = d.load_predictions()
    except ValueError:  # a damaged predictions.npz keeps no light
        pred = None
    kept = pred.bands.lights if pred is not None and pred.bands is not None else {}
    out = []
    for name in names:
        if name in asked:
            out.append(asked[name])
        elif name in NAMED:
            out.append(named_light(name).colour_map(wl))
        elif np.shape(kept.get(name)) == (3, len(wl)):
            out.append(ColourMap(kept[name], name))
        else:
            return tuple(asked.values())
    return tuple(out)


def band_patches(d: RunDir, table, options: EvaluateOptions, log) -> SpectralPatches:
    """The baselines' spectral colour table's patches (``spectral_table.spectral_patches``: cached, shipped for the
    default spectral inks, else built) for the run's volume's g and ior, ``options.patch_mm`` thick; logged."""
    with np.load(d.volume_path, allow_pickle=False) as z:  # two scalars, not the volume
        g = float(z["g"]) if "g" in z.files else float(table.g)
        ior = float(z["ior"]) if "ior" in z.files else 1.5
    patches = spectral_patches(table, g, ior, options.patch_mm, threads=options.threads, progress=log is not None)
    if log is not None:
        how = "cached" if patches.cached else f"built in {patches.seconds:.0f} s"
        size = f"{len(patches.mixtures)} patches of {patches.patch_mm:g} mm, {table.bands} bands"
        log(f"spectral colour table: {size} ({how})")
    return patches


def table_entry(entry: dict, table) -> dict:
    """evaluation_lights.json's ``colour_table``: ``evaluate``'s entry, with whether the table is spectral and the
    lights its look-up used."""
    spectral = isinstance(table, SpectralColourTable)
    return {**entry, "spectral": spectral, "lights": list(table.light_names) if spectral else []}


def gamut_floors(table: ColourTable, ev: Evaluating) -> dict:
    """Per light of a spectral colour ``table`` (one entry, "rgb", for an RGB table): the mean and 95th percentile
    over the scene texels of the ΔE76 from each target's CIELAB to the nearest colour a thick homogeneous patch of
    the inks shows under that light (``ColourTable.reachable_lab``)."""
    spectral = isinstance(table, SpectralColourTable)
    tables = {n: table.under_light(k) for k, n in enumerate(table.light_names)} if spectral else {"rgb": table}
    out = {}
    for name, t in tables.items():
        de = delta_e76(t.reachable_lab(ev.target), ev.target_lab)
        out[name] = {"delta_e76_mean": float(de.mean()), "delta_e76_p95": float(np.percentile(de, 95))}
    return out


def _write(d: RunDir, ev: Evaluating, viewing: Viewing, out: dict, names: tuple) -> None:
    """evaluation_lights.json; with every texel rendered the pictures and predictions.npz (an earlier sample's
    predictions_sample.npz removed), with a texel sample predictions_sample.npz (the sample's points only)."""
    write_json(d.evaluation_lights_path, out)
    spp = {name: out[name]["spp"] for name in names}
    digest, lighting = file_digest(d.volume_path), ev.lighting.describe()
    if ev.sample is not None:
        bands = {name: ev.renders[name].ads[0].rgb for name in names}  # on the points, in their (sorted) order
        shown = {name: viewing.display(v) for name, v in bands.items()}
        pred = Predictions(shown, "evaluation", spp, digest, lighting, bands_of(viewing, bands), ev.sample.points)
        d.save_sample_predictions(pred)
        return
    bands = {name: ev.colours[name] for name in names}
    shown = {name: viewing.display(v) for name, v in bands.items()}
    _pictures(d, ev.rec, shown, ev.say)
    d.save_predictions(Predictions(shown, "evaluation", spp, digest, lighting, bands_of(viewing, bands)))
    d.sample_predictions_path.unlink(missing_ok=True)


def bands_of(viewing: Viewing, values) -> BandValues | None:
    """A spectral viewing's predictions ``values`` ((I, B) band values, or {result name: (I, B)}; "continuous" for
    one array) with its grid and lights (``rundir.BandValues``); None on the RGB path."""
    if not viewing.spectral:
        return None
    values = values if isinstance(values, dict) else {"continuous": values}
    values = {k: np.asarray(v, np.float32) for k, v in values.items()}
    return BandValues(values, viewing.table.wavelengths_nm, viewing.light_matrices())


def _result_figures(loss, rendered: Rendered, names: tuple[str, ...], figures: dict | None = None) -> dict:
    """One result's ``light_figures`` (or ``figures``, a sample's) with its samples (``spp`` per scene texel,
    ``spp_passes``), seconds and, for a printed result, its quantization method and printer samples per texel
    (``spp_printer``)."""
    ad = rendered.ads[0]
    figures = light_figures(loss, ad.rgb, ad.var, names) if figures is None else figures
    out = {**figures, "spp": ad.spp, "spp_passes": ad.passes, "seconds": rendered.seconds}
    if rendered.method is not None:
        out.update(method=rendered.method, spp_printer=rendered.spp_printer)
    return out


def _sampled_results(ev: Evaluating, viewing: Viewing, names: tuple[str, ...]) -> tuple[dict, dict]:
    """With a texel sample (``evaluation.sample``): every result's figures under each light from its sampled
    texels (``sample.sampled_figures`` on each light's view of the loss, ``TexelLoss.under``), each with its
    standard error (``by_light[light]["stderr"]``), the colour inconstancy on the points with its standard error
    (``inconstancy_stderr``); and per light the paired differences between the results (``sample.differences``)."""
    s = ev.sample
    loss = TexelLoss(
        ev.target[s.windows], ev.groups[-1].texels.pos_vox, FIGURE_GAMMA, sampled.SIGMA, colours=viewing.colours()
    )
    values = [{} for _ in names]  # per light: result -> per-texel values
    results = {}
    for name, rendered in ev.renders.items():
        ad, win = rendered.ads
        points, windows = (ad.rgb, ad.var), (win.rgb, win.var)
        figures, own = sampled_light_figures(loss, windows, points, ev.groups[0].target_lab, s, names)
        for k, v in enumerate(own):
            values[k][name] = v
        results[name] = {**_result_figures(loss, rendered, names, figures), "spp_windows": win.spp}
    pairs = [("continuous", "quantized")] + [("quantized", b) for b in BASELINES if b in ev.renders]
    return results, {light: sampled.differences(values[k], pairs, s) for k, light in enumerate(names)}


def print_beats_baselines(results: dict, names: tuple[str, ...]) -> dict:
    """Per light: for each baseline present, whether the printed (quantized) result's mean ΔE2000 is lower than
    the baseline's ({light: {"surface": bool, "extrusion": bool}}; empty without the baselines)."""
    if "quantized" not in results or not any(b in results for b in BASELINES):
        return {}

    def de(name, light):
        return results[name]["by_light"][light]["delta_e2000_mean"]

    return {n: {b: bool(de("quantized", n) < de(b, n)) for b in BASELINES if b in results} for n in names}


def _pictures(d: RunDir, rec, shown: dict, log) -> None:
    """The target beside the results ``shown`` (by name, (I, 3) linear sRGB): a slab's faces or a mesh's views."""
    results = {"target": rec.target_rgb, **shown}
    if "views" in picture_names(rec):
        write_mesh_views(d, rec, results, stem="evaluation_lights", say=log)
    else:
        write_face_pictures(d, rec, results, stem="evaluation_lights")
