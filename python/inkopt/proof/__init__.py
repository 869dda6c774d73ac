"""The soft proof (``inkopt report RUN``): one self-contained HTML page that shows a run's object as it will
print beside its target, for the people who decide whether to print it (docs/report.md).

It reads the run directory only: report.json, scene.npz, predictions.npz (the colours per scene texel of the
continuous result and, after ``inkopt evaluate``, of the printed result and the baselines), evaluation.json,
quantized.npz's label counts, volume.npz's mixture, loss.png and, for meshes, the mesh file the run was made
from. Nothing is rendered again, so writing the page takes seconds.
"""

from __future__ import annotations

import base64
import time
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

from ..color import delta_e76, linear_to_lab
from ..evaluation.results import Evaluation, Report
from ..io import atomic_write_bytes, check_output, load_npz, read_head
from ..model.mixturefile import MixtureSource
from ..rundir import VOLUME_DIGEST, RunDir, StaleOutputError
from .bake import MeshAtlas, encode, heat_legend, heat_rgb8, heat_scale, mesh_atlas, srgb8
from .budget import DEFAULT_MAX_MB, Composed, Fitted, ProofOptions, fit_mesh, fit_slab
from .figures import LABELS, describe_lighting, figures_html, ink_shares, settings_html
from .lights import light_bar, light_figures_html, light_views
from .markup import html
from .page import data_uri, mesh_section, page_html, slab_section

ORDER = ("target", "continuous", "quantized", "surface", "extrusion")
SHADE = 0.35  # head-light share of the 3D view's shading (as views.png)
SLAB_WIDTH_PX = 400  # a slab face is shown about this wide (whole pixels per texel)
#: what marks a page written by ``inkopt report``: the generator tag in its head (``page.page_html``)
GENERATOR = b'<meta name="generator" content="inkopt report">'


def is_proof_page(path) -> bool:
    """Whether the file ``path`` is a soft-proof page written by ``inkopt report`` (by its generator tag)."""
    return GENERATOR in read_head(path)


def proof_target(d: RunDir, out=None) -> Path:
    """Where the page goes: RUN/report.html or ``out``, checked by ``io.check_output``: a file there is replaced
    only if it is an earlier soft-proof page, never a run's file, a picture or anything else."""
    return check_output(d.proof_path if out is None else out, is_proof_page, "a soft-proof page of 'inkopt report'")


@dataclass
class Proof:
    """What ``write_proof`` wrote: ``path``, its size in bytes, the results shown, the atlas size (meshes; 0 for
    slabs), whether the pictures are coarser than the texels, the seconds it took, and what the size budget
    chose: ``max_mb`` the budget, ``reduced`` whether it made the pictures smaller, ``quality`` the mesh
    textures' JPEG quality (0 for slabs), ``pixels_per_texel`` along the surface (meshes; None for slabs),
    ``step`` (slabs: one pixel per ``step`` x ``step`` texels) and ``unreduced_bytes``, the size the page would
    have had without the budget."""

    path: str
    bytes: int
    results: list
    atlas: int
    downsampled: bool
    seconds: float
    max_mb: float = DEFAULT_MAX_MB
    reduced: bool = False
    quality: int = 0
    pixels_per_texel: float | None = None
    step: int = 1
    unreduced_bytes: int | None = None

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> Proof:
        return cls(**{f.name: d[f.name] for f in fields(cls) if f.name in d})


def write_proof(run, out=None, options: ProofOptions | None = None) -> Proof:
    """Write the soft-proof page of run directory ``run`` to ``out`` (default RUN/report.html), within the size
    budget ``options.max_mb`` (``budget``: the pictures are made smaller only when the page would be larger)."""
    t0 = time.perf_counter()
    options = ProofOptions() if options is None else options
    d = RunDir(run)
    path = proof_target(d, out)
    report, rec, pred, ev = _read_run(d)
    colours = {"target": rec.target_rgb, **pred.rgb}
    keys = [k for k in ORDER if k in colours] + [k for k in colours if k not in ORDER]
    for k in keys:
        if colours[k].shape != rec.target_rgb.shape:
            raise ValueError(f"{d.predictions_path} does not match {d.scene_path}: run 'inkopt evaluate {d}' again")
    lv = None if pred.bands is None else light_views(pred.bands, rec.target_rgb, keys)
    if lv is None:
        target_lab = linear_to_lab(rec.target_rgb)
        shown = [(colours, {k: delta_e76(linear_to_lab(colours[k]), target_lab) for k in keys if k != "target"})]
    else:  # a spectral run: each light's colours and ΔE from the stored band values, the first light's first
        shown = list(zip(lv.colours, lv.de76))
    scale = heat_scale([v for _, de in shown for v in de.values()])
    baked = [
        ({k: srgb8(c[k]) for k in keys if k in c}, {k: heat_rgb8(v, scale) for k, v in de.items()}) for c, de in shown
    ]
    legend = data_uri(encode(heat_legend(scale)), "image/png")
    data = {"shade": SHADE, "results": keys, "heat_scale": scale}
    if lv is not None:
        data["lights"] = list(lv.names)
    sections = _sections(d, report, ev, lv, pred)
    evaluated = ev is not None or (lv is not None and pred.source == "evaluation")
    subtitle = _subtitle(report, rec.kind, keys, describe_lighting(pred.lighting), evaluated)
    title = f"inkopt soft proof: {d.path.resolve().name}"

    def compose(kind: str, view, view_data: dict, picture_bytes: int) -> Composed:
        if lv is not None:
            view = html("{}{}", light_bar(lv.names), view)
        page = page_html(title, subtitle, {**data, kind: view_data}, view, sections, kind == "mesh")
        return Composed(page.encode(), picture_bytes)

    pictures = Pictures(keys, baked, legend, scale, options)
    fit = _fit_mesh(rec, pictures, compose) if rec.kind == "mesh" else _fit_slab(rec, pictures, compose)
    atomic_write_bytes(path, fit.page)
    atlas = fit.atlas
    return Proof(
        str(path),
        len(fit.page),
        keys,
        0 if atlas is None else atlas.size,
        bool(atlas.downsampled if atlas is not None else fit.step > 1),
        time.perf_counter() - t0,
        options.max_mb,
        fit.reduced,
        fit.quality,
        None if atlas is None else atlas.pixels_per_texel,
        fit.step,
        fit.first_bytes,
    )


def _read_run(d: RunDir):
    """report.json, scene.npz, predictions.npz and (when the predictions come from it) evaluation.json of run
    ``d``, each checked against the others: (Report, scene record, Predictions, Evaluation or None)."""
    report = Report.from_json(d.read_report(), where=str(d.report_path))
    rec = d.load_scene()
    pred = d.load_predictions()
    if pred is None:
        raise ValueError(f"{d.predictions_path} does not exist: run 'inkopt evaluate {d}' first")
    d.check_volume_unchanged(
        pred.volume_digest,
        f"{d.predictions_path} was rendered from another volume.npz: run 'inkopt evaluate {d}' again",
    )
    evj = d.read_evaluation()
    ev = (
        Evaluation.from_json(evj, where=str(d.evaluation_path))
        if evj is not None and pred.source == "evaluation"
        else None
    )
    if ev is not None and ev.quantized_digest is not None and ev.quantized_digest != d.quantized_digest():
        raise StaleOutputError(
            f"{d.evaluation_path} was made from another quantized.npz (the run was quantized again since): run "
            f"'inkopt evaluate {d}' again"
        )
    return report, rec, pred, ev


def _sections(d: RunDir, report: Report, ev, lv, pred) -> list:
    """The page's (heading, HTML) sections below the view: figures, loss curve, inks, settings, files."""
    sections = [("Figures", figures_html(report, ev) if lv is None else light_figures_html(lv, _lights_eval(d)))]
    if d.loss_picture_path.is_file():
        uri = data_uri(d.loss_picture_path.read_bytes(), "image/png")
        sections.append(("Loss curve", html('<img class="loss" alt="loss curve" src="{}">', uri)))
    quant = ev.quantization if ev is not None else None
    counts = load_npz(d.quantized_path, "quantized volume")["label_counts"] if d.has_quantized() else None
    sections.append(("Inks", ink_shares(list(report.inks), counts, mixture_mean(d.volume_file()))))
    sections.append(("Printer, settings and time", settings_html(report, ev, quant)))
    sections.append(("Files", _files(pred)))
    return sections


def _subtitle(report: Report, kind: str, keys: list[str], light: str, evaluated: bool):
    """What the page shows, in a line: the object, the inks, the results and the lighting."""
    what = html("mesh, {:.1f} mm high", report.scene.get("height_mm", 0)) if kind == "mesh" else "slab"
    return html(
        "{}; inks {}; shown: {}; predicted under {}. {}",
        what,
        ", ".join(str(n) for n in report.inks),
        ", ".join(LABELS[k] for k in keys if k in LABELS),
        light,
        "" if evaluated else html("Not evaluated yet: run <code>inkopt evaluate</code> for the printed result."),
    )


def mixture_mean(path) -> np.ndarray | None:
    """The mean ink shares (N,) float64 over the inside voxels of a mixture volume file, read one layer at a time
    (a large object's mixture does not fit in memory twice); None if no voxel is inside."""
    src = MixtureSource(path)
    try:
        total, count = np.zeros(src.shape[3]), 0
        for z in range(src.shape[0]):
            lay = src[z]
            ins = src.inside[z] if src.inside is not None else np.ones(lay.shape[:2], bool)
            total += lay[ins].sum(0, dtype=np.float64)
            count += int(ins.sum())
    finally:
        src.close()
    return total / count if count else None


def _lights_eval(d: RunDir) -> dict | None:
    """evaluation_lights.json if it was made from the run's volume.npz, else None."""
    if not d.evaluation_lights_path.is_file():
        return None
    got = d._read_json(d.evaluation_lights_path, f"run 'inkopt evaluate {d.path}' again")
    return got if isinstance(got, dict) and got.get(VOLUME_DIGEST) == d.volume_digest() else None


def _by_light(baked, keys, picture) -> list[dict]:
    """The pictures of every light after the first (``baked``: (rgb8, heat8) per light; ``picture``: an image
    (..., 3) uint8 per scene texel -> data URI): [{}] for the first, whose are the page's own, then
    {"pictures"|"textures", "heat"} per light (the target's picture is the same under every light)."""
    return [{}] + [
        {
            "pictures": {k: picture(rgb8[k]) for k in keys if k != "target"},
            "heat": {k: picture(v) for k, v in heat8.items()},
        }
        for rgb8, heat8 in baked[1:]
    ]


@dataclass(frozen=True)
class Pictures:
    """What the view's pictures are made of: the results ``keys``, ``baked`` (per light: ({result: (I, 3) uint8
    sRGB}, {result: (I, 3) uint8 heat map})), the heat legend's data URI, the heat ``scale`` (ΔE76) and the
    page's ``options`` (its size budget)."""

    keys: list
    baked: list
    legend: str
    scale: float
    options: ProofOptions

    def budget_note(self) -> str:
        return f"to keep the page within its {self.options.max_mb:g} MB budget"


def _fit_mesh(rec, pic: Pictures, compose) -> Fitted:
    """The mesh page within the budget (``budget.fit_mesh``): the 3D view of the mesh the run was made from."""
    from ..scenes.mesh.load import load_mesh

    info = rec.mesh
    if info is None or not Path(info.mesh_path).is_file():
        where = "unknown" if info is None else info.mesh_path
        raise ValueError(f"the report draws the mesh the run was made from, and {where} does not exist")
    # the geometry only (the colours are the run's): a mesh coloured by a replacement texture or a constant is drawn too
    mesh = load_mesh(info.mesh_path, scale=info.mesh_scale, up=info.up, constant_color=True)
    voxel_mm = float(info.voxel_mm[0])

    def build(max_size: int) -> MeshAtlas:
        return mesh_atlas(
            mesh.solid_vertices, mesh.solid_faces, info.texel_closest_mm, rec.texels.normal, voxel_mm, max_size
        )

    def view(atlas: MeshAtlas, quality: int, reduced: bool) -> Composed:
        section, data, picture_bytes = _mesh_view(atlas, quality, pic, reduced)
        return compose("mesh", section, data, picture_bytes)

    return fit_mesh(build, view, pic.options)


def _mesh_view(atlas: MeshAtlas, quality: int, pic: Pictures, reduced: bool):
    """The 3D view's section, its data (geometry and JPEG pictures at ``quality``) and the pictures' bytes;
    ``reduced``: the budget made the pictures smaller (the note says so)."""
    sizes = []

    def jpeg(img):
        sizes.append(len(uri := data_uri(encode(atlas.picture(img), "JPEG", quality), "image/jpeg")))
        return uri

    b64 = lambda a: base64.b64encode(np.ascontiguousarray(a, np.float32).tobytes()).decode()  # noqa: E731
    rgb8, heat8 = pic.baked[0]
    data = {
        "positions": b64(atlas.positions),
        "normals": b64(atlas.normals),
        "uv": b64(atlas.uv),
        "textures": {k: jpeg(rgb8[k]) for k in pic.keys},
        "heat": {k: jpeg(v) for k, v in heat8.items()},
    }
    if len(pic.baked) > 1:
        data["by_light"] = [
            {"textures": b.get("pictures", {}), "heat": b.get("heat", {})} for b in _by_light(pic.baked, pic.keys, jpeg)
        ]
    texture = f"Texture {atlas.size} x {atlas.size} pixels, {1000 * atlas.pixel_mm:.0f} µm per pixel"
    if reduced:
        texture += f", JPEG quality {quality}"
    if atlas.downsampled:
        texture += (
            f": coarser than the texels, so the picture is downsampled ({atlas.pixels_per_texel:.2f} pixels per "
            "texel along the surface, where the page wants 2)"
        )
    note = (
        f"Colours: each scene texel (a {1000 * atlas.texel_mm:.0f} µm surface voxel) as predicted, printed results "
        "rendered at printer resolution and averaged onto the texels; shaded by a head-light "
        f"({100 * SHADE:.0f} %) for shape only. {texture}" + (f", {pic.budget_note()}." if reduced else ".")
    )
    return mesh_section(pic.keys, pic.legend, pic.scale, note), data, sum(sizes)


def _fit_slab(rec, pic: Pictures, compose) -> Fitted:
    """The slab page within the budget (``budget.fit_slab``): every textured face, the top first."""
    faces = [(n, rec.pix[n]) for n in sorted(rec.faces, key=lambda f: f != "top") if n in rec.pix]
    if not faces:
        raise ValueError("the slab's scene has no face pictures (scene.npz lacks pix_<face>)")

    def view(step: int) -> Composed:
        section, data, picture_bytes = _slab_view(faces, step, pic)
        return compose("slab", section, data, picture_bytes)

    return fit_slab(view, max(max(p.shape) for _, p in faces), pic.options)


def _slab_view(faces: list, step: int, pic: Pictures):
    """The faces' section, its data (PNG pictures of every ``step``-th texel along each side) and the pictures'
    bytes."""
    sizes = []

    def png(img):
        sizes.append(len(uri := data_uri(encode(img), "image/png")))
        return uri

    rgb8, heat8 = pic.baked[0]
    shown = []
    for name, full in faces:
        pix = full[::step, ::step]
        shown.append(
            {
                "name": name,
                "width": int(pix.shape[1]),
                "height": int(pix.shape[0]),
                "pictures": {k: png(rgb8[k][pix]) for k in pic.keys},
                "heat": {k: png(v[pix]) for k, v in heat8.items()},
            }
        )
        if len(pic.baked) > 1:
            shown[-1]["by_light"] = _by_light(pic.baked, pic.keys, lambda img, pix=pix: png(img[pix]))
    zoom = max(1, SLAB_WIDTH_PX // max(f["width"] for f in shown))
    note = None
    if step > 1:
        note = (
            f"Face pictures: one texel of every {step} along each side (one pixel per {step} x {step} texels), "
            f"{pic.budget_note()}: the pictures are downsampled."
        )
    return slab_section(shown, pic.keys, pic.legend, pic.scale, note), {"faces": shown, "zoom": zoom}, sum(sizes)


def _files(pred):
    return html(
        "<ul><li>volume.npz: <code>{}</code></li><li>predictions.npz from the {}, {}</li></ul>",
        pred.volume_digest,
        pred.source,
        ", ".join(f"{k}: {v} spp" for k, v in pred.spp.items()),
    )
