"""How long a mesh job's set-up and iterations take, from its counts and its size alone (``Footprint``'s time): an
iteration's passes cost CPU seconds in proportion to texels x events per path (a path's free-flight collisions,
real and null, and boundary events), and the events per path follow the object's thickness and whether a band
over a white core or every voxel is free.

- Events per path of a forward render from white, with r = 3 V / A (mm) the radius of the ball with the object's
  volume-to-area ratio: every voxel free, ``FREE_EVENTS_LIMIT`` - ``FREE_EVENTS_MM`` / r (light enters and leaves
  within about a millimetre of the surface, so they level off with size; Spot 10-60 mm within 0.2 events); a band
  over a pure-white core (albedo 0.999), ``BAND_EVENTS_REF`` + ``BAND_EVENTS_PER_LOG`` x ln(r / ``BAND_R_REF_MM``),
  at least the every-voxel-free figure: light that reaches the core walks on through it, the longer the thicker
  the core (Spot 20-60 mm with a 1 mm band within 0.5 events). Fitted to the 1 mm band: a deeper band or an
  absorbing core walks less (Spot with a 2 mm band: 80 and 117 events at 20 and 60 mm, against 102 and 182), a
  thinner one more; beyond the fitted sizes the logarithm is an extrapolation.
- An iteration on a quiet 2-core machine: ``CPU_SECONDS_PER_TEXEL_EVENT`` x texels x events of CPU over
  ``BUSY_CORES`` busy cores, plus ``STEP_SECONDS_PER_FREE`` per free voxel of the step.
- The set-up (voxelization, the scene and the optimiser's set-up): ``SETUP_CPU_SECONDS_PER_TEXEL`` per texel,
  about as many wall-clock seconds on a quiet machine (most of it runs on one thread).

The constants are fitted by ``python bench/bench_footprint.py walk`` (bench/results/footprint_spot.json, entry
``fit_walk``: the runs it reads and why, and the residuals); docs/performance.md, "Estimates before allocation".
"""

from __future__ import annotations

import math

#: every voxel free: events per path level off at this many (Spot 10, 20, 40, 60 mm: 62.1, 75.2, 82.0, 84.3)
FREE_EVENTS_LIMIT = 88.63
#: ... less this many mm over the object's thickness r (mm)
FREE_EVENTS_MM = 59.23
#: a band over a white core: events per path at r = ``BAND_R_REF_MM`` (Spot 20 mm; 102.3 measured) ...
BAND_EVENTS_REF = 102.12
BAND_R_REF_MM = 4.465
#: ... and their growth per unit of ln(r) (Spot 40 and 60 mm with a 1 mm band: 152.1 and 182.5 measured)
BAND_EVENTS_PER_LOG = 72.85
#: CPU seconds of an iteration's passes (4-spp gradient, 16-spp forward, the loss) per texel and event per path:
#: the geometric mean over the quiet runs of Spot 20 and 40 mm every voxel free and 60 mm with a 1 mm band (3.00,
#: 3.40 and 3.08 us)
CPU_SECONDS_PER_TEXEL_EVENT = 3.157e-6
#: CPU seconds per wall-clock second of an iteration with 2 threads on a quiet 2-core machine (those runs: 1.94,
#: 1.92, 1.93)
BUSY_CORES = 1.93
#: the step per free voxel (wall-clock seconds): 2.59 s over 15.68 M free voxels (bench/results/mesh_40mm.json)
STEP_SECONDS_PER_FREE = 1.65e-7
#: CPU seconds of the set-up per texel: Spot 20 mm every voxel free (9.1 s over 96 002 texels) and 60 mm with a
#: 1 mm band (81.5 s over 872 457), the scene's and the optimiser's set-up of bench/bench_mesh.py
SETUP_CPU_SECONDS_PER_TEXEL = 94.3e-6


def thickness_mm(volume_mm3: float, area_mm2: float) -> float:
    """r = 3 V / A (mm): the radius of the ball with the object's volume-to-area ratio."""
    return 3.0 * volume_mm3 / max(area_mm2, 1e-300)


def events_per_path(r_mm: float, band: bool) -> float:
    """Events per path of a forward render from white of an object r_mm thick (``thickness_mm``), every voxel free
    or (``band``) a band over a white core (module docstring); at least 1."""
    free = FREE_EVENTS_LIMIT - FREE_EVENTS_MM / max(r_mm, 1e-9)
    if band:
        walk = BAND_EVENTS_REF + BAND_EVENTS_PER_LOG * math.log(max(r_mm, 1e-9) / BAND_R_REF_MM)
        free = max(free, walk)
    return max(free, 1.0)


def iteration_cpu_seconds(texels: float, events: float) -> float:
    """CPU seconds of an iteration's passes over ``texels`` texels at ``events`` events per path."""
    return CPU_SECONDS_PER_TEXEL_EVENT * texels * events


def iteration_seconds(texels: float, events: float, free_voxels: float) -> float:
    """Wall-clock seconds of an iteration on a quiet 2-core machine: the passes' CPU over ``BUSY_CORES`` and the
    step over ``free_voxels``."""
    return iteration_cpu_seconds(texels, events) / BUSY_CORES + STEP_SECONDS_PER_FREE * free_voxels


def setup_seconds(texels: float) -> float:
    """Seconds of a mesh run's set-up (voxelization, scene, the optimiser's set-up) on a quiet machine."""
    return SETUP_CPU_SECONDS_PER_TEXEL * texels
