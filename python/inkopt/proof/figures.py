"""The soft-proof page's tables, as HTML: the figures of every result with their noise, the inks and their
shares, the printer and layer settings, the times and the display lighting. Every value comes from the run's own
files (report.json, evaluation.json, quantized.npz, volume.npz)."""

from __future__ import annotations

from html import escape

import numpy as np

from ..evaluation.results import Evaluation, Measured, Report
from ..printing.formats.slices import ink_colours

LABELS = {
    "target": "target",
    "continuous": "optimised (continuous)",
    "quantized": "optimised, printed",
    "surface": "surface baseline",
    "extrusion": "extrusion baseline",
}


def _num(v, fmt: str = ".2f") -> str:
    return "–" if v is None or (isinstance(v, float) and not np.isfinite(v)) else format(v, fmt)


def _table(head: list[str], rows: list[list[str]], cls: str) -> str:
    th = "".join(f"<th>{escape(h)}</th>" for h in head)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    return f'<table class="{cls}"><thead><tr>{th}</tr></thead><tbody>{body}</tbody></table>'


def _metric_row(name: str, m, spp) -> list[str]:
    return [
        escape(LABELS.get(name, name)),
        f'<span class="fig" data-fig="{name}-de76">{_num(m.delta_e76_mean)}</span>',
        _num(m.delta_e76_mean_corrected),
        _num(m.delta_e76_noise),
        _num(m.delta_e76_p95),
        _num(m.delta_e2000_mean),
        _num(m.ssim, ".3f"),
        _num(m.mottle_l2),
        str(spp),
    ]


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


def figures_html(report: Report, ev: Evaluation | None) -> str:
    """The figures table: from evaluation.json when the run was evaluated, else the optimisation's own."""
    if ev is not None:
        rows = [_metric_row(k, m.metrics, m.spp) for k, m in _evaluated(ev)]
        note = (
            f"<code>inkopt evaluate</code>: {ev.texels} texels; samples chosen so that the Monte Carlo noise adds at "
            f"most {ev.noise_target_delta_e76:g} to the mean ΔE76 (at most {ev.spp_max} spp)"
            if ev.spp_adaptive
            else f"<code>inkopt evaluate --spp {ev.spp}</code>: {ev.texels} texels"
        )
        if ev.gamut_floor_delta_e76 is not None:
            note += f"; gamut floor (nearest colour the inks reach): mean ΔE76 {ev.gamut_floor_delta_e76:.2f}"
    else:
        rows = [_metric_row("continuous", report.metrics, report.eval_spp)]
        note = (
            "the optimisation's final render; run <code>inkopt evaluate</code> for the printed result and the baselines"
        )
    m = report.metrics
    extra = (
        f"Start (all-white or the chosen initialisation): mean ΔE76 {_num(report.initial_delta_e76_mean)}, SSIM "
        f"{_num(report.initial_ssim, '.3f')}. Mottle: high-frequency L* power on {m.flat_texels} texels where the "
        f"target is flat (the target's own: {_num(m.mottle_l2_target)})."
    )
    return _table(FIGURE_HEAD, rows, "figures") + f'<p class="note">{note}. {extra}</p>'


def _evaluated(ev: Evaluation) -> list[tuple[str, Measured]]:
    return [("continuous", ev.continuous), ("quantized", ev.quantized), *(ev.baselines or {}).items()]


def ink_shares(names, label_counts=None, mixture_mean=None) -> str:
    """The inks table: each ink's colour, its mean share in the optimised mixture (inside voxels) and its share
    of the printed voxels (from quantized.npz's label counts)."""
    colours = ink_colours(list(names))
    rows = []
    printed = None
    if label_counts is not None:
        c = np.asarray(label_counts, np.float64)[: len(names)]
        printed = c / max(c.sum(), 1.0)
    for i, n in enumerate(names):
        r, g, b = colours[i][:3]
        rows.append(
            [
                f'<span class="swatch" style="background:rgb({r},{g},{b})"></span>{escape(n)}',
                "–" if mixture_mean is None else f"{100 * mixture_mean[i]:.1f} %",
                "–" if printed is None else f"{100 * printed[i]:.1f} %",
            ]
        )
    return _table(["ink", "share, optimised", "share of printed voxels"], rows, "inks")


def settings_html(report: Report, ev: Evaluation | None, quantization: dict | None) -> str:
    """Printer, layer and run settings, times and the display lighting, as a definition list."""
    items = []
    scene = report.scene
    if "height_mm" in scene:
        items.append(("object", f"mesh {scene['height_mm']:.1f} mm high, {scene.get('texels', '?')} surface texels"))
    elif "size_mm" in scene:
        items.append(("object", "slab " + " x ".join(f"{v:g}" for v in scene["size_mm"]) + " mm"))
    if "voxel_mm" in scene:
        items.append(("optimisation grid", f"{1000 * scene['voxel_mm'][0]:.1f} µm voxels"))
    if quantization:
        dpi = quantization.get("dpi") or []
        if len(dpi) == 3:
            items.append(
                (
                    "printer resolution",
                    f"{dpi[0]:g} x {dpi[1]:g} DPI, layers {25400 / dpi[2]:.1f} µm ({dpi[2]:g} DPI in z)",
                )
            )
        items.append(
            (
                "halftoning",
                f"{quantization.get('method')}, seed {quantization.get('seed')}, {quantization.get('upsample')}",
            )
        )
    else:
        items.append(("printer resolution", "not quantized yet (run <code>inkopt quantize</code>)"))
    items.append(
        (
            "optimisation",
            f"{report.iterations} iterations, {report.optimizer} step {report.lr:g}, {report.spp} spp per gradient, "
            f"init {escape(str(report.init))}, seed {report.seed}",
        )
    )
    t = f"{report.seconds:.0f} s in all ({report.seconds_per_iteration:.2f} s per iteration)"
    if ev is not None:
        t += f"; evaluation {ev.seconds:.0f} s"
    items.append(("time", t))
    light = ev.lighting if ev is not None else report.lighting
    items.append(("display lighting", escape(describe_lighting(light))))
    return "<dl>" + "".join(f"<dt>{escape(k)}</dt><dd>{v}</dd>" for k, v in items) + "</dl>"


def describe_lighting(d: dict) -> str:
    """A line for ``Lighting.describe()``'s fields."""
    src = d.get("lighting", "uniform")
    if src == "uniform":
        return "uniform white light from every direction"
    rot = d.get("lighting_rotate_deg", 0.0)
    return f"environment map {src}" + (f", rotated {rot:g}°" if rot else "")
