"""The colour -> mixture table of a spectral ink table under lights: the print shop of the baselines with a spectral
model (``evaluation.spectral``).

The patches are ``colour_table``'s (the mixtures of ``table_mixtures``; infinite homogeneous layers ``patch_mm``
thick, ``boundary = "periodic-xy"``, seen from the top under the uniform white environment), rendered band by band
(``spectral.render.SpectralRenderer``, a pass's samples shared among the band groups by ``Viewing.group_weights``
under the named lights, as a run shares them: 4.5x faster than equal samples per group at the same error target)
until the CIELAB standard error of each patch's colour is below ``max_stderr`` under every named light
(``spectral.lights.NAMED``; a 16-sample pilot, then one pass sized by its error). A group given one sample (the
spectrum's ends, whose weight in any colour is a few thousandths) has no variance estimate: its variance counts as
0. What is kept does not depend on a light (:class:`SpectralPatches`: each patch's mean
band values and their variances), so one build serves every light: it is cached on disk beside the RGB tables
(``colour_table.cache_dir``), keyed by a hash of the spectral table, g, ior, patch thickness, lattice step, error
target and the inkopt version, and the default spectral ink set's ships with the package (:data:`PACKAGED`).

:meth:`SpectralPatches.under` gives the :class:`SpectralColourTable` of some lights: each patch's CIELAB under each
light (relative to the light's white). Its look-up blends the k = 8 entries nearest the target in the lights'
stacked CIELAB with the weights that minimise the sum over the lights of the squared ΔE76 between the blend's
colour and the target's CIELAB (the texture's, sRGB D65 white: what every light is scored against), the mean of the
lights as a run's ``--illuminants`` loss takes it. ``lab``, ``rgb`` and ``stderr`` are the first light's (the
colour shown in pictures; ``baselines.white_mixture``), ``stderr`` the largest over the lights.

Conventions (docs/conventions.md): mixtures (M, N); band values (M, B) reflectance; CIELAB via ``inkopt.color``.
"""

from __future__ import annotations

import hashlib
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..color import ColourMap
from ..errors import ParameterError
from ..io import save_npz
from ..model import Texels, Volume
from ..model.spectral import SpectralInkTable
from ..spectral.inks import rgb_stand_in
from ..spectral.lights import NAMED, named_light
from ..spectral.render import SpectralRenderer
from ..spectral.viewing import Viewing, display_under
from .colour_table import (
    DEFAULT_MAX_STDERR,
    DEFAULT_PATCH_MM,
    MAX_PATCH_SPP,
    PATCH_LATERAL,
    PATCH_LATERAL_MM,
    PATCH_PILOT_SPP,
    REFINE_K,
    ColourTable,
    cache_dir,
    check_patch_settings,
    default_step,
    table_mixtures,
)

#: spectral tables shipped with the package (the default spectral ink set's), read like the cache
PACKAGED = Path(__file__).resolve().parents[1] / "data" / "spectral_colour_tables"
SPECTRAL_TABLE_VERSION = 1


@dataclass
class SpectralPatches:
    """The rendered patches of a spectral table: ``mixtures`` (M, N) float32, ``bands`` (M, B) float64 mean band
    values of each patch's top face, ``bands_var`` (M, B) float64 the variance of each mean, ``wavelengths_nm``
    (B,); ``patch_mm``, ``step``, ``key``, ``seconds`` (build time; when read from the cache or the package, of the
    build that wrote it: ``cached``)."""

    ink_names: tuple
    mixtures: np.ndarray
    bands: np.ndarray
    bands_var: np.ndarray
    wavelengths_nm: np.ndarray
    patch_mm: float
    step: int
    key: str
    seconds: float = 0.0
    cached: bool = False

    def under(self, cmaps: tuple[ColourMap, ...]) -> SpectralColourTable:
        """The colour table of these patches under the lights' colour maps ``cmaps`` (``Light.colour_map`` on this
        band grid; at least one): CIELAB (L, M, 3) per light, the first light's as ``lab`` and linear sRGB."""
        if not cmaps:
            raise ParameterError("`illuminants`: a spectral colour table needs at least one light")
        labs = np.stack([c.lab(self.bands) for c in cmaps])
        stderr = np.max([c.lab_stderr(self.bands, self.bands_var) for c in cmaps], axis=0)
        rgb = display_under(cmaps[0], self.bands)
        names = tuple(c.name for c in cmaps)
        return SpectralColourTable(
            self.ink_names, self.mixtures, rgb, labs[0], stderr, self.patch_mm, self.step, self.key, self.seconds,
            self.cached, labs=labs, light_names=names,
        )  # fmt: skip

    def to_arrays(self) -> dict:
        return {
            "ink_names": np.array(self.ink_names),
            "mixtures": self.mixtures,
            "bands": self.bands,
            "bands_var": self.bands_var,
            "wavelengths_nm": self.wavelengths_nm,
            "patch_mm": np.float64(self.patch_mm),
            "step": np.int64(self.step),
            "key": np.array(self.key),
            "seconds": np.float64(self.seconds),
        }


@dataclass
class SpectralColourTable(ColourTable):
    """A :class:`~inkopt.evaluation.colour_table.ColourTable` under lights (module docstring): ``labs`` (L, M, 3)
    float64 each patch's CIELAB under each light of ``light_names``; the look-up searches and blends in the lights'
    stacked CIELAB (M, 3L)."""

    labs: np.ndarray = field(default=None, repr=False)
    light_names: tuple = ()

    def points(self) -> np.ndarray:
        return np.concatenate(list(self.labs), axis=1)

    def target_points(self, lab_t: np.ndarray) -> np.ndarray:
        return np.tile(lab_t, (1, len(self.labs)))

    def reachable_lab(self, target_rgb, k: int = REFINE_K, iterations: int = 300) -> np.ndarray:
        """(I, 3): ``ColourTable.reachable_lab`` under the first light (as ``lab``); :meth:`under_light` for another."""
        return self.under_light(0).reachable_lab(target_rgb, k, iterations)

    def under_light(self, k: int) -> ColourTable:
        """The table under light ``k`` alone (its look-up and reachable colours in that light's CIELAB)."""
        return ColourTable(
            self.ink_names, self.mixtures, self.rgb, self.labs[k], self.stderr, self.patch_mm, self.step, self.key,
            self.seconds, self.cached,
        )  # fmt: skip


def spectral_table_key(table: SpectralInkTable, g: float, ior: float, patch_mm: float, step: int, max_stderr: float):
    """Hex digest identifying a spectral table's patches (changes with anything that changes their band values)."""
    from .. import __version__

    h = hashlib.sha256()
    ident = (SPECTRAL_TABLE_VERSION, __version__, tuple(table.names), round(float(g), 9), round(float(ior), 9))
    h.update(repr(ident + (round(float(patch_mm), 9), int(step), round(float(max_stderr), 9))).encode())
    for arr in (table.wavelengths_nm, table.sigma_s, table.sigma_a):
        h.update(np.ascontiguousarray(arr, np.float64).tobytes())
    return h.hexdigest()[:20]


def _read_patches(path: Path, table: SpectralInkTable, key: str) -> SpectralPatches | None:
    """The patches stored at ``path`` if readable and made for ``table`` with ``key``, else None."""
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as d:
            if tuple(str(n) for n in d["ink_names"]) != tuple(table.names) or str(d["key"]) != key:
                return None
            arrays = [d[k] for k in ("mixtures", "bands", "bands_var", "wavelengths_nm")]
            patch_mm, step, seconds = float(d["patch_mm"]), int(d["step"]), float(d["seconds"])
        return SpectralPatches(tuple(table.names), *arrays, patch_mm, step, key, seconds, cached=True)
    except (OSError, ValueError, KeyError):
        return None


def spectral_patches(
    table: SpectralInkTable,
    g: float | None = None,
    ior: float = 1.5,
    patch_mm: float = DEFAULT_PATCH_MM,
    step: int | None = None,
    max_stderr: float = DEFAULT_MAX_STDERR,
    cache: bool = True,
    threads=None,
    progress: bool = False,
) -> SpectralPatches:
    """The rendered patches of spectral ink table ``table`` (module docstring); read from the cache or the package
    when present, else built (and cached). ``g`` defaults to the table's."""
    g = table.g if g is None else float(g)
    step = default_step(len(table.names)) if step is None else int(step)
    check_patch_settings(patch_mm, max_stderr)
    key = spectral_table_key(table, g, ior, patch_mm, step, max_stderr)
    path = cache_dir() / f"spectral_colour_table_{key}.npz"
    for where in (path, PACKAGED / path.name) if cache else ():
        found = _read_patches(where, table, key)
        if found is not None:
            return found
    t0 = time.perf_counter()
    mixtures = table_mixtures(len(table.names), step)
    optics = (g, ior)
    bands, var = render_band_patches(mixtures, table, optics, patch_mm, max_stderr, threads=threads, progress=progress)
    wl = np.asarray(table.wavelengths_nm, np.float64)
    built = time.perf_counter() - t0
    patches = SpectralPatches(tuple(table.names), mixtures, bands, var, wl, float(patch_mm), step, key, built)
    if cache:
        try:
            save_npz(path, patches.to_arrays())
        except OSError as exc:
            print(f"inkopt: note: cannot cache the spectral colour table in {path.parent} ({exc})", file=sys.stderr)
    return patches


def render_band_patches(
    mixtures, table: SpectralInkTable, optics: tuple, patch_mm: float, max_stderr: float, seed: int = 0, **kw
) -> tuple[np.ndarray, np.ndarray]:
    """Band values (M, B) float64 of infinite homogeneous patches of ``mixtures`` (M, N) with their variances
    (M, B), ``optics`` = (g, ior): each a 16-sample pilot (seed 2 j + 1 000 003 ``seed``) and, when its CIELAB
    standard error under a named light exceeds ``max_stderr``, a second pass (the next seed) sized by it (x1.2
    margin, at most ``MAX_PATCH_SPP``), pooled. ``kw``: ``threads``, ``progress``."""
    mixtures = np.asarray(mixtures, np.float32)
    g, ior = optics
    inks = rgb_stand_in(table)  # the patch volume's RGB table gives only the ink names
    lights = tuple(named_light(n) for n in NAMED)
    cmaps = [light.colour_map(table.wavelengths_nm) for light in lights]
    plan = Viewing(table, lights, pilot=False).sampling()  # samples shared among the groups by the mid grey's weights
    bands = np.zeros((len(mixtures), table.bands))
    var = np.zeros_like(bands)
    bar = _progress_bar(len(mixtures)) if kw.get("progress") else None
    texels = None
    for j, row in enumerate(mixtures):  # a loop over table entries (hundreds), not voxels
        m = np.broadcast_to(row, (1, PATCH_LATERAL, PATCH_LATERAL, len(row))).copy()
        vmm = [PATCH_LATERAL_MM, PATCH_LATERAL_MM, patch_mm]
        vol = Volume.from_mixture(vmm, m, inks, g=g, ior=ior, boundary="periodic-xy")
        texels = texels or Texels.for_volume(vol, ["top"])
        rnd = SpectralRenderer(vol, table, kw.get("threads"), plan=plan, shared=True)
        bands[j], var[j] = _patch_bands(rnd, texels, 2 * j + seed * 1_000_003, max_stderr, cmaps)
        if bar is not None:
            bar.update()
    if bar is not None:
        bar.close()
    return bands, var


def _patch_bands(rnd: SpectralRenderer, texels: Texels, seed: int, max_stderr: float, cmaps) -> tuple:
    """One patch's mean band values (B,) and their variances (B,): the pilot with ``seed`` and, when its largest
    CIELAB standard error under ``cmaps`` exceeds ``max_stderr``, a second pass with ``seed + 1``, pooled."""

    def error(mean, var):
        return max(float(c.lab_stderr(mean, var)) for c in cmaps)

    n = len(texels)
    r0 = rnd.render(texels, PATCH_PILOT_SPP, seed=seed)
    m, v = r0.rgb.astype(np.float64), r0.var_mean.astype(np.float64)
    se = error(m.mean(0), v.sum(0) / n**2)
    if se > max_stderr:
        spp1 = int(min(MAX_PATCH_SPP, np.ceil(PATCH_PILOT_SPP * ((se / max_stderr) ** 2 * 1.2 - 1.0))))
        r1 = rnd.render(texels, max(spp1, 1), seed=seed + 1)
        n0, n1 = PATCH_PILOT_SPP, r1.spp
        m = (n0 * m + n1 * r1.rgb) / (n0 + n1)
        v = (n0 * n0 * v + n1 * n1 * r1.var_mean) / (n0 + n1) ** 2
    return m.mean(0), v.sum(0) / n**2


def _progress_bar(total: int):
    """A progress bar on a terminal, else None."""
    if not sys.stderr.isatty():
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc="spectral colour table", unit="patch", leave=False)
