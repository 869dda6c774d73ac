"""What fits the memory a job may use (``MemoryLimit``): the one-line refusal of a job beyond it that names the
largest height, scale or slab size and DPI that fit (``check_spec_fits``), and the shell of a mesh run given none
(``choose_shell``): every voxel free when that fits, else a ``BAND_SHELL_MM`` band over a white core when that fits
(docs/quality.md, "The core below a band"), else a refusal naming the largest height that fits either way."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from ..errors import ParameterError
from ..model.volume import MAX_GRID_VOXELS
from ..units import voxel_mm
from . import Footprint, MemoryLimit, MeshShape, _count, mesh_band, mesh_footprint, slab_footprint, spec_footprint

#: the shell and core a mesh run given no shell takes when every voxel free does not fit the memory: a 1 mm band over
#: a white core was measured at least as good as every voxel free on Spot 20 mm, 150 DPI, 60 iterations (-0.26 +-
#: 0.02 dE76, docs/quality.md, "The core below a band"), and costs its band instead of the object's volume (Spot
#: 60 mm: 11.2 GiB every voxel free, 2.80 GiB through an iteration with the band: docs/performance.md)
BAND_SHELL_MM = 1.0
BAND_CORE = "white"


def _largest(fits, hi: float, steps: int = 40) -> float:
    """The largest x in (0, hi] with ``fits(x)`` (monotone: true below some x), by halving from ``hi`` until one
    fits and then bisection; 0 when none above hi / 2^steps fits."""
    lo = hi
    for _ in range(steps):
        if fits(lo):
            break
        lo /= 2.0
    else:
        return 0.0
    top = min(2.0 * lo, hi)
    for _ in range(steps if lo < hi else 0):
        mid = 0.5 * (lo + top)
        lo, top = (mid, top) if fits(mid) else (lo, mid)
    return lo


def largest_mesh_height(shape: MeshShape, dpi: float, shell_mm, n_inks: int, band: float, limit: float) -> float:
    """The largest height (mm) at which a mesh of ``shape`` fits ``limit`` bytes at ``dpi`` (0: none)."""

    def fits(height: float) -> bool:
        fp = mesh_footprint(shape.scaled(height / shape.height_mm), dpi, shell_mm, n_inks, band)
        return fp.fits(limit)

    return _largest(fits, shape.height_mm)


def largest_dpi(footprint_at, dpi: float, limit: float) -> float:
    """The largest DPI up to ``dpi`` at which ``footprint_at(dpi)`` fits ``limit`` bytes (0: none)."""
    return _largest(lambda d: footprint_at(d).fits(limit), dpi)


def check_fits(fp: Footprint, limit: MemoryLimit, what: str, larger: str, size: str, dpi: float) -> None:
    """One-line ParameterError when ``fp``'s peak exceeds ``limit``: it names ``what`` (the input), the peak, the
    limit, the largest ``size`` (text) of the parameter ``larger`` (e.g. height_mm) and the largest ``dpi`` that
    fit."""
    need = fp.peak_bytes()
    if fp.fits(limit.bytes):
        return
    nx, ny, nz = fp.grid
    raise ParameterError(
        f"{what}: the job needs ~{need / 2**30:.1f} GiB at its peak (grid {nx} x {ny} x {nz}, "
        f"{_count(fp.inside_voxels)} inside, {_count(fp.free_voxels)} free, {_count(fp.texels)} texels at "
        f"{fp.dpi:g} DPI), {_beyond(fp, limit)}; the largest "
        f"`{larger}` that fits is {size}, or `dpi` {math.floor(dpi)} at this size"
    )


def _beyond(fp: Footprint, limit: MemoryLimit) -> str:
    """In words, what the job ``fp``, which does not fit, exceeds: ``limit``, the renderer's 2^31 grid voxels or
    both."""
    memory = f"more than the {limit.bytes / 2**30:.1f} GiB it may use {limit.source}"
    grid = f"its grid of {_count(fp.grid_voxels)} voxels more than the renderer's 2^31"
    if fp.peak_bytes() <= limit.bytes:
        return f"within memory, but {grid}"
    return f"{memory} and {grid}" if fp.grid_voxels > MAX_GRID_VOXELS else memory


def _down(x: float) -> str:
    """``x`` rounded down to 3 significant digits (a size that still fits)."""
    if x <= 0:
        return "none"
    digits = max(0, 2 - math.floor(math.log10(x)))
    return f"{math.floor(x * 10**digits) / 10**digits:.{digits}f}"


def check_spec_fits(spec, fp: Footprint, shape: MeshShape | None, limit: MemoryLimit) -> None:
    """One-line ParameterError (``check_fits``) when the job of ``spec`` (its ``fp`` and, for a mesh, ``shape`` from
    ``spec_footprint``) needs more than ``limit``, naming the largest size (``height_mm``, ``scale`` or
    ``size_mm``) and DPI that fit."""
    if fp.fits(limit.bytes):
        return
    n = fp.n_inks
    if spec.kind == "slab":
        w, h, d = spec.size_mm
        faces = 1 if spec.bottom is None else 2
        f = _largest(lambda k: slab_footprint((k * w, k * h, d), spec.dpi, faces, n).fits(limit.bytes), 1.0)
        dpi = largest_dpi(lambda x: slab_footprint(spec.size_mm, x, faces, n), spec.dpi, limit.bytes)
        check_fits(fp, limit, spec.top, "size_mm", f"{_down(f * w)}x{_down(f * h)}x{d:g}", dpi)
        return
    larger, size, dpi = _largest_mesh(spec, fp, shape, limit, spec.shell_mm)
    check_fits(fp, limit, spec.path, larger, size, dpi)


def _largest_mesh(spec, fp: Footprint, shape: MeshShape, limit: MemoryLimit, shell_mm) -> tuple[str, str, float]:
    """(the parameter that sizes the mesh of ``spec``: ``height_mm`` or ``scale``, its largest value that fits
    ``limit`` as text, the largest DPI that fits at the spec's size) with a shell of ``shell_mm`` (None: every voxel
    free) and ``fp``'s band."""
    n, band = fp.n_inks, fp.band
    height = largest_mesh_height(shape, spec.dpi, shell_mm, n, band, limit.bytes)
    larger, size = "height_mm", _down(height)
    if spec.height_mm is None:  # placed by scale: the scale that gives that height
        larger, size = "scale", _down(spec.scale * height / shape.height_mm)
    dpi = largest_dpi(lambda x: mesh_footprint(shape, x, shell_mm, n, band), spec.dpi, limit.bytes)
    return larger, size, dpi


@dataclass(frozen=True)
class ShellChoice:
    """The job a spec runs as (``choose_shell``): ``spec`` (``scenes.spec.MeshSpec`` with the band when one was
    chosen, its ``shell_chosen`` saying why; or the spec as given), its ``footprint`` and ``shape`` (a mesh's
    ``MeshShape``, None for a slab); ``note``: one line, why the band was chosen, both peaks and how to choose
    otherwise, parameter names in backticks (``errors.ParameterError``'s convention; None: the spec as given)."""

    spec: object
    footprint: Footprint
    shape: MeshShape | None
    note: str | None = None


def choose_shell(spec, n_inks: int, limit: MemoryLimit, automatic: bool = True, mesh=None) -> ShellChoice:
    """The job the scene ``spec`` (checked) runs as with ``n_inks`` inks within ``limit``. As given when it fits,
    names a shell, is not a mesh, is translucent, or ``automatic`` is False (every voxel free by choice), else
    refused as ``check_spec_fits`` refuses; a mesh without a shell whose every-voxel-free peak exceeds ``limit``
    but whose ``BAND_SHELL_MM`` band over a ``BAND_CORE`` core fits takes that band; one that fits neither is
    refused in one line naming the largest height (or scale) and DPI that fit with every voxel free and with the
    band. Loads a mesh (``mesh``: one already loaded), never voxelizes it."""
    fp, shape = spec_footprint(spec, n_inks, mesh)
    eligible = automatic and spec.kind == "mesh" and spec.shell_mm is None and spec.translucency is None
    if not eligible or fp.fits(limit.bytes):
        check_spec_fits(spec, fp, shape, limit)
        return ShellChoice(spec, fp, shape)
    band = mesh_footprint(shape, spec.dpi, BAND_SHELL_MM, n_inks, mesh_band(voxel_mm(spec.dpi), BAND_SHELL_MM))
    free_gib, band_gib, room = fp.peak_bytes() / 2**30, band.peak_bytes() / 2**30, limit.bytes / 2**30
    if not band.fits(limit.bytes):
        _refuse_both(spec, fp, band, shape, limit)
    why = (
        f"every voxel free needs ~{free_gib:.1f} GiB at its peak, more than the {room:.1f} GiB it may use "
        f"{limit.source}; a {BAND_SHELL_MM:g} mm band over a {BAND_CORE} core needs ~{band_gib:.1f} GiB"
    )
    note = (
        f"memory: {why}: optimising that band (`shell_mm` {BAND_SHELL_MM:g}, `core` {BAND_CORE}; "
        f"docs/quality.md, 'The core below a band'); `shell_mm` 0 forces every voxel free, `shell_mm` D sets the band"
    )
    chosen = replace(spec, shell_mm=BAND_SHELL_MM, core=BAND_CORE, shell_chosen=f"automatic: {why}")
    return ShellChoice(chosen, band, shape, note)


def _refuse_both(spec, fp: Footprint, band: Footprint, shape: MeshShape, limit: MemoryLimit) -> None:
    """The one-line ParameterError of a mesh that fits ``limit`` neither with every voxel free (``fp``) nor with
    the band (``band``): both peaks, and the largest size and DPI that fit each way."""
    larger, size, dpi = _largest_mesh(spec, fp, shape, limit, None)
    _, band_size, band_dpi = _largest_mesh(spec, band, shape, limit, BAND_SHELL_MM)
    nx, ny, nz = fp.grid
    raise ParameterError(
        f"{spec.path}: the job needs ~{fp.peak_bytes() / 2**30:.1f} GiB at its peak with every voxel free and "
        f"~{band.peak_bytes() / 2**30:.1f} GiB with a {BAND_SHELL_MM:g} mm band over a {BAND_CORE} core (grid "
        f"{nx} x {ny} x {nz}, {_count(fp.inside_voxels)} inside, {_count(band.free_voxels)} in the band, "
        f"{_count(fp.texels)} texels at {fp.dpi:g} DPI), {_beyond(band, limit)}; the largest `{larger}` that fits "
        f"is {size} with every voxel free, {band_size} with "
        f"`shell_mm` {BAND_SHELL_MM:g}, or `dpi` {math.floor(dpi)} (every voxel free) or {math.floor(band_dpi)} "
        f"(`shell_mm` {BAND_SHELL_MM:g}) at this size"
    )
