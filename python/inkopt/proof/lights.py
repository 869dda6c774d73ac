"""A spectral run's soft proof under several lights: the colours each light gives the stored band values, the page's
light selector and the figures table of each light.

predictions.npz of a spectral run keeps every result's band reflectances and the band matrices of the lights the run
or its evaluation asked (``rundir.BandValues``). The page offers those lights and D65 and A (``ALWAYS``) on the
run's band grid; under each, a result's colour is its bands' CIE XYZ relative to that light's white, carried to
sRGB's D65 white by the Bradford transform (``spectral.viewing.display_under``, as the run's own pictures), and its
ΔE76 / ΔE2000 to the target are in CIELAB relative to the light's white (as ``evaluation.lights``), the target
being the same under every light (the texture as an adapted viewer sees it). All of it is computed here, when the
page is written; the page's script only switches pictures. Light names come from files anyone may edit (a light
file's name, predictions.npz): they reach the page only through ``markup.html`` and the JSON data block, and the
scripts address lights by index, never by name.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..color import ColourMap, delta_e76, delta_e2000, linear_to_lab
from ..rundir import BandValues
from ..spectral.lights import named_light
from ..spectral.viewing import display_under
from .figures import LABELS, _num, _table
from .markup import Markup, html, join

#: lights every spectral page offers besides the run's and its evaluation's
ALWAYS = ("D65", "A")


@dataclass(frozen=True)
class LightViews:
    """Under each light of ``names`` (the first: the run's or evaluation's first): ``colours[k]`` {result: (I, 3)
    linear sRGB, Bradford-adapted}, ``de76[k]`` and ``de2000[k]`` {result: (I,) float64 to the target}, and
    ``inconstancy[k]`` {result: mean ΔE2000 between the result under the first light and under light k}."""

    names: tuple[str, ...]
    colours: tuple[dict, ...]
    de76: tuple[dict, ...]
    de2000: tuple[dict, ...]
    inconstancy: tuple[dict, ...]


def offered_lights(bands: BandValues) -> list[ColourMap]:
    """The colour maps of the stored lights (in their order), then of ``ALWAYS`` not among them (a named light's
    name stands for it: a stored light of that name is kept)."""
    maps = [ColourMap(m, name) for name, m in bands.lights.items()]
    have = {c.name for c in maps}
    maps += [named_light(n).colour_map(bands.wavelengths_nm) for n in ALWAYS if n not in have]
    return maps


def light_views(bands: BandValues, target_rgb, keys: list[str]) -> LightViews:
    """The colours and ΔE of results ``keys`` (those of ``bands.values``; "target" is the target itself under every
    light) under each offered light, from targets ``target_rgb`` (I, 3) linear sRGB."""
    target = np.asarray(target_rgb, np.float64)
    target_lab = linear_to_lab(target)
    results = [k for k in keys if k in bands.values]
    maps = offered_lights(bands)
    labs = [{k: c.lab(bands.values[k]) for k in results} for c in maps]
    colours = tuple({"target": target, **{k: display_under(c, bands.values[k]) for k in results}} for c in maps)
    return LightViews(
        tuple(c.name for c in maps),
        colours,
        tuple({k: delta_e76(lab[k], target_lab) for k in results} for lab in labs),
        tuple({k: delta_e2000(lab[k], target_lab) for k in results} for lab in labs),
        tuple({k: float(delta_e2000(labs[0][k], lab[k]).mean()) for k in results} for lab in labs),
    )


def light_bar(names: tuple[str, ...]) -> Markup:
    """The light selector: one option per light, valued by its index (the scripts never see a name)."""
    options = join(
        html('<option value="{}"{}>{}</option>', i, html(" selected") if i == 0 else "", n) for i, n in enumerate(names)
    )
    return html(
        '<div class="bar" id="lightbar"><label>seen under <select id="light">{}</select></label>'
        '<span class="note">colours computed from the predicted spectra under each light, adapted to sRGB\'s white '
        "(Bradford), as a viewer adapted to that light sees them</span></div>",
        options,
    )


FIGURE_HEAD = ["result", "ΔE76 mean", "ΔE2000 mean", "ΔE2000 p95", "SSIM", "colour inconstancy (ΔE2000)"]


def light_figures_html(lv: LightViews, evaluated: dict | None) -> Markup:
    """One figures table per light (``data-light-table`` its index; all but the first hidden until the selector shows
    it): per result its mean ΔE76, mean and 95th-percentile ΔE2000 from the stored band values, SSIM from
    evaluation_lights.json (``evaluated``: its JSON, or None) where it judged that light, and the colour inconstancy
    against the first light."""
    evaluated = evaluated if isinstance(evaluated, dict) else {}
    tables = []
    for i, name in enumerate(lv.names):
        rows = []
        for k, de76 in lv.de76[i].items():
            by_light = evaluated.get(k, {}).get("by_light", {}) if isinstance(evaluated.get(k), dict) else {}
            ssim = by_light.get(name, {}).get("ssim") if isinstance(by_light.get(name), dict) else None
            de2000 = lv.de2000[i][k]
            incon = "–" if i == 0 else _num(lv.inconstancy[i][k])
            row = [LABELS.get(k, k), _num(float(de76.mean())), _num(float(de2000.mean()))]
            rows.append(row + [_num(float(np.percentile(de2000, 95))), _num(ssim, ".3f"), incon])
        note = html(
            "under {}: ΔE from the predicted spectra (render noise included); SSIM from <code>inkopt evaluate</code> "
            "where it judged this light; colour inconstancy: mean ΔE2000 of each result between {} and {}",
            name,
            lv.names[0],
            name,
        )
        hidden = html(" hidden") if i else ""
        tables.append(
            html(
                '<div data-light-table="{}"{}>{}<p class="note">{}.</p></div>',
                i,
                hidden,
                _table(FIGURE_HEAD, rows, "figures"),
                note,
            )
        )
    return join(tables)
