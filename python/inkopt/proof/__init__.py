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
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..color import delta_e76, linear_to_lab
from ..evaluation.results import Evaluation, Report
from ..io import atomic_write_bytes, check_output, load_npz, read_head
from ..model.mixturefile import MixtureSource
from ..rundir import VOLUME_DIGEST, RunDir, StaleOutputError
from .bake import encode, heat_legend, heat_rgb8, heat_scale, mesh_atlas, srgb8
from .figures import LABELS, describe_lighting, figures_html, ink_shares, settings_html
from .lights import light_bar, light_figures_html, light_views
from .markup import html
from .page import data_uri, mesh_section, page_html, slab_section

ORDER = ("target", "continuous", "quantized", "surface", "extrusion")
SHADE = 0.35  # head-light share of the 3D view's shading (as views.png)
JPEG_QUALITY = 90
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
    slabs), whether the textures are coarser than the texels, and the seconds it took."""

    path: str
    bytes: int
    results: list
    atlas: int
    downsampled: bool
    seconds: float

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> Proof:
        return cls(**{k: d[k] for k in ("path", "bytes", "results", "atlas", "downsampled", "seconds")})


def write_proof(run, out=None) -> Proof:
    """Write the soft-proof page of run directory ``run`` to ``out`` (default RUN/report.html)."""
    t0 = time.perf_counter()
    d = RunDir(run)
    path = proof_target(d, out)
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

    atlas, data = None, {"shade": SHADE, "results": keys, "heat_scale": scale}
    if lv is not None:
        data["lights"] = list(lv.names)
    if rec.kind == "mesh":
        atlas, view, data["mesh"] = _mesh(rec, keys, baked, legend, scale)
    else:
        view, data["slab"] = _slab(rec, keys, baked, legend, scale)
    if lv is not None:
        view = html("{}{}", light_bar(lv.names), view)

    sections = [("Figures", figures_html(report, ev) if lv is None else light_figures_html(lv, _lights_eval(d)))]
    if d.loss_picture_path.is_file():
        uri = data_uri(d.loss_picture_path.read_bytes(), "image/png")
        sections.append(("Loss curve", html('<img class="loss" alt="loss curve" src="{}">', uri)))
    quant = ev.quantization if ev is not None else None
    counts = load_npz(d.quantized_path, "quantized volume")["label_counts"] if d.has_quantized() else None
    sections.append(("Inks", ink_shares(list(report.inks), counts, mixture_mean(d.volume_file()))))
    sections.append(("Printer, settings and time", settings_html(report, ev, quant)))
    sections.append(("Files", _files(pred)))

    evaluated = ev is not None or (lv is not None and pred.source == "evaluation")
    subtitle = _subtitle(report, rec.kind, keys, describe_lighting(pred.lighting), evaluated)
    page = page_html(f"inkopt soft proof: {d.path.resolve().name}", subtitle, data, view, sections, atlas is not None)
    atomic_write_bytes(path, page.encode())
    return Proof(
        str(path),
        len(page.encode()),
        keys,
        0 if atlas is None else atlas.size,
        bool(atlas is not None and atlas.downsampled),
        time.perf_counter() - t0,
    )


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


def _mesh(rec, keys, baked, legend, scale):
    from ..scenes.mesh.load import load_mesh

    info = rec.mesh
    if info is None or not Path(info.mesh_path).is_file():
        where = "unknown" if info is None else info.mesh_path
        raise ValueError(f"the report draws the mesh the run was made from, and {where} does not exist")
    # the geometry only (the colours are the run's): a mesh coloured by a replacement texture or a constant is drawn too
    mesh = load_mesh(info.mesh_path, scale=info.mesh_scale, up=info.up, constant_color=True)
    atlas = mesh_atlas(
        mesh.solid_vertices, mesh.solid_faces, info.texel_closest_mm, rec.texels.normal, float(info.voxel_mm[0])
    )

    def jpeg(img):
        return data_uri(encode(atlas.picture(img), "JPEG", JPEG_QUALITY), "image/jpeg")

    b64 = lambda a: base64.b64encode(np.ascontiguousarray(a, np.float32).tobytes()).decode()  # noqa: E731
    rgb8, heat8 = baked[0]
    data = {
        "positions": b64(atlas.positions),
        "normals": b64(atlas.normals),
        "uv": b64(atlas.uv),
        "textures": {k: jpeg(rgb8[k]) for k in keys},
        "heat": {k: jpeg(v) for k, v in heat8.items()},
    }
    if len(baked) > 1:
        data["by_light"] = [
            {"textures": b.get("pictures", {}), "heat": b.get("heat", {})} for b in _by_light(baked, keys, jpeg)
        ]
    note = (
        f"Colours: each scene texel (a {1000 * atlas.texel_mm:.0f} µm surface voxel) as predicted, printed results "
        "rendered at printer resolution and averaged onto the texels; shaded by a head-light "
        f"({100 * SHADE:.0f} %) for shape only. Texture {atlas.size} x {atlas.size} pixels, "
        f"{1000 * atlas.pixel_mm:.0f} µm per pixel"
        + (": coarser than the texels, so the picture is downsampled." if atlas.downsampled else ".")
    )
    return atlas, mesh_section(keys, legend, scale, note), data


def _slab(rec, keys, baked, legend, scale):
    rgb8, heat8 = baked[0]
    faces = []
    for name in sorted(rec.faces, key=lambda f: f != "top"):  # the top face first
        if name not in rec.pix:
            continue
        pix = rec.pix[name]
        faces.append(
            {
                "name": name,
                "width": int(pix.shape[1]),
                "height": int(pix.shape[0]),
                "pictures": {k: data_uri(encode(rgb8[k][pix]), "image/png") for k in keys},
                "heat": {k: data_uri(encode(v[pix]), "image/png") for k, v in heat8.items()},
            }
        )
        if len(baked) > 1:
            faces[-1]["by_light"] = _by_light(baked, keys, lambda img, pix=pix: data_uri(encode(img[pix]), "image/png"))
    if not faces:
        raise ValueError("the slab's scene has no face pictures (scene.npz lacks pix_<face>)")
    zoom = max(1, SLAB_WIDTH_PX // max(f["width"] for f in faces))
    return slab_section(faces, keys, legend, scale), {"faces": faces, "zoom": zoom}


def _files(pred):
    return html(
        "<ul><li>volume.npz: <code>{}</code></li><li>predictions.npz from the {}, {}</li></ul>",
        pred.volume_digest,
        pred.source,
        ", ".join(f"{k}: {v} spp" for k, v in pred.spp.items()),
    )
