"""What an evaluation (``evaluate``) shows besides evaluation.json: the pictures of a slab's faces or a mesh's views
(target | optimized | quantized | baselines, sRGB) and the plain-text table of its figures."""

from __future__ import annotations

from ..io import write_png
from ..pictures import panels
from ..rundir import RunDir, SceneRecord
from . import sample as sampled
from .results import Evaluation
from .translucency import table_lines as translucency_lines


def picture_names(rec: SceneRecord) -> list[str]:
    """What an evaluation's pictures are named after: a slab's pictured faces, or "views" for a mesh."""
    if rec.faces:
        return [face for face in rec.faces if face in rec.pix]
    return ["views"] if rec.mesh is not None else []


def write_face_pictures(d: RunDir, rec: SceneRecord, results: dict, stem: str = "evaluation") -> list[str]:
    """DIR/<stem>_<face>.png (target | optimized | quantized | baselines: those in ``results``) for every textured
    face of a slab; returns the file names."""
    names = [("target", "target"), ("optimized", "continuous"), ("quantized", "quantized")]
    names += [(k, k) for k in ("surface", "extrusion")]
    items = [(label, results[k]) for label, k in names if k in results]  # those given
    written = []
    for face in rec.faces:
        if face in rec.pix:
            path = d.evaluation_picture_path(face, stem)
            write_png(path, panels(items, rec.pix[face]))
            written.append(path.name)
    return written


def write_mesh_views(d: RunDir, rec: SceneRecord, results: dict, stem: str = "evaluation", say=None) -> list[str]:
    """DIR/<stem>_views.png of a mesh run: target, optimized, quantized and baseline rows from four sides
    (``scenes.mesh.views.result_views``); none (and a log line) when the mesh file cannot be read any more."""
    from ..scenes.mesh.views import result_views

    names = [("target", "target"), ("optimized", "continuous"), ("quantized", "quantized")]
    names += [(k, k) for k in ("surface", "extrusion")]
    path = d.evaluation_picture_path("views", stem)
    try:
        result_views(rec.mesh, rec.texels.normal, [(label, results[k]) for label, k in names if k in results], path)
    except ValueError as exc:
        if say is not None:
            say(f"no views picture: {exc}")
        return []
    return [path.name]


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
