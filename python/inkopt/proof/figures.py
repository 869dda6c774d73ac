"""The soft-proof page's tables, as HTML: the figures of every result with their noise, the inks and their
shares, the printer and layer settings, the times and the display lighting. Every value comes from the run's own
files (report.json, evaluation.json, quantized.npz, volume.npz), which anyone may have edited: all markup is made
by ``markup.html``, which escapes them."""

from __future__ import annotations

from pathlib import PurePath

import numpy as np

from ..evaluation.results import Evaluation, Measured, Report
from ..printing.formats.slices import ink_colours
from .markup import Markup, html, join

LABELS = {
    "target": "target",
    "continuous": "optimised (continuous)",
    "quantized": "optimised, printed",
    "surface": "surface baseline",
    "extrusion": "extrusion baseline",
}


def _num(v, fmt: str = ".2f") -> str:
    """``v`` formatted, "–" for None or a non-finite float, and a value that does not take ``fmt`` (a string in
    an edited file) as text."""
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "–"
    try:
        return format(v, fmt)
    except (TypeError, ValueError):
        return str(v)


def _table(head: list[str], rows: list[list], cls: str) -> Markup:
    """A table of text or ``Markup`` cells."""
    th = join(html("<th>{}</th>", h) for h in head)
    body = join(html("<tr>{}</tr>", join(html("<td>{}</td>", c) for c in r)) for r in rows)
    return html('<table class="{}"><thead><tr>{}</tr></thead><tbody>{}</tbody></table>', cls, th, body)


def _metric_row(name: str, m, spp) -> list:
    return [
        LABELS.get(name, name),
        html('<span class="fig" data-fig="{}-de76">{}</span>', name, _num(m.delta_e76_mean)),
        _num(m.delta_e76_mean_corrected),
        _num(m.delta_e76_noise),
        _num(m.delta_e76_p95),
        _num(m.delta_e2000_mean),
        _num(m.ssim, ".3f"),
        _num(m.mottle_l2),
        spp,
    ]


def _sampled(taken) -> Markup | str:
    """Where the run's figures come from when report.json's ``texel_sample`` names a sample (a dict with a
    ``sample`` dict; anything else, as a hostile file may hold: nothing said), its counts escaped."""
    sample = taken.get("sample") if isinstance(taken, dict) else None
    if not isinstance(sample, dict):
        return ""
    counts = (sample.get(k, "?") for k in ("texels", "population", "windows"))
    return html(
        " on a random sample of {} of its {} texels and {} SSIM windows (the figures' standard errors: "
        "report.json's <code>texel_sample</code>)",
        *counts,
    )


FIGURE_HEAD = [
    "result",
    "ΔE76 mean",
    "ΔE76 mean, noise removed",
    "render noise per texel (ΔE76)",
    "ΔE76 p95",
    "ΔE2000 mean",
    "SSIM",
    "mottle (ΔL*)²",
    "spp",
]


def figures_html(report: Report, ev: Evaluation | None) -> Markup:
    """The figures table: from evaluation.json when the run was evaluated, else the optimisation's own."""
    if ev is not None:
        rows = [_metric_row(k, m.metrics, m.spp) for k, m in _evaluated(ev)]
        note = (
            html(
                "<code>inkopt evaluate</code>: {} texels; samples chosen so that the Monte Carlo noise adds at most "
                "{} to the mean ΔE76 (at most {} spp)",
                ev.texels,
                _num(ev.noise_target_delta_e76, "g"),
                ev.spp_max,
            )
            if ev.spp_adaptive
            else html("<code>inkopt evaluate --spp {}</code>: {} texels", ev.spp, ev.texels)
        )
        if ev.gamut_floor_delta_e76 is not None:
            note = html(
                "{}; gamut floor (nearest colour the inks reach): mean ΔE76 {}", note, _num(ev.gamut_floor_delta_e76)
            )
    else:
        rows = [_metric_row("continuous", report.metrics, report.eval_spp)]
        note = html(
            "the optimisation's final render{}; run <code>inkopt evaluate</code> for the printed result and the "
            "baselines",
            _sampled(report.texel_sample),
        )
    m = report.metrics
    return html(
        '{table}<p class="note">{note}. Start (all-white or the chosen initialisation): mean ΔE76 {start}, SSIM '
        "{ssim}. Mottle: high-frequency L* power on {flat} texels where the target is flat (the target's own: "
        "{mottle}).</p>",
        table=_table(FIGURE_HEAD, rows, "figures"),
        note=note,
        start=_num(report.initial_delta_e76_mean),
        ssim=_num(report.initial_ssim, ".3f"),
        flat=m.flat_texels,
        mottle=_num(m.mottle_l2_target),
    )


def _evaluated(ev: Evaluation) -> list[tuple[str, Measured]]:
    return [("continuous", ev.continuous), ("quantized", ev.quantized), *(ev.baselines or {}).items()]


def ink_shares(names, label_counts=None, mixture_mean=None) -> Markup:
    """The inks table: each ink's colour, its mean share in the optimised mixture (inside voxels) and its share
    of the printed voxels (from quantized.npz's label counts)."""
    colours = ink_colours(list(names))
    rows = []
    printed = None
    if label_counts is not None:
        c = np.asarray(label_counts, np.float64)[: len(names)]
        printed = c / max(c.sum(), 1.0)
    for i, n in enumerate(names):
        rows.append([html("{}{}", _swatch(colours[i]), n), _percent(mixture_mean, i), _percent(printed, i)])
    return _table(["ink", "share, optimised", "share of printed voxels"], rows, "inks")


def _percent(shares, i: int) -> str:
    """Share ``i`` of ``shares`` as a percentage; "–" without one (no array, or fewer inks than report.json)."""
    return "–" if shares is None or i >= len(shares) else f"{100 * shares[i]:.1f} %"


def _swatch(rgba) -> Markup:
    """A colour square as SVG: its colour is a presentation attribute, not a style attribute, which the page's
    policy refuses."""
    r, g, b = (int(v) for v in rgba[:3])
    return html(
        '<svg class="swatch" viewBox="0 0 1 1" aria-hidden="true"><rect width="1" height="1" fill="rgb({},{},{})"/>'
        "</svg>",
        r,
        g,
        b,
    )


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _scaled(v, factor: float):
    """``factor * v`` for a number, else ``v`` as it is (a string in an edited file is shown as text)."""
    return factor * v if _is_number(v) else v


def _item(v, i: int):
    """``v[i]`` of a list, else None."""
    return v[i] if isinstance(v, list) and len(v) > i else None


def settings_html(report: Report, ev: Evaluation | None, quantization: dict | None) -> Markup:
    """Printer, layer and run settings, times and the display lighting, as a definition list."""
    items = _object_items(report.scene) + _printer_items(quantization)
    items.append(
        (
            "optimisation",
            html(
                "{} iterations, {} step {}, {} spp per gradient, init {}, seed {}",
                report.iterations,
                report.optimizer,
                _num(report.lr, "g"),
                report.spp,
                report.init,
                report.seed,
            ),
        )
    )
    t = html("{:.0f} s in all ({:.2f} s per iteration)", report.seconds, report.seconds_per_iteration)
    if ev is not None:
        t = html("{}; evaluation {:.0f} s", t, ev.seconds)
    items.append(("time", t))
    light = ev.lighting if ev is not None else report.lighting
    items.append(("display lighting", describe_lighting(light)))
    return html("<dl>{}</dl>", join(html("<dt>{}</dt><dd>{}</dd>", k, v) for k, v in items))


def _printer_items(quantization: dict | None) -> list[tuple[str, str]]:
    """The printer resolution and the halftoning (evaluation.json's quantization settings)."""
    if not quantization:
        return [("printer resolution", html("not quantized yet (run <code>inkopt quantize</code>)"))]
    items = []
    dpi = quantization.get("dpi") or []
    if isinstance(dpi, list) and len(dpi) == 3:
        layer = 25400 / dpi[2] if _is_number(dpi[2]) and dpi[2] else dpi[2]
        resolution = html("{:g} x {:g} DPI, layers {:.1f} µm ({:g} DPI in z)", dpi[0], dpi[1], layer, dpi[2])
        items.append(("printer resolution", resolution))
    method, seed, upsample = (quantization.get(k) for k in ("method", "seed", "upsample"))
    items.append(("halftoning", html("{}, seed {}, {}", method, seed, upsample)))
    return items


def _object_items(scene: dict) -> list[tuple[str, str]]:
    """The object's size, the files its target came from and its optimisation grid (report.json's scene
    entries)."""
    items = []
    if "height_mm" in scene:
        items.append(
            ("object", html("mesh {:.1f} mm high, {} surface texels", scene["height_mm"], scene.get("texels", "?")))
        )
    elif "size_mm" in scene:
        size = scene["size_mm"] if isinstance(scene["size_mm"], list) else [scene["size_mm"]]
        items.append(("object", html("slab {} mm", " x ".join(_num(v, "g") for v in size))))
    if scene.get("mesh_path"):
        items.append(("mesh file", PurePath(str(scene["mesh_path"])).name))
    if scene.get("colour_source"):
        items.append(("target colours", scene["colour_source"]))
    if "voxel_mm" in scene:
        items.append(("optimisation grid", html("{:.1f} µm voxels", _scaled(_item(scene["voxel_mm"], 0), 1000))))
    return items


def describe_lighting(d: dict) -> str:
    """A line (text) for ``Lighting.describe()``'s fields (an edited file's other value: as it is)."""
    if not isinstance(d, dict):
        return str(d)
    src = d.get("lighting", "uniform")
    if src == "uniform":
        return "uniform white light from every direction"
    rot = d.get("lighting_rotate_deg", 0.0)
    return f"environment map {src}" + (f", rotated {_num(rot, 'g')}°" if rot else "")
