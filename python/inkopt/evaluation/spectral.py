"""``inkopt evaluate`` of a spectral run: the continuous result's figures under each light.

A spectral run (``run.run_optimisation`` with a spectral ``Viewing``) leaves its ink table in the run directory
(spectral_inks.json) and its lights in report.json (``viewing``). Its result is rendered band by band
(``spectral.render.SpectralRenderer``) with seeds the optimisation never used (``noise.EVAL_SEED_OFFSET + seed``),
at the options' samples per texel or adaptively against the target under the first light, and scored under each
light asked (default: the run's) by ``evaluation.lights.light_figures``: ΔE76, ΔE2000, SSIM per light, the worst
light and the colour inconstancy between the first light and each other. The figures go to
evaluation_lights.json (with the volume.npz digest they were made from) and the pictures (the target beside the
result shown as sRGB under the first light, ``Viewing.display``) to evaluation_lights_<face>.png.
"""

from __future__ import annotations

import time

from ..errors import ParameterError
from ..io import write_json
from ..model.inks import read_ink_file
from ..model.spectral import spectral_from_data
from ..render import Renderer
from ..rundir import VOLUME_DIGEST, RunDir
from ..spectral.lights import parse_lights
from ..spectral.viewing import Viewing
from .lights import light_figures
from .noise import EVAL_SEED_OFFSET, Sampling, adaptive_render
from .options import EvaluateOptions
from .outputs import picture_names, write_face_pictures, write_mesh_views

#: the loss weights the figures' TexelLoss is built with (the figures do not depend on them)
FIGURE_GAMMA = (1.0, 0.0, 0.0)


def run_viewing(d: RunDir) -> dict | None:
    """The run's spectral ``viewing`` entry of report.json (None: an RGB run)."""
    return d.read_report().get("viewing")


def evaluate_lights(path, options: EvaluateOptions, lights: str | None = None, log=None) -> dict:
    """Figures of spectral run ``path``'s continuous result under ``lights`` ("D65,A"; None: the run's), rendered
    as ``options`` say (``spp``, ``max_spp``, ``time_budget``, ``seed``, ``threads``, ``lighting``); written to
    evaluation_lights.json and pictures unless ``options.write`` is False. Returns the JSON object: ``viewing``,
    ``continuous`` (``light_figures``' dict with ``spp``, ``spp_passes``, ``seconds``), ``volume_digest``."""
    t0 = time.perf_counter()
    d = RunDir(path)
    run = run_viewing(d)
    if run is None:
        raise ParameterError(
            f"`illuminants`: {d} is an RGB run; figures under other lights need a run with a spectral ink table "
            "(`inks` vero-cmykw@spectral)"
        )
    table = spectral_from_data(read_ink_file(d.spectral_inks_path), d.spectral_inks_path)
    viewing = Viewing(table, parse_lights(lights or ",".join(run["illuminants"])))
    rec, vol = d.load_scene(), d.load_volume()
    loss = viewing.loss(rec.target_rgb.astype("float64"), rec.texels.pos_vox, FIGURE_GAMMA)
    renderer = viewing.renderer_factory(Renderer)(vol, options.threads, options.lighting)
    del vol

    def render(n: int, s: int):
        r = renderer.render(rec.texels, n, s)
        return r.rgb, r.var_mean, n

    sampling = Sampling(EVAL_SEED_OFFSET + int(options.seed), options.spp, options.max_spp, options.time_budget)
    res = adaptive_render(render, loss.target_lab, sampling, log=log, cmap=loss.colours[0])
    names = tuple(light.name for light in viewing.seen_under())
    out = {
        "viewing": {**viewing.describe(), "headline": names[0]},
        "continuous": {**light_figures(loss, res.rgb, res.var, names), "spp": res.spp, "spp_passes": res.passes},
        "seconds": time.perf_counter() - t0,
        VOLUME_DIGEST: d.volume_digest(),
    }
    if options.write:
        write_json(d.evaluation_lights_path, out)
        _pictures(d, rec, viewing.display(res.rgb), log)
    return out


def _pictures(d: RunDir, rec, shown, log) -> None:
    """The target beside the result (I, 3) linear sRGB: a slab's faces or a mesh's views."""
    results = {"target": rec.target_rgb, "continuous": shown}
    if "views" in picture_names(rec):
        write_mesh_views(d, rec, results, stem="evaluation_lights", say=log)
    else:
        write_face_pictures(d, rec, results, stem="evaluation_lights")
