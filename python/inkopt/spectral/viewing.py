"""Spectral or RGB: how a run's prediction becomes colour, chosen from its ink table and its lights.

A run with an RGB ink table and no light, or D65 (the white of linear sRGB, docs/conventions.md), takes the RGB path
unchanged: three channels, CIELAB of linear sRGB. A spectral ink table renders its bands
(:class:`~inkopt.spectral.render.SpectralRenderer`) and takes its colour under each light asked
(``spectral.lights``; D65 when none is); several lights combine by their mean or worst loss. An RGB table has no
spectrum, so any other light needs a spectral table.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, replace

import numpy as np

from ..color import RGB, RGB_TO_XYZ, WHITE_XYZ, ColourMap
from ..errors import ParameterError
from ..loss import COMBINE, TexelLoss
from ..model.spectral import SpectralInkTable
from ..render import RendererFactory, RenderResult
from .allocation import BandPlan, choose, pilot
from .lights import Light, named_light
from .render import SpectralRenderer

#: the light of the RGB path (linear sRGB's white)
RGB_LIGHT = "D65"


@dataclass(frozen=True)
class Viewing:
    """``table``: the spectral ink table (None: the RGB path); ``lights``: what the print is seen under (empty: D65);
    ``combine``: "mean" or "worst" of the loss under several lights. How the bands are sampled: ``plan``, measured
    on a volume (``spectral.allocation.BandPlan``, :meth:`planned`); without one, ``pilot``: an optimisation makes
    its plan from a pilot render of its start before its first step (``optim.Optimization``; the default), and
    until then (and for renders outside an optimisation) the bands go in wavelength order, a pass's samples shared
    among the groups by :meth:`group_weights` when ``weighted`` (False: equally), with hero paths when ``hero``
    (each group's paths carry its three bands: 0.64x the band paths' cost at equal noise on the reference slab
    but 8x on Spot 20 mm, docs/spectral.md "Cost")."""

    table: SpectralInkTable | None = None
    lights: tuple[Light, ...] = ()
    combine: str = "mean"
    weighted: bool = True
    hero: bool = False
    plan: BandPlan | None = None
    pilot: bool = True

    def __post_init__(self):
        object.__setattr__(self, "lights", tuple(self.lights))
        if self.combine not in COMBINE:
            raise ParameterError(f"`combine` must be one of {', '.join(COMBINE)}, got {self.combine!r}")
        if self.table is None and any(light.name != RGB_LIGHT for light in self.lights):
            names = ",".join(light.name for light in self.lights)
            raise ParameterError(
                f"`illuminants` {names}: a light other than {RGB_LIGHT} needs a spectral ink table "
                "(e.g. `inks` vero-cmykw@spectral)"
            )
        if len({light.name for light in self.lights}) != len(self.lights):
            raise ParameterError("`illuminants` names a light twice")
        if self.plan is not None and (self.table is None or self.plan.bands != self.table.bands):
            raise ParameterError("`plan` must be of the spectral ink table's bands")

    @property
    def spectral(self) -> bool:
        return self.table is not None

    def seen_under(self) -> tuple[Light, ...]:
        """The lights the colour is taken under: the ones asked, or D65."""
        return self.lights or (named_light(RGB_LIGHT),)

    def colours(self) -> tuple[ColourMap, ...]:
        """One colour map per light: linear sRGB on the RGB path, else the table's bands under each light."""
        if self.table is None:
            return (RGB,)
        return tuple(light.colour_map(self.table.wavelengths_nm) for light in self.seen_under())

    def loss(self, target_rgb, pos_vox, gamma, colour_term: str = "squared") -> TexelLoss:
        """The run's loss (``TexelLoss``) of targets (I, 3) linear RGB under :meth:`colours`, combined as asked, with
        the colour term ``colour_term`` (``loss.COLOUR_TERMS``)."""
        return TexelLoss(
            target_rgb, pos_vox, gamma, colours=self.colours(), combine=self.combine, colour_term=colour_term
        )

    def renderer_factory(self, inner: RendererFactory, shared: bool = False) -> RendererFactory:
        """What renders a run: ``inner`` on the RGB path, else band renders through ``inner`` per group (``shared``:
        one ``inner`` renderer for all groups, ``SpectralRenderer``'s ``shared``)."""
        table = self.table
        if table is None:
            return inner
        plan = self.sampling()
        return lambda volume, threads, lighting: SpectralRenderer(volume, table, threads, lighting, inner, plan, shared)

    def sampling(self) -> BandPlan:
        """How a render of this viewing samples the bands: its ``plan``, else the bands in wavelength order with
        :meth:`group_weights` and ``hero`` (a spectral viewing)."""
        if self.plan is not None:
            return self.plan
        w = self.group_weights()
        return BandPlan.in_order(self.table, None if w is None else tuple(w), self.hero)

    @property
    def needs_pilot(self) -> bool:
        """Whether an optimisation makes this viewing's plan from a pilot of its start (spectral, ``pilot``, no
        ``plan`` yet)."""
        return self.table is not None and self.pilot and self.plan is None

    def planned(self, volume, texels, threads: int | None = None, lighting=None, inner: RendererFactory | None = None):
        """This viewing with the ``plan`` measured by a pilot render of ``volume`` (a mixture or labels of the
        table's inks; e.g. a run's start) on ``texels`` under ``lighting`` (``spectral.allocation.pilot``, through
        ``inner``, default :class:`~inkopt.render.Renderer`; the same for any thread count): band paths by
        ``allocation.plan`` or hero paths by ``allocation.hero_plan``, whichever the pilots measure cheaper at
        equal colour noise (``allocation.choose``)."""
        if self.table is None:
            raise ParameterError("`plan` needs a spectral ink table")
        measured = pilot(volume, self.table, texels, self.colours(), threads, lighting, inner)
        hero = pilot(volume, self.table, texels, self.colours(), threads, lighting, inner, hero=True)
        return replace(self, plan=choose(measured, hero))

    def checkpoint_entries(self) -> dict:
        """A checkpoint's entries of this viewing: ``band_plan``, its plan's JSON object (:meth:`BandPlan.to_json`)
        as text, when it has a plan; else none."""
        return {} if self.plan is None else {"band_plan": np.array(json.dumps(self.plan.to_json()))}

    def resumed(self, entries) -> Viewing:
        """This viewing with the plan of a checkpoint's ``band_plan`` entry (``entries``: the checkpoint's arrays)
        when it makes its plan by a pilot and has none yet, so a resumed run samples the bands as it did, bit for
        bit; else itself."""
        if "band_plan" not in entries or not self.needs_pilot:
            return self
        return replace(self, plan=BandPlan.from_json(json.loads(str(entries["band_plan"]))))

    def group_weights(self) -> np.ndarray | None:
        """(G,) the band groups' sample weights (``spectral.render.group_spp``; None unless ``weighted``): the square
        root of each group's share of the CIELAB variance of a mid grey (reflectance 0.18 in every band) summed over
        the lights, every band's variance taken equal; with a ``plan``, its weights (its groups)."""
        if not self.weighted:
            return None
        if self.plan is not None:
            return None if self.plan.weights is None else np.array(self.plan.weights)
        grey = np.full(self.table.bands, 0.18)
        per_band = sum(np.sum(c.lab_jacobian(grey) ** 2, axis=0) for c in self.colours())
        return np.sqrt([per_band[list(b)].sum() for b in self.table.group_bands()])

    def key(self) -> str | None:
        """What identifies a spectral viewing in a checkpoint's key (None on the RGB path: its key is unchanged)."""
        if self.table is None:
            return None
        h = hashlib.sha256()
        t = self.table
        for arr in (t.wavelengths_nm, t.sigma_s, t.sigma_a, np.array([t.g])):
            h.update(np.ascontiguousarray(arr, np.float64).tobytes())
        for light in self.seen_under():
            h.update(light.name.encode())
            h.update(np.ascontiguousarray(light.on_grid()).tobytes())
        if self.plan is not None:
            return f"{self.combine}:{h.hexdigest()[:16]}:plan-{self.plan.key()}"
        return (
            f"{self.combine}:{h.hexdigest()[:16]}" + (":hero" if self.hero else "") + (":pilot" if self.pilot else "")
        )

    def display(self, values) -> np.ndarray:
        """Predictions ``values`` (I, C) as linear sRGB (I, 3) float64 for pictures: the RGB path's as they are;
        a spectral prediction's bands under the first light (:meth:`seen_under`) as CIE XYZ relative to that
        light's white, carried to sRGB's D65 white by the Bradford chromatic adaptation transform
        (:func:`adaptation_matrix`), then to linear sRGB (may leave [0, 1] for colours outside sRGB)."""
        values = np.asarray(values, np.float64)
        if self.table is None:
            return values
        return display_under(self.colours()[0], values)

    def light_matrices(self) -> dict[str, np.ndarray]:
        """{light name: (3, B) float64 band matrix of its colour map} for :meth:`seen_under` (a spectral viewing;
        ``rundir.BandValues.lights``)."""
        return {c.name: np.array(c.matrix) for c in self.colours()}

    def describe(self) -> dict:
        """Report fields: spectral or RGB, the bands, the lights and how they combine."""
        d = {"colour": "spectral" if self.spectral else "rgb", "illuminants": [x.name for x in self.seen_under()]}
        if self.table is not None:
            d.update(bands=self.table.bands, combine=self.combine, pictures=f"under {d['illuminants'][0]}, {CAT}")
            d.update({} if self.plan is None else {"plan": self.plan.to_json()})
        return d


def display_under(cmap: ColourMap, values) -> np.ndarray:
    """Band values ``values`` (I, B) under colour map ``cmap`` (a light's, ``Light.colour_map``) as linear sRGB
    (I, 3) float64: CIE XYZ relative to the light's white, carried to sRGB's D65 white by the Bradford chromatic
    adaptation transform (:func:`adaptation_matrix`); may leave [0, 1] for colours outside sRGB."""
    return cmap.xyz(values) @ (np.linalg.inv(RGB_TO_XYZ) @ adaptation_matrix(cmap.white)).T


def display_result(cmap: ColourMap, res: RenderResult) -> RenderResult:
    """A band render ``res`` (``rgb`` (I, B) band values, ``var_mean`` their variances) shown under colour map
    ``cmap`` as :func:`display_under` shows it: ``rgb`` (I, 3) float32 linear sRGB and ``var_mean`` (I, 3) float32,
    the band variances carried through the linear map (bands independent, as band paths trace them); counts and
    seconds as ``res``'s."""
    values = np.asarray(res.rgb, np.float64)
    shown = display_under(cmap, values)
    t = display_under(cmap, np.eye(values.shape[1]))  # (B, 3): each band's unit value as linear sRGB
    var = np.asarray(res.var_mean, np.float64) @ (t * t)
    return replace(res, rgb=shown.astype(np.float32), var_mean=var.astype(np.float32))


#: how a spectral run's pictures carry the first light's white to sRGB's (:meth:`Viewing.display`)
CAT = "Bradford chromatic adaptation to D65"


def adaptation_matrix(white_xyz) -> np.ndarray:
    """(3, 3): XYZ under a light of white ``white_xyz`` (3,) (Y = 1) -> the corresponding XYZ under linear sRGB's
    D65 white (``color.WHITE_XYZ``), the Bradford von Kries transform (colour-science)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from colour.adaptation import matrix_chromatic_adaptation_VonKries

    return np.asarray(matrix_chromatic_adaptation_VonKries(white_xyz, WHITE_XYZ, transform="Bradford"), np.float64)
