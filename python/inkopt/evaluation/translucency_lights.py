"""The translucency figures of a spectral run under each light (``evaluation.translucency``'s, band by band).

Light of one wavelength travels through the inks independently of every other, so the translucency figures of a
spectral ink table are those of each band, combined per light as the eye sees them: the luminance Y under light S
(CIE 1931 2°, a perfect white Y = 1: row 1 of the light's colour map, ``ColourMap.matrix[1]``, (B,)) of the band
values. Per band the renders are ``translucency``'s own (the same back light, texels, probes and knife edge), with a
spectral ink table's bands rendered three at a time by ``spectral.render.SpectralRenderer`` in wavelength order,
every band its own paths at the full ``spp`` (no band plan: the bands' estimates are independent, so a light's
variance is sum_b w_b^2 var_b):

- **transmittance** under S: the mean over a region's texels of Y_S of each texel's band transmittances, with its
  standard error;
- **spread** under S: the knife edge's E|Δx| with the probe's exit light weighed per band by Y_S's weights (the
  luminance-weighted line-spread width), the probe's layers the region's mean mixture mixed with the spectral
  table (``model.inks.mix``), each band group rendered with its :func:`~inkopt.spectral.render.group_seed`.

On spectra flat over wavelength every light's figures are the RGB figures (``translucency.measure``, luminance
Y of linear Rec. 709), within their standard errors; a spectrally non-flat ink's differ from light to light
(tests/spectral/test_translucency.py).

Each region's entry holds ``by_light`` {light: figures} and, at its top level, the first light's figures under the
RGB figures' names (so ``translucency.table_lines`` prints them).
"""

from __future__ import annotations

import numpy as np

from ..color import ColourMap
from ..model import Texels, Volume
from ..model.inks import mix
from ..model.spectral import GROUP, SpectralInkTable
from ..render import Renderer
from ..rundir import SceneRecord
from ..spectral.render import SpectralRenderer, group_seed
from .translucency import (
    PROBE_WIDTH,
    TranslucencyRenders,
    back_light,
    depth_layers,
    edge_spread,
    face_group,
    probe_mixture,
    probe_volume,
    regions,
    texel_axes,
)

#: the renders' defaults (``translucency``'s)
DEFAULT_RENDERS = TranslucencyRenders()


def luminance_weights(colours: tuple[ColourMap, ...]) -> dict[str, np.ndarray]:
    """{light name: (B,) float64}: each band's weight in the luminance Y under the light (Y of white = 1)."""
    return {c.name: np.asarray(c.matrix[1], np.float64) for c in colours}


def band_transmittance(
    volume: Volume, texels: Texels, table: SpectralInkTable, renders: TranslucencyRenders
) -> tuple[np.ndarray, np.ndarray]:
    """Per texel and band the diffuse transmittance (I, B) float64 and its variance (I, B): each texel lit from
    behind its face (``translucency.back_light``), ``renders.spp`` samples per band."""
    axes = texel_axes(texels)
    t = np.zeros((len(texels), table.bands))
    var = np.zeros_like(t)
    renderer = None
    for a in np.unique(axes):
        sel = np.flatnonzero(axes == a)
        if renderer is None:
            renderer = SpectralRenderer(volume, table, renders.threads, back_light(int(a)), shared=True)
        else:
            renderer.set_lighting(back_light(int(a)))
        r = renderer.render(texels.subset(sel), renders.spp, renders.seed + int(a))
        t[sel], var[sel] = r.rgb, r.var_mean
    return t, var


def band_spread(
    mixture: np.ndarray,
    table: SpectralInkTable,
    voxel_mm: float,
    g: float,
    ior: float,
    renders: TranslucencyRenders,
    weights: dict[str, np.ndarray],
    width: int | None = None,
) -> dict[str, dict]:
    """{light: E|Δx| figures (``translucency.edge_spread``)} of the knife-edge probe whose layers hold ``mixture``
    (L, N) of ``table``'s inks (layer 0 the viewed surface; phase function ``g``, index ``ior``), its exit light
    weighed by each light's ``weights`` (B,); ``width`` voxels along x (default ``PROBE_WIDTH``)."""
    width = int(width or PROBE_WIDTH)
    sigma_s, sigma_a = mix(mixture, table)  # (L, B)
    values = var = None
    for k, bands in enumerate(table.group_bands()):
        cols = list(bands) + [bands[-1]] * (GROUP - len(bands))  # a short group repeats its last band
        vol, tex = probe_volume(sigma_s[:, cols], sigma_a[:, cols], voxel_mm, g, ior, width)
        r = Renderer(vol, renders.threads, back_light(5)).render(tex, renders.probe_spp, group_seed(renders.seed, k))
        if values is None:
            values, var = np.zeros((len(tex), table.bands)), np.zeros((len(tex), table.bands))
        values[:, bands], var[:, bands] = r.rgb[:, : len(bands)], r.var_mean[:, : len(bands)]
    return {name: edge_spread(values @ w, var @ w**2, width, voxel_mm) for name, w in weights.items()}


def measure_lights(
    vol: Volume,
    rec: SceneRecord,
    table: SpectralInkTable,
    colours: tuple[ColourMap, ...],
    region_rec: SceneRecord | None = None,
    renders: TranslucencyRenders = DEFAULT_RENDERS,
) -> dict:
    """``translucency.measure``'s figures of ``vol`` (a mixture volume of ``table``'s inks, scene ``rec``) per
    region of ``region_rec``'s constraint (default ``rec``'s) and for the whole face group, under each light of
    ``colours`` (module docstring): {"lights", "regions", "whole", "spp", "probe_spp", "probe_width_mm"}."""
    region_rec = region_rec or rec
    if len(region_rec.texels) != len(rec.texels) or not np.array_equal(region_rec.texels.voxel, rec.texels.voxel):
        raise ValueError("the runs compared for translucency have different texels (not the same target and size)")
    weights = luminance_weights(colours)
    group = face_group(rec)
    t, var = np.zeros((len(rec.texels), table.bands)), np.zeros((len(rec.texels), table.bands))
    t[group], var[group] = band_transmittance(vol, rec.texels.subset(group), table, renders)
    try:
        near, depth = depth_layers(vol, rec.texels.subset(group))
    except MemoryError:
        near = depth = None
    share = rec.translucency.texel_share(rec.texels) if rec.translucency is not None else None

    def figures(sel: np.ndarray) -> dict:
        by = {
            n: {
                "transmittance": float((t[sel] @ w).mean()),
                "transmittance_stderr": float(np.sqrt((var[sel] @ w**2).sum()) / len(sel)),
            }
            for n, w in weights.items()
        }
        f = {"texels": int(len(sel)), "required_share": None if share is None else float(share[sel].mean())}
        if near is not None:
            mixture = probe_mixture(vol, near, depth, np.searchsorted(group, sel))
            for n, s in band_spread(mixture, table, float(vol.voxel_mm[0]), vol.g, vol.ior, renders, weights).items():
                by[n].update(s)
            f["probe_layers"] = int(len(mixture))
        return {**f, **by[colours[0].name], "by_light": by}

    return {
        "lights": list(weights),
        "regions": [figures(r) for r in regions(region_rec, group)],
        "whole": figures(group),
        "spp": int(renders.spp),
        "probe_spp": int(renders.probe_spp),
        "probe_width_mm": float(PROBE_WIDTH * vol.voxel_mm[0]),
    }


def evaluate_translucency_lights(
    vol: Volume,
    rec: SceneRecord,
    table: SpectralInkTable,
    colours: tuple[ColourMap, ...],
    compare=None,
    seed: int = 0,
    threads: int | None = None,
    log=None,
) -> dict:
    """evaluation_lights.json's ``translucency``: :func:`measure_lights` of the run (``vol``, ``rec``) under the
    lights of ``colours`` and, with ``compare`` (the run directory of an unconstrained run of the same target and
    inks), of that run on the same regions; each with its ``seconds``. Rendered as ``translucency`` renders them
    (``DEFAULT_SPP`` per band, ``PROBE_SPP``; no per-region ΔE76: the evaluation's figures hold the colour)."""
    from . import translucency

    renders = TranslucencyRenders(translucency.DEFAULT_SPP, translucency.PROBE_SPP, seed, threads)
    say = log or (lambda msg: None)
    lights = ", ".join(c.name for c in colours)

    def one(v: Volume, r: SceneRecord) -> dict:
        return measure_lights(v, r, table, colours, rec, renders)

    return translucency.measured_with_compare(one, vol, rec, compare, say, f"translucency under {lights}")
