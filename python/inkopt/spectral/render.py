"""Band renders of a spectral ink table through the RGB core: three bands at a time as a path's three "channels".

The core traces each channel of a texel's samples independently (a path carries one channel; its random numbers
are keyed by (seed, texel, sample, channel)), so a table of B bands renders as ceil(B / 3) RGB-shaped tables
(``SpectralInkTable.band_groups``), group k with seed :func:`group_seed` (seed, k): the groups' noise is
independent, group 0 keeps the pass's seed (a 3-band table renders exactly as the RGB renderer renders it), and
every group is bit-identical for any thread count. A group's fourth-or-later band slot repeats its last band
(traced, its value dropped, its adjoint 0). Gradients replay each group's paths with the group's adjoints.

How the bands are sampled is the renderer's plan (``spectral.allocation.BandPlan``): which bands share a group
(default: wavelength order), the groups' ``weights`` and ``hero`` paths. Samples per group: a pass of ``spp``
samples gives every group ``spp`` samples unless the plan has group ``weights``; then the pass's G x spp samples are
shared out in proportion to the weights (Neyman allocation: weight = the square root of the group's share of the
colour's variance, :func:`group_spp`), at least one each, so bands that barely reach the colour (the spectrum's
ends) cost little. Each band's estimate stays unbiased and its variance (``var_mean``) is its own.

``hero`` (the plan's): each group's paths carry its three bands at once (the core's hero-channel paths: ``spp``
paths per texel serve the group's three bands, the hero band sample mod 3, the balance heuristic over the three
bands' samplers, ``PassSettings.hero``) instead of one path per band and sample; a group's bands are then correlated
(one path), each stays unbiased with its own variance.

The light's spectrum does not enter transport (``spectral.lights``); what does is the geometric lighting, which
must be grey (the same radiance in R, G and B: the uniform light or a grey map such as the calibration's upper
hemisphere): an RGB environment map has no spectrum.

:class:`SpectralRenderer` keeps one core renderer per group (each its own geometry and medium: memory x groups);
it is a :class:`~inkopt.render.TexelRenderer` whose "rgb" arrays hold B band values per texel.
"""

from __future__ import annotations

import hashlib
from dataclasses import replace

import numpy as np

from ..errors import ParameterError
from ..lighting import Lighting, load_lighting
from ..model import Texels, Volume
from ..model.spectral import GROUP, SpectralInkTable
from ..render import PassSettings, Renderer, RendererFactory, RenderResult, TexelRenderer
from .allocation import BandPlan
from .bands import band_table, check_grey, with_inks


def group_seed(seed: int, group: int) -> int:
    """The seed of band group ``group`` in a pass of seed ``seed``: ``seed`` itself for group 0, else a hash of
    (seed, group) in [0, 2^63)."""
    if group == 0:
        return int(seed)
    digest = hashlib.blake2b(f"{int(seed)}:{int(group)}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "little") >> 1


def group_spp(spp: int, weights: np.ndarray | None, groups: int) -> list[int]:
    """Samples per texel of each of ``groups`` band groups in a pass of ``spp``: ``spp`` each without ``weights``,
    else round(G spp w_g / sum w) and at least 1."""
    if weights is None or groups == 1:
        return [int(spp)] * groups
    w = np.asarray(weights, np.float64)
    return [max(1, int(round(groups * spp * x / w.sum()))) for x in w]


class SpectralRenderer(TexelRenderer):
    """Renders band values (I, B) of ``volume`` (a mixture or labels of ``table``'s inks; the volume's own ink
    table gives only the names) with ``table``: one renderer per band group, built by ``factory(volume, threads,
    lighting)`` (default :class:`~inkopt.render.Renderer`). ``lighting`` must be grey (:func:`check_grey`).
    ``plan``: how the bands are sampled (``spectral.allocation.BandPlan``: the bands of each group, the groups'
    shares of a pass's samples, :func:`group_spp`, and hero paths, see the module's documentation; None: the
    table's bands in wavelength order, ``table.group_bands()``, every group the pass's spp, one path per band).
    ``shared``: one renderer for every group, each group's medium swapped in before its pass (``set_volume``, which
    renders bit-identically to a renderer built for it): the geometry is held once instead of G times, for
    evaluations; its medium cannot be updated in place (``set_mixture``)."""

    def __init__(
        self,
        volume: Volume,
        table: SpectralInkTable,
        threads: int | None = None,
        lighting: Lighting | str | None = None,
        factory: RendererFactory | None = None,
        plan: BandPlan | None = None,
        shared: bool = False,
    ):
        if volume.inks is None or tuple(volume.inks.names) != tuple(table.names):
            have = None if volume.inks is None else list(volume.inks.names)
            raise ParameterError(f"`inks` {list(table.names)} must be the volume's inks {have}, in order")
        plan = BandPlan.in_order(table) if plan is None else plan
        if plan.bands != table.bands:
            raise ParameterError(f"`plan` must be of the spectral ink table's {table.bands} bands, not {plan.bands}")
        self.table, self.plan = table, plan
        self._source = volume  # whose medium the groups render (``shared``: swapped in from it)
        self.volume = volume
        self.lighting = check_grey(load_lighting(lighting))
        self._bands = [tuple(g) for g in plan.groups]
        self._groups = [band_table(table, bands) for bands in self._bands]
        self.weights = None if plan.weights is None else np.asarray(plan.weights, np.float64)
        make = factory or Renderer
        self.shared, self._current, self.hero = bool(shared), 0, plan.hero
        built = self._groups[:1] if self.shared else self._groups
        self._renderers = [make(with_inks(volume, g), threads, self.lighting) for g in built]

    @property
    def threads(self) -> int:
        return self._renderers[0].threads

    @property
    def volume(self) -> Volume:
        return self._volume

    @volume.setter
    def volume(self, volume: Volume) -> None:
        """The volume the renderer describes; every group's renderer is given it too (read with the group's inks),
        so a caller that points it back at the volume the geometry was built for frees the one it replaced (a
        ``shared`` renderer keeps the volume of the last ``set_volume``: it swaps each group's medium in from it)."""
        self._volume = volume
        if getattr(self, "shared", False):
            self._renderers[0].volume = with_inks(volume, self._groups[self._current])
            return
        for r, g in zip(getattr(self, "_renderers", ()), getattr(self, "_groups", ())):
            r.volume = with_inks(volume, g)

    def _each(self):
        """(group index, its renderer) for every band group; a shared renderer is given the group's medium first."""
        for k in range(len(self._groups)):
            if not self.shared:
                yield k, self._renderers[k]
                continue
            r = self._renderers[0]
            if self._current != k:
                r.set_volume(with_inks(self._source, self._groups[k]))
                self._current = k
            yield k, r

    @property
    def bands(self) -> int:
        return self.table.bands

    def set_lighting(self, lighting: Lighting | str | None) -> None:
        light = check_grey(load_lighting(lighting))
        for r in self._renderers:
            r.set_lighting(light)
        self.lighting = light

    def set_volume(self, volume: Volume) -> None:
        self._source = volume
        for r, g in zip(self._renderers, self._groups[self._current :] if self.shared else self._groups):
            r.set_volume(with_inks(volume, g))
        self.volume = volume

    def set_mixture(self, index: np.ndarray, mixture: np.ndarray) -> None:
        if self.shared:
            raise ParameterError("`shared` band renders swap each group's medium in: they cannot update it in place")
        for r in self._renderers:
            r.set_mixture(index, mixture)

    def _gather(self, results: list[RenderResult], settings: PassSettings) -> RenderResult:
        """The groups' results as one: (I, B) band values and variances, counts and seconds summed."""
        n = len(results[0].rgb)
        values = np.empty((n, self.bands), np.float32)
        var = np.empty((n, self.bands), np.float32)
        for res, bands in zip(results, self._bands):
            values[:, bands] = res.rgb[:, : len(bands)]
            var[:, bands] = res.var_mean[:, : len(bands)]
        counts = ("paths", "events", "replayed_paths", "replayed_events")
        total = {k: sum(getattr(r, k) for r in results) for k in counts}
        return RenderResult(values, var, int(settings.spp), sum(r.seconds for r in results), **total)

    def render_pass(self, texels: Texels, settings: PassSettings, progress: bool = False) -> RenderResult:
        """Band values (I, B) float32 and their variances: each group rendered with its :func:`group_seed`."""
        results = [r.render_pass(texels, self._settings(settings, k), progress) for k, r in self._each()]
        return self._gather(results, settings)

    def _settings(self, settings: PassSettings, group: int) -> PassSettings:
        """Group ``group``'s pass: its seed (:func:`group_seed`), samples (:func:`group_spp`) and ``hero`` (hero paths
        have "replay" gradients only: the "li1" method's passes trace one path per band)."""
        spp = group_spp(settings.spp, self.weights, len(self._groups))[group]
        hero = self.hero and settings.method == "replay"
        return replace(settings, seed=group_seed(settings.seed, group), spp=spp, hero=hero)

    def gradient_pass(
        self,
        texels: Texels,
        adjoint: np.ndarray,
        settings: PassSettings,
        grad_index: np.ndarray | None = None,
        progress: bool = False,
    ) -> tuple[np.ndarray, np.ndarray, RenderResult]:
        """``adjoint`` (I, B) = de/d band values -> (de/dsigma_s, de/dsigma_a) shaped like the RGB renderer's
        with B bands in the last axis (float32), and the pass's own band estimate; each group replays its paths."""
        adjoint = np.asarray(adjoint, np.float32)
        if adjoint.shape != (len(texels), self.bands):
            raise ParameterError(f"`adjoint` must have shape ({len(texels)}, {self.bands}), got {adjoint.shape}")
        gs = ga = None
        results = []
        for (k, r), bands in zip(self._each(), self._bands):
            adj = np.zeros((len(texels), GROUP), np.float32)
            adj[:, : len(bands)] = adjoint[:, bands]
            s, a, res = r.gradient_pass(texels, adj, self._settings(settings, k), grad_index)
            if gs is None:
                gs = np.empty(s.shape[:-1] + (self.bands,), np.float32)
                ga = np.empty_like(gs)
            gs[..., bands], ga[..., bands] = s[..., : len(bands)], a[..., : len(bands)]
            results.append(res)
        return gs, ga, self._gather(results, settings)
