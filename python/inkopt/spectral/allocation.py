"""Which bands share a path group and how many samples each group gets, from a pilot render of the volume itself.

A band render's colour noise is a sum over bands (band paths are independent): the squared CIELAB standard error of
a texel is sum_j w_j s_j^2 / n_j, with w_j = sum over the lights and L*, a*, b* of (d lab / d band j)^2, s_j^2 the
band's variance per sample and n_j its samples; a band's cost per sample is c_j, the path events of one of its
paths. Bands differ by orders of magnitude in both: where white ink scatters most (the blue bands) paths are 3.6x
longer than in the red ones, and the bands at the spectrum's ends barely reach the eye. For a fixed cost the
noise is least when n_j is proportional to sqrt(A_j / c_j), A_j = the texels' mean of w_j s_j^2 (Neyman allocation
with costs). The core traces three bands per group with one sample count, so :func:`plan` puts the bands in order
of that ideal density and takes consecutive triples (bands of one group then want about the same samples; a group
need not be three neighbouring wavelengths), and gives group g the weight sqrt(A_g / C_g) (A_g, C_g: its bands'
sums; the optimum for those groups). Every band's estimate stays the mean of its own paths: unbiased whatever the
plan, which only moves cost between bands.

:func:`pilot` measures A_j and c_j on the volume: every band rendered on its own (its three channels one band) at a
fixed seed on an evenly spaced subset of the texels; it is a pure function of the volume, texels and lights
(bit-identical for any thread count), so a run that repeats it (a resume) gets the same plan.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..color import ColourMap
from ..errors import ParameterError
from ..lighting import Lighting, load_lighting
from ..model import Texels, Volume
from ..model.spectral import GROUP, SpectralInkTable
from ..render import PassSettings, Renderer, RendererFactory
from .bands import band_table, check_grey, check_groups, with_inks

#: the pilot's random numbers (a constant: the plan is a function of the volume, not of a run's seed)
PILOT_SEED = 0x5EC7_A110
#: at most this many texels in the pilot (evenly spaced over the list)
PILOT_TEXELS = 4096
#: the pilot's samples per band slot: spread over its texels, at least 2 per texel (three slots per band: 3x this
#: many paths per band), so a pilot of a few texels still sees every band's variance
PILOT_SAMPLES = 2 * PILOT_TEXELS


#: the format version of a plan's JSON object (:meth:`BandPlan.to_json`: report.json's ``viewing.plan``, a
#: checkpoint's ``band_plan``)
PLAN_FORMAT = 1


@dataclass(frozen=True)
class BandPlan:
    """How a band render samples a spectral table's bands (``spectral.render.SpectralRenderer``'s ``plan``).
    ``groups``: the bands of each path group (every band of the table in exactly one group, at most three per
    group, in any order); ``weights`` (G,) > 0: the groups' shares of a pass's samples
    (``spectral.render.group_spp``; None: every group the pass's spp); ``hero``: each group's paths carry its
    three bands (hero-channel paths) instead of one path per band and sample. ``measured``: what the pilot that
    made the plan measured (:meth:`to_json` records it; not part of the plan's identity, :meth:`key`)."""

    groups: tuple[tuple[int, ...], ...]
    weights: tuple[float, ...] | None = None
    hero: bool = False
    measured: dict | None = field(default=None, compare=False, hash=False)

    def __post_init__(self):
        groups = tuple(tuple(int(b) for b in g) for g in self.groups)
        object.__setattr__(self, "groups", groups)
        object.__setattr__(self, "hero", bool(self.hero))
        check_groups(groups, sum(len(g) for g in groups))
        if self.weights is None:
            return
        object.__setattr__(self, "weights", tuple(float(w) for w in self.weights))
        if len(self.weights) != len(groups) or not all(np.isfinite(w) and w > 0 for w in self.weights):
            raise ParameterError(f"`weights` must be {len(groups)} positive numbers, one per band group")

    @classmethod
    def in_order(cls, table: SpectralInkTable, weights=None, hero: bool = False) -> BandPlan:
        """The table's bands in wavelength order, three to a group (``table.group_bands()``)."""
        return cls(tuple(table.group_bands()), None if weights is None else tuple(weights), hero)

    @property
    def bands(self) -> int:
        return sum(len(g) for g in self.groups)

    def key(self) -> str:
        """A short digest of the plan's groups, weights and paths (what a checkpoint's key holds)."""
        h = hashlib.sha256(repr((self.groups, self.weights) + (("hero",) if self.hero else ())).encode())
        return h.hexdigest()[:12]

    def line(self, iteration_seconds: float | None = None) -> str:
        """One line on the plan: its groups' bands and weights, and its pilot's cost (over ``iteration_seconds``,
        one iteration's, when given)."""
        groups = " ".join(f"({','.join(map(str, g))})" for g in self.groups)
        weights = "equal" if self.weights is None else " ".join(f"{w:.2g}" for w in self.weights)
        out = f"band plan: groups {groups}, weights {weights}" + (", hero paths" if self.hero else "")
        m = self.measured or {}
        if "seconds" in m:
            per = "" if not iteration_seconds else f", {m['seconds'] / iteration_seconds:.2f} of an iteration"
            out += f"; its pilot {m['seconds']:.1f} s ({m['paths'] / 1e6:.2f} M paths{per})"
        return out

    def to_json(self) -> dict:
        """The plan as a JSON object (``format_version`` :data:`PLAN_FORMAT`); weights as Python floats, which
        JSON carries exactly, so :meth:`from_json` gives the same plan bit for bit."""
        d = {"format_version": PLAN_FORMAT, "groups": [list(g) for g in self.groups], "hero": self.hero}
        d["weights"] = None if self.weights is None else list(self.weights)
        return {**d, **({} if self.measured is None else {"measured": self.measured})}

    @classmethod
    def from_json(cls, d: dict) -> BandPlan:
        """The plan of a :meth:`to_json` object; a ParameterError naming `plan` for another format version or a
        malformed one."""
        if not isinstance(d, dict) or d.get("format_version") != PLAN_FORMAT:
            version = d.get("format_version") if isinstance(d, dict) else None
            raise ParameterError(f"`plan` has format version {version}; this inkopt reads {PLAN_FORMAT}")
        try:
            return cls(tuple(map(tuple, d["groups"])), d["weights"], d["hero"], d.get("measured"))
        except (KeyError, TypeError, ValueError) as exc:
            raise ParameterError(f"`plan` is malformed: {exc}") from None


@dataclass(frozen=True)
class Pilot:
    """What :func:`pilot` measured, per band (B,) float64: ``noise`` A_j, the texels' mean of the band's
    contribution to the squared CIELAB standard error (ΔE76^2) of one sample per band, summed over the lights;
    ``cost`` c_j, path events per path; ``texels``: how many texels it rendered; ``paths``, ``events``: how many
    paths and path events it traced; ``seconds``: its wall time (load-dependent; 0 when not given); ``hero``: the
    bands were traced by hero paths in wavelength-order groups (``cost``: each band's group's events per path)."""

    noise: np.ndarray
    cost: np.ndarray
    texels: int
    paths: int
    events: int = 0
    seconds: float = 0.0
    hero: bool = False

    def describe(self) -> dict:
        """JSON fields: per band ``noise`` and ``cost`` (lists), ``texels``, ``paths``, ``events``, ``seconds``."""
        d = {"noise": [float(x) for x in self.noise], "cost": [float(x) for x in self.cost]}
        return {**d, "texels": self.texels, "paths": self.paths, "events": self.events, "seconds": self.seconds}

    def effort(self, groups, weights=None) -> float:
        """The cost of the colour noise with these measures for ``groups`` of bands given samples in proportion to
        ``weights`` (G,): (sum_g A_g / w_g) (sum_g C_g w_g), A_g its bands' summed ``noise`` and C_g the path
        events of one of its samples (band paths: its three slots' ``cost``, a short group's last band repeated;
        hero paths: one path); without ``weights`` the Neyman allocation with costs, w_g = sqrt(A_g / C_g), where
        it is (sum_g sqrt(A_g C_g))^2, the least. At equal colour noise a render's path events are proportional
        to it (bands taken independent, as the noise is measured elsewhere; rounding to whole samples left out)."""
        a = np.array([np.sum(np.maximum(self.noise[list(g)], 0.0)) for g in groups])
        pad = [list(g) + [g[-1]] * (GROUP - len(g)) for g in groups]
        c = np.array([self.cost[g[0]] if self.hero else np.sum(self.cost[s]) for g, s in zip(groups, pad)])
        if weights is None:
            return float(np.sum(np.sqrt(a * c)) ** 2)
        w = np.asarray(weights, np.float64)
        return float(np.sum(a / w) * np.sum(c * w))


def pilot_texels(texels: Texels, most: int = PILOT_TEXELS) -> Texels:
    """At most ``most`` of ``texels``, evenly spaced over the list (all of them if there are no more)."""
    if len(texels) <= most:
        return texels
    return texels.subset(np.linspace(0, len(texels) - 1, most).round().astype(np.int64))


def pilot(
    volume: Volume,
    table: SpectralInkTable,
    texels: Texels,
    colours: Sequence[ColourMap],
    threads: int | None = None,
    lighting: Lighting | str | None = None,
    factory: RendererFactory | None = None,
    samples: int = PILOT_SAMPLES,
    hero: bool = False,
) -> Pilot:
    """Every band of ``table`` rendered alone (its three channels that band, ``samples`` per channel spread over
    the texels, at least 2 per texel) on :func:`pilot_texels` of ``texels`` at :data:`PILOT_SEED`, with one
    renderer (``factory``, default :class:`~inkopt.render.Renderer`) whose medium each band swaps in; ``colours``:
    the lights' colour maps on the table's bands (``Viewing.colours``). A_j uses each texel's CIELAB Jacobian at
    the pilot's band values. ``hero``: instead each group of ``table.group_bands()`` rendered with hero paths
    (one path carries the group's bands), each band's ``cost`` its group's path events per path (``Pilot.hero``)."""
    start = time.perf_counter()
    tex = pilot_texels(texels)
    spp = max(2, -(-int(samples) // len(tex)))
    light = check_grey(load_lighting(lighting))
    values = np.empty((len(tex), table.bands))
    var = np.empty_like(values)
    cost = np.empty(table.bands)
    paths, events, renderer = 0, 0, None
    slots = table.group_bands() if hero else [(j,) * GROUP for j in range(table.bands)]
    for k, bands in enumerate(slots):
        vol = with_inks(volume, band_table(table, bands))
        if renderer is None:
            renderer = (factory or Renderer)(vol, threads, light)
        else:
            renderer.set_volume(vol)
        res = renderer.render_pass(tex, PassSettings(spp, PILOT_SEED + k, hero=hero))
        b = list(bands[:1] if not hero else bands)
        # one path's variance: a channel's variance of its mean of spp paths, x spp (band paths: the three
        # channels' mean; hero paths: each band its channel)
        n = len(b)
        if hero:
            values[:, b], var[:, b] = res.rgb[:, :n], res.var_mean[:, :n] * np.float64(spp)
        else:
            values[:, b] = np.mean(res.rgb, axis=1, keepdims=True, dtype=np.float64)
            var[:, b] = np.mean(res.var_mean, axis=1, keepdims=True, dtype=np.float64) * spp
        cost[b] = res.events / max(res.paths, 1)
        paths, events = paths + res.paths, events + res.events
    del renderer
    w = sum(np.sum(c.lab_jacobian(values) ** 2, axis=-2) for c in colours)
    return Pilot(np.mean(w * var, axis=0), cost, len(tex), paths, events, time.perf_counter() - start, hero)


def plan(measured: Pilot) -> BandPlan:
    """The bands in order of their ideal sample density sqrt(A_j / c_j) (largest first), consecutive triples as
    groups, each group weighted sqrt(A_g / C_g) (its bands' summed noise over the cost of its three paths: a short
    last group's slots repeat its last band and are traced). Weights are floored at 1e-6 of the largest (a band
    that does not reach the colour still gets a sample: ``group_spp`` gives every group at least one)."""
    noise = np.maximum(np.asarray(measured.noise, np.float64), 0.0)
    cost = np.maximum(np.asarray(measured.cost, np.float64), 1e-9)
    order = np.argsort(-np.sqrt(noise / cost), kind="stable")
    groups = tuple(tuple(int(b) for b in order[k : k + GROUP]) for k in range(0, len(order), GROUP))
    slots = [list(g) + [g[-1]] * (GROUP - len(g)) for g in groups]
    w = np.array([np.sqrt(noise[list(g)].sum() / cost[s].sum()) for g, s in zip(groups, slots)])
    return BandPlan(groups, _normalised(w), measured={**measured.describe(), "effort": measured.effort(groups)})


def _normalised(w: np.ndarray) -> tuple[float, ...]:
    """Weights floored at 1e-6 of the largest (every group keeps a sample), the largest 1."""
    w = np.maximum(w, 1e-6 * max(w.max(), 1e-300))
    return tuple(w / w.max())


def hero_plan(measured: Pilot) -> BandPlan:
    """Hero paths in the groups a hero pilot traced (bands in wavelength order, three to a group), group g
    weighted sqrt(A_g / C_g) (its bands' summed noise over one path's events)."""
    bands = len(measured.noise)
    groups = tuple(tuple(range(k, min(k + GROUP, bands))) for k in range(0, bands, GROUP))
    w = np.array([np.sqrt(max(measured.noise[list(g)].sum(), 0.0) / max(measured.cost[g[0]], 1e-9)) for g in groups])
    measured_json = {**measured.describe(), "effort": measured.effort(groups)}
    return BandPlan(groups, _normalised(w), hero=True, measured=measured_json)


def choose(bands: Pilot, hero: Pilot | None = None) -> BandPlan:
    """:func:`plan` of the band paths' pilot, or :func:`hero_plan` of the hero paths' when its measured effort
    (``Pilot.effort``: path events at equal colour noise) is less. ``measured`` of the plan chosen records both
    efforts (``effort_bands``, ``effort_hero``) and both pilots' paths, events and seconds together."""
    p = plan(bands)
    if hero is None:
        return p
    h = hero_plan(hero)
    eb, eh = p.measured["effort"], h.measured["effort"]
    pick = h if eh < eb else p
    both = {k: bands.describe()[k] + hero.describe()[k] for k in ("paths", "events", "seconds")}
    measured = {**pick.measured, **both, "effort_bands": eb, "effort_hero": eh}
    return BandPlan(pick.groups, pick.weights, pick.hero, measured)
