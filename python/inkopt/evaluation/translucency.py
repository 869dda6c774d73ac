"""Translucency measurements of a run: how much light goes through, and how far it spreads sideways
(docs/lighting-and-translucency.md).

Two figures, per constrained region (a connected set of texels whose voxels carry a translucency constraint) and
for the whole object, always on the same texels (those of the constrained run's scene):

- **Diffuse transmittance** ``transmittance``: the texel's rendered luminance Y (linear Rec. 709) when the only
  light is radiance 1 from the hemisphere *opposite* its face (an environment map lit where ``dir . axis < 0``,
  ``axis`` the texel's dominant outward normal axis; a slab's top face is lit from below). With the view ray along
  the inward normal and the illumination diffuse, this is the directional-hemispherical transmittance of the
  object there (1 for a vacuum, ~0.92 for a clear non-absorbing slab of index 1.5: two Fresnel crossings).
  Mean over the region's texels, with its Monte Carlo standard error.
- **Lateral spread** ``spread_mm``: the mean absolute sideways displacement E|Δx| of light between where it enters
  the far side and where it leaves the viewed face, the width of the line-spread function (the response to a thin
  line of light). Measured by a knife edge on a *probe*: a laterally homogeneous slab (periodic in x and y,
  ``PROBE_WIDTH`` voxels wide) whose layer k holds the region's mean medium k voxels below its surface (voxels are
  assigned to their nearest texel of the face group, so a slab region gives its voxel columns), over an opaque
  mask covering half of its far face (x < width / 2) and lit diffusely from the far side. Light that emerges above
  the mask travelled sideways: for a shift-invariant medium with two edges in a period, sum over the dark half of
  the exit light / sum over all = E|Δx| / (width / 2), so E|Δx| = (width / 2) * dark / all (valid while the spread
  is well below the width). A clear, non-scattering medium has E|Δx| = 0 (the view ray goes straight through);
  scattering widens it, up to about the thickness for a diffusing slab.

Both are rendered at fixed ``spp`` (``DEFAULT_SPP``; the figures carry their standard errors). Regions with fewer
than ``MIN_REGION_TEXELS`` texels are skipped; at most ``MAX_REGIONS`` (the largest) are reported.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..lighting import Lighting
from ..model import FACE_NORMALS, Texels, Volume
from ..model.inks import mix
from ..render import Renderer
from ..rundir import SceneRecord

DEFAULT_SPP = 64
PROBE_SPP = 64
PROBE_WIDTH = 256  # voxels along x (periodic); the probe is 2 voxels deep in y (periodic)
MASK_SIGMA_A = 1000.0  # mm^-1: the knife edge's absorber (optical depth ~85 per 85 µm voxel)
MAP_ROWS = 32
MIN_REGION_TEXELS = 4
MAX_REGIONS = 8
MAX_GRID_VOXELS = 30_000_000  # the probe's depth assignment needs ~30 bytes per grid voxel
LUMA = np.array([0.2126, 0.7152, 0.0722])


@dataclass(frozen=True)
class TranslucencyRenders:
    """The renders of the translucency figures: ``spp`` samples per texel of the transmittance, ``probe_spp`` of
    each knife-edge probe, their ``seed`` and render ``threads`` (None: all cores)."""

    spp: int = DEFAULT_SPP
    probe_spp: int = PROBE_SPP
    seed: int = 0
    threads: int | None = None


def back_light(axis: int, rows: int = MAP_ROWS) -> Lighting:
    """An environment of radiance 1 where ``dir . FACE_NORMALS[axis] < 0`` (behind a face of that axis), 0 else."""
    i = (np.arange(rows) + 0.5) * np.pi / rows
    j = (np.arange(2 * rows) + 0.5) * np.pi / rows
    th, ph = np.meshgrid(i, j, indexing="ij")
    d = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    lit = (d @ FACE_NORMALS[axis].astype(np.float64)) < 0
    return Lighting(np.repeat(lit[..., None], 3, -1).astype(np.float32), 0.0, f"back-light {axis}")


def texel_axes(texels: Texels) -> np.ndarray:
    """(I,) int: the face id whose outward normal is closest to each texel's normal."""
    return np.argmax(texels.normal @ FACE_NORMALS.T, axis=1)


def transmittance(volume: Volume, texels: Texels, spp: int = DEFAULT_SPP, seed: int = 0, threads=None):
    """Per-texel diffuse transmittance: luminance (I,) and its variance (I,) (module docstring)."""
    axes = texel_axes(texels)
    y, var = np.zeros(len(texels)), np.zeros(len(texels))
    renderer = None
    for a in np.unique(axes):
        sel = np.flatnonzero(axes == a)
        if renderer is None:
            renderer = Renderer(volume, threads, back_light(int(a)))
        else:
            renderer.set_lighting(back_light(int(a)))
        r = renderer.render(texels.subset(sel), spp, seed + int(a))
        y[sel] = r.rgb.astype(np.float64) @ LUMA
        var[sel] = r.var_mean.astype(np.float64) @ LUMA**2
    return y, var


def knife_edge_spread(
    sigma_s: np.ndarray,
    sigma_a: np.ndarray,
    voxel_mm: float,
    g: float,
    ior: float,
    renders: TranslucencyRenders = TranslucencyRenders(),
    width: int | None = None,
) -> dict:
    """E|Δx| (mm) of a layered probe: ``sigma_s``, ``sigma_a`` (L, 3) mm^-1, layer 0 the viewed surface;
    ``width`` voxels along x (default ``PROBE_WIDTH``), rendered at ``renders.probe_spp``."""
    width = int(width or PROBE_WIDTH)
    vol, tex = probe_volume(sigma_s, sigma_a, voxel_mm, g, ior, width)
    r = Renderer(vol, renders.threads, back_light(5)).render(tex, renders.probe_spp, renders.seed)
    return edge_spread(r.rgb.astype(np.float64) @ LUMA, r.var_mean.astype(np.float64) @ LUMA**2, width, voxel_mm)


def probe_volume(sigma_s: np.ndarray, sigma_a: np.ndarray, voxel_mm: float, g: float, ior: float, width: int):
    """The knife-edge probe of layers ``sigma_s``, ``sigma_a`` (L, 3) mm^-1 (layer 0 the viewed surface),
    ``width`` voxels along x, over its half-masked far face, and its top texels."""
    L = len(sigma_s)
    ss = np.zeros((L + 1, 2, width, 3), np.float32)
    sa = np.full((L + 1, 2, width, 3), 1e-4, np.float32)
    ss[1:] = np.asarray(sigma_s, np.float32)[::-1, None, None]  # z = L: the surface layer, viewed from +z
    sa[1:] = np.asarray(sigma_a, np.float32)[::-1, None, None]
    sa[0, :, : width // 2] = MASK_SIGMA_A
    vol = Volume.from_coefficients((voxel_mm,) * 3, sigma_s=ss, sigma_a=sa, g=g, ior=ior, boundary="periodic-xy")
    return vol, Texels.box_faces(vol.shape, ["top"])


def edge_spread(y: np.ndarray, v: np.ndarray, width: int, voxel_mm: float) -> dict:
    """E|Δx| (mm) and its standard error from a probe's exit luminance ``y`` (2 x width,) and its variance ``v``
    (the probe's top texels in order: two rows of ``width``), and the probe's mean transmittance."""
    y, v = y.reshape(2, width).sum(0), v.reshape(2, width).sum(0)
    dark, total = y[: width // 2].sum(), y.sum()
    half = 0.5 * width * voxel_mm
    if total <= 0:
        return {"spread_mm": float("nan"), "spread_stderr_mm": float("nan"), "probe_transmittance": 0.0}
    ratio = dark / total
    var_ratio = ((1 - ratio) ** 2 * v[: width // 2].sum() + ratio**2 * v[width // 2 :].sum()) / total**2
    return {
        "spread_mm": float(half * ratio),
        "spread_stderr_mm": float(half * np.sqrt(var_ratio)),
        "probe_transmittance": float(total / width),
    }


def face_group(rec: SceneRecord) -> np.ndarray:
    """Indices of the texels that are measured: a slab's top face (the mask's face), every texel of a mesh."""
    if rec.kind == "slab":
        return np.flatnonzero(rec.texels.face == 5)
    return np.arange(len(rec.texels))


def regions(rec: SceneRecord, group: np.ndarray) -> list[np.ndarray]:
    """The constrained regions: connected (26-neighbour) sets of texel voxels of ``group`` with a positive required
    share, largest first (at most ``MAX_REGIONS``, each at least ``MIN_REGION_TEXELS``), as texel indices."""
    if rec.translucency is None:
        return []
    share = rec.translucency.texel_share(rec.texels)[group]
    vox = rec.texels.voxel[group]
    grid = np.zeros(rec.translucency.shape, np.int64)
    on = share > 0
    grid[tuple(vox[on].T)] = 1
    lab, n = ndimage.label(grid, np.ones((3, 3, 3), bool))
    ids = lab[tuple(vox.T)]
    order = np.argsort(ids, kind="stable")  # one pass over the texels however many components there are
    bounds = np.cumsum(np.bincount(ids, minlength=n + 1))
    out = [r for r in np.split(group[order], bounds[:-1])[1:] if len(r) >= MIN_REGION_TEXELS]
    return sorted(out, key=len, reverse=True)[:MAX_REGIONS]


def depth_layers(vol: Volume, texels: Texels) -> tuple[np.ndarray, np.ndarray]:
    """For every inside voxel its nearest texel of ``texels`` (index, (z, y, x) int64, -1 outside) and its depth
    in whole voxels below it."""
    inside = vol.inside_mask()
    if inside.size > MAX_GRID_VOXELS:
        raise MemoryError
    surf = np.ones(inside.shape, bool)
    surf[tuple(texels.voxel.T)] = False
    dist, idx = ndimage.distance_transform_edt(surf, return_indices=True)
    lin = np.full(inside.shape, -1, np.int64)
    lin[tuple(texels.voxel.T)] = np.arange(len(texels))
    near = lin[tuple(idx)]
    near[~inside] = -1
    return near, np.rint(dist).astype(np.int64)


def probe_medium(vol: Volume, near: np.ndarray, depth: np.ndarray, texel_sel: np.ndarray):
    """Mean sigma_s, sigma_a (L, 3) per depth layer of the voxels whose nearest texel is in ``texel_sel``."""
    return mix(probe_mixture(vol, near, depth, texel_sel), vol.inks)


def probe_mixture(vol: Volume, near: np.ndarray, depth: np.ndarray, texel_sel: np.ndarray) -> np.ndarray:
    """Mean mixture (L, N) float64 per depth layer of the voxels whose nearest texel is in ``texel_sel``."""
    member = np.zeros(near.max() + 2, bool)
    member[texel_sel] = True
    sel = member[near]  # near == -1 maps to member[-1], always False
    d = depth[sel]
    mixture = vol.mixture[sel].astype(np.float64)
    L = int(d.max()) + 1
    cnt = np.maximum(np.bincount(d, minlength=L), 1)[:, None]
    return np.stack([np.bincount(d, mixture[:, n], L) for n in range(mixture.shape[1])], 1) / cnt


@dataclass(frozen=True)
class _Measurements:
    """What the figures of every region of ``measure`` come from: the run's mixture volume, the measured face
    group (texel indices), each texel's transmittance ``t_y`` and its variance (I,) (0 outside the group), ΔE76
    (I,) or None, the nearest texel and depth of every voxel (None: too large a grid for the probes), the share the
    run's own constraint requires per texel (None: an unconstrained run) and the renders."""

    vol: Volume
    group: np.ndarray
    t_y: np.ndarray
    t_var: np.ndarray
    de: np.ndarray | None
    near: np.ndarray | None
    depth: np.ndarray | None
    share: np.ndarray | None
    renders: TranslucencyRenders

    def figures(self, sel: np.ndarray) -> dict:
        """The figures of the texels ``sel`` (indices, in the face group): transmittance, required share, ΔE76 and
        the knife-edge spread of their mean medium."""
        f = {
            "texels": int(len(sel)),
            "required_share": None if self.share is None else float(self.share[sel].mean()),
            "transmittance": float(self.t_y[sel].mean()),
            "transmittance_stderr": float(np.sqrt(self.t_var[sel].sum()) / len(sel)),
        }
        if self.de is not None:
            f["delta_e76_mean"] = float(self.de[sel].mean())
        if self.near is not None:
            local = np.searchsorted(self.group, sel)
            s_s, s_a = probe_medium(self.vol, self.near, self.depth, local)
            vol = self.vol
            f.update(knife_edge_spread(s_s, s_a, float(vol.voxel_mm[0]), vol.g, vol.ior, self.renders))
            f["probe_layers"] = int(len(s_s))
        return f


def measure(
    vol: Volume,
    rec: SceneRecord,
    region_rec: SceneRecord | None = None,
    renders: TranslucencyRenders = TranslucencyRenders(),
    colours: np.ndarray | None = None,
    target_lab: np.ndarray | None = None,
) -> dict:
    """Transmittance and spread of ``vol`` (a mixture volume of scene ``rec``) per region of ``region_rec``'s
    constraint (default ``rec``'s) and for the whole face group, with the share ``rec``'s own constraint requires
    there (``required_share``; None for a run without one); with ``colours`` (I, 3) linear and ``target_lab``
    (I, 3), each region's mean ΔE76 too."""
    from ..color import delta_e76, linear_to_lab

    region_rec = region_rec or rec
    if len(region_rec.texels) != len(rec.texels) or not np.array_equal(region_rec.texels.voxel, rec.texels.voxel):
        raise ValueError("the runs compared for translucency have different texels (not the same target and size)")
    group = face_group(rec)
    y, var = transmittance(vol, rec.texels.subset(group), renders.spp, renders.seed, renders.threads)
    t_y, t_var = np.zeros(len(rec.texels)), np.zeros(len(rec.texels))
    t_y[group], t_var[group] = y, var
    de = None if colours is None else delta_e76(linear_to_lab(colours), target_lab)
    try:
        near, depth = depth_layers(vol, rec.texels.subset(group))
    except MemoryError:
        near = depth = None
    # the share the measured run itself was required to hold (None: an unconstrained run has no requirement)
    share = rec.translucency.texel_share(rec.texels) if rec.translucency is not None else None
    at = _Measurements(vol, group, t_y, t_var, de, near, depth, share, renders)
    return {
        "regions": [at.figures(r) for r in regions(region_rec, group)],
        "whole": at.figures(group),
        "spp": int(renders.spp),
        "probe_spp": int(renders.probe_spp),
        "probe_width_mm": float(PROBE_WIDTH * vol.voxel_mm[0]),
    }


def table_lines(tr: dict) -> list[str]:
    """Plain-text lines of an evaluation's ``translucency`` entry (and its ``compare`` run's)."""
    lines = [f"{'translucency':<24}{'texels':>8}{'share':>7}{'dE76':>7}{'transmittance':>15}{'spread mm':>11}"]
    runs = [("", tr)] + ([("unconstrained ", tr["compare"])] if "compare" in tr else [])
    nan = float("nan")
    for prefix, t in runs:
        items = [(f"region {k + 1}", r) for k, r in enumerate(t["regions"])] + [("whole", t["whole"])]
        for name, r in items:
            req = "-" if r["required_share"] is None else f"{r['required_share']:.2f}"
            lines.append(
                f"{(prefix + name):<24}{r['texels']:>8}{req:>7}"
                f"{r.get('delta_e76_mean', nan):>7.2f}{r['transmittance']:>9.3f} ±{r['transmittance_stderr']:.3f}"
                f"{r.get('spread_mm', nan):>7.3f} ±{r.get('spread_stderr_mm', nan):.3f}"
            )
    return lines


COLOUR_SPP = 256  # the per-region ΔE76 of both runs: one render each at this spp under the evaluation's lighting


def evaluate_translucency(
    vol: Volume,
    rec: SceneRecord,
    compare=None,
    seed: int = 0,
    threads=None,
    lighting=None,
    spp: int = DEFAULT_SPP,
    log=None,
) -> dict:
    """evaluation.json's ``translucency``: ``measure`` of the run (``vol``, ``rec``) and, with ``compare`` (the
    run directory of an unconstrained run of the same target), of that run on the same regions, each with its
    per-region ΔE76 from a ``COLOUR_SPP`` render under ``lighting``."""
    from ..color import linear_to_lab

    target_lab = linear_to_lab(rec.target_rgb.astype(np.float64))
    say = log or (lambda msg: None)

    def one(v: Volume, r: SceneRecord) -> dict:
        colours = Renderer(v, threads, lighting).render(r.texels, COLOUR_SPP, seed).rgb.astype(np.float64)
        renders = TranslucencyRenders(spp, PROBE_SPP, seed, threads)  # PROBE_SPP: the module's value at call time
        return measure(v, r, rec, renders, colours, target_lab)

    out = measured_with_compare(one, vol, rec, compare, say, "translucency")
    out["colour_spp"] = COLOUR_SPP
    return out


def measured_with_compare(one, vol: Volume, rec: SceneRecord, compare, say, what: str) -> dict:
    """``one(volume, scene)`` (a dict with ``regions``) of the run and, with ``compare`` (a run directory), of that
    run as its ``compare`` entry; each with its ``seconds`` and one line to ``say`` naming ``what``."""
    import time

    from ..rundir import RunDir

    def timed(v: Volume, r: SceneRecord) -> dict:
        t0 = time.perf_counter()
        m = one(v, r)
        return {**m, "seconds": time.perf_counter() - t0}

    out = timed(vol, rec)
    say(f"{what}: {len(out['regions'])} regions in {out['seconds']:.1f} s")
    if compare is not None:
        d = RunDir(compare)
        out["compare"] = {"run": str(compare), **timed(d.load_volume(), d.load_scene())}
        say(f"translucency of {compare}: {out['compare']['seconds']:.1f} s")
    return out
