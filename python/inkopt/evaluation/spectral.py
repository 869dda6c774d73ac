"""``inkopt evaluate`` of a spectral run: its continuous result, its printed result and the baselines under each
light.

A spectral run (``run.run_optimisation`` with a spectral ``Viewing``) leaves its ink table in the run directory
(spectral_inks.json) and its lights in report.json (``viewing``). The evaluation is ``evaluate.evaluate_run``'s
pipeline with the band renders of that table (``spectral.render.SpectralRenderer``) in place of the RGB renderer:
the continuous result on the scene texels; the printed result (quantized.npz, made with ``inkopt quantize``'s
defaults first if missing) and the ``surface`` and ``extrusion`` baselines (chosen from the RGB colour table of the
volume's inks, as a print shop without a spectral model would, and quantized exactly like the print) on the printer
texels, averaged onto the scene texels (``printed.PrintedRenderer``). Every result is rendered with the evaluation's
seeds (``noise.EVAL_SEED_OFFSET + seed``), at the options' samples per texel or adaptively against the target
under the first light, on every texel (no texel sample), and scored under each light asked (default: the run's) by
``evaluation.lights.light_figures``: ΔE76, ΔE2000, SSIM per light, the worst light and the colour inconstancy
between the first light and each other.

evaluation_lights.json holds ``viewing``; one entry per result (``continuous``, ``quantized``, ``surface``,
``extrusion``: ``light_figures``' keys with ``spp``, ``spp_passes``, ``seconds``, and for the printed ones
``method`` and ``spp_printer``); ``print_beats_baselines`` (per light, whether the print's mean ΔE2000 is below
each baseline's); ``quantization``, ``printer_texels``, ``seconds`` and the digests of the volume.npz and
quantized.npz it was made from. predictions.npz (``rundir.Predictions``, source "evaluation") holds every result as
sRGB under the first light and as band values with the lights' band matrices (``rundir.BandValues``), so the
soft-proof page can show any light without rendering again. The pictures (the target beside every result shown
as sRGB under the first light, ``Viewing.display``) go to evaluation_lights_<face>.png (meshes:
evaluation_lights_views.png).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..errors import ParameterError
from ..io import file_digest, write_json
from ..model.inks import read_ink_file
from ..model.spectral import spectral_from_data
from ..render import Renderer
from ..rundir import VOLUME_DIGEST, BandValues, Predictions, RunDir
from ..spectral.lights import parse_lights
from ..spectral.viewing import Viewing
from .baselines import BASELINES
from .evaluate import Evaluating, _mixture_results, _printed_results
from .lights import light_figures
from .options import EvaluateOptions
from .outputs import picture_names, write_face_pictures, write_mesh_views
from .renders import Rendered

#: the loss weights the figures' TexelLoss is built with (the figures do not depend on them)
FIGURE_GAMMA = (1.0, 0.0, 0.0)


def run_viewing(d: RunDir) -> dict | None:
    """The run's spectral ``viewing`` entry of report.json (None: an RGB run)."""
    return d.read_report().get("viewing")


def evaluate_lights(path, options: EvaluateOptions, lights: str | None = None, log=None) -> dict:
    """Figures of spectral run ``path``'s results under ``lights`` ("D65,A"; None: the run's), rendered as
    ``options`` say (``spp``, ``max_spp``, ``time_budget``, ``seed``, ``threads``, ``lighting``, ``method``,
    ``baselines``, ``patch_mm``, ``refine``); written to evaluation_lights.json, predictions.npz and pictures unless
    ``options.write`` is False. Every texel is rendered (``texel_sample`` > 0 is refused). Returns the JSON object
    (module docstring)."""
    d = RunDir(path)
    run = run_viewing(d)
    if run is None:
        raise ParameterError(
            f"`illuminants`: {d} is an RGB run; figures under other lights need a run with a spectral ink table "
            "(`inks` vero-cmykw@spectral)"
        )
    if options.texel_sample:
        raise ParameterError("`texel_sample`: a spectral run's evaluation renders every texel (leave it out, or 0)")
    table = spectral_from_data(read_ink_file(d.spectral_inks_path), d.spectral_inks_path)
    viewing = Viewing(table, parse_lights(lights or ",".join(run["illuminants"])))
    ev = Evaluating.open(path, replace(options, texel_sample=0, translucency=False), log)
    loss = viewing.loss(ev.target, ev.rec.texels.pos_vox, FIGURE_GAMMA)
    ev.factory, ev.cmap = viewing.renderer_factory(Renderer, shared=True), loss.colours[0]  # geometry held once
    ev.say(f"spectral: {table.bands} bands under {', '.join(n.name for n in viewing.seen_under())}; every texel")
    grid, sources = _mixture_results(ev)  # the continuous result and the baselines' layer sources
    printed = _printed_results(ev, grid, sources)  # the quantized result and the baselines on printer texels
    names = tuple(light.name for light in viewing.seen_under())
    results = {name: _result_figures(loss, r, names) for name, r in ev.renders.items()}
    out = {
        "viewing": {**viewing.describe(), "headline": names[0]},
        **results,
        "print_beats_baselines": print_beats_baselines(results, names),
        "quantization": {**printed.quantization.to_json(), "dpi": list(printed.dpi)},
        "printer_texels": printed.printer_texels,
        "seconds": time.perf_counter() - ev.shares.started,
        VOLUME_DIGEST: d.volume_digest(),
        "quantized_digest": d.quantized_digest(),
    }
    if options.write:
        write_json(d.evaluation_lights_path, out)
        bands = {name: ev.colours[name] for name in results}
        shown = {name: viewing.display(v) for name, v in bands.items()}
        _pictures(d, ev.rec, shown, log)
        spp = {name: r["spp"] for name, r in results.items()}
        band_values = bands_of(viewing, bands)
        digest, lighting = file_digest(d.volume_path), ev.lighting.describe()
        d.save_predictions(Predictions(shown, "evaluation", spp, digest, lighting, band_values))
    return out


def bands_of(viewing: Viewing, values) -> BandValues | None:
    """A spectral viewing's predictions ``values`` ((I, B) band values, or {result name: (I, B)}; "continuous" for
    one array) with its grid and lights (``rundir.BandValues``); None on the RGB path."""
    if not viewing.spectral:
        return None
    values = values if isinstance(values, dict) else {"continuous": values}
    values = {k: np.asarray(v, np.float32) for k, v in values.items()}
    return BandValues(values, viewing.table.wavelengths_nm, viewing.light_matrices())


def _result_figures(loss, rendered: Rendered, names: tuple[str, ...]) -> dict:
    """One result's ``light_figures`` with its samples (``spp`` per scene texel, ``spp_passes``), seconds and, for a
    printed result, its quantization method and printer samples per texel (``spp_printer``)."""
    ad = rendered.ads[0]
    out = {**light_figures(loss, ad.rgb, ad.var, names), "spp": ad.spp, "spp_passes": ad.passes}
    out["seconds"] = rendered.seconds
    if rendered.method is not None:
        out.update(method=rendered.method, spp_printer=rendered.spp_printer)
    return out


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
