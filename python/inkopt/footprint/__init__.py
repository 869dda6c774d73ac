"""What a job needs before anything large is built: its grid's counts from the loaded mesh alone (no voxelization) or
from a slab's size, the peak memory, seconds per iteration and disk those counts need (``Footprint``), the memory the
machine can give (``memory_limit``); ``footprint.fits``: the one-line refusal of a job beyond it that names the
largest height (or DPI) that fits (``check_spec_fits``) and the shell of a mesh run given none (``choose_shell``).

Counts of a mesh at voxel size h (mm) from its area A, volume V (trimesh), bounding box and face normals:

- grid voxels: ceil(box / h) + 2 a side (voxelization pads one empty voxel each side): exact;
- inside voxels: V / h^3;
- texels (inside voxels with an outside face neighbour): the sum over faces of area x max(|n_x|, |n_y|, |n_z|) / h^2
  (a digital plane of normal n has one such voxel per h^2 / max|n_i| of its area), times (1 - h / 2r)^2: their
  centres lie about half a voxel deep, where a ball with the object's volume-to-area ratio (radius r = 3 V / A)
  has that share of its area;
- free voxels: every inside voxel, or with ``shell_mm`` d those within d of the surface, estimated as the shell of
  that ball: V (1 - (1 - d / r)^3) / h^3, which is A d to first order and less where the surface curves inwards;
  at least the texels, at most the inside voxels.

On Spot at 6-60 mm these land within 0.1 % (grid, inside), 1.5 % (texels) and 1 % (free with a 0.5-2 mm shell)
of the voxelized counts (tests/test_footprint.py; docs/performance.md, "Estimates before allocation").

Memory: the largest of three stages' peaks (voxelization, a step, the figures), each ``BASE_BYTES`` and the mesh
plus bytes per grid voxel, inside voxel, free voxel and texel (a band run's stages: their own per-free and per-texel
terms; the constants below say where each comes from).
Time (``footprint.walk``): an iteration's passes cost in proportion to texels x events per path, the events per
path following the object's thickness and whether a band over a white core or every voxel is free, plus the step's
cost per free voxel; the set-up in proportion to the texels; all measured on Spot on 2 cores. The machine's speed
on the day and an optimised start's longer paths are not in it.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace

import numpy as np

from ..errors import ParameterError
from ..estimate import quantized_bytes
from ..model.volume import MAX_GRID_VOXELS
from ..units import format_duration, voxel_mm
from . import walk

#: the interpreter, numpy, the extension and the ink tables before a scene is built: the 'start' peak of
#: bench/results/mesh_*mm.json is 0.066-0.070 GiB
BASE_BYTES = 0.07 * 2**30
#: voxelization and the scene's masks (the mesh's stage before the run): per grid voxel the inside and free masks'
#: bits (1/8 B each; the bytes they are filled in, a slab or a chunk at a time, are resident only where pages were
#: written, the object's own, so they are counted in the per-texel term); per texel its closest points, faces,
#: normals, colours and exposed faces, and the exact depths of the inside voxels within the band below it
#: (``voxelize.NearDepth``, 12 B per near voxel and their chunks while they are joined, ``VOXELIZE_NEAR_BYTES`` per
#: texel and voxel of the band: Spot 20 mm has 0.89 near voxels per texel and band voxel at a 1 mm shell, band 14)
#: with the near-surface queries' chunks: 900 B per texel at band 14, between the 929 B that fits Spot 40 mm's
#: scene stage (0.419 GiB) and the 864 B that fits 60 mm's (0.820 GiB) less the base and 0.25 B per grid voxel
#: (python bench/bench_footprint.py run H --stages --tag _s69 -- --shell-mm 1 ..., bench/results/
#: footprint_spot.json, fit_shell_s69; Spot 100 mm's 2.37 GiB, mesh_100mm_shell1_mem69.json after_voxelize, is
#: estimated 2.33); nothing fixed. 2.125 B per grid voxel and 626 B per texel fitted the code that held the dense
#: masks whole (bench/results/stages_spot.json, 40mm_shell1_new_s58 and 60mm_shell1_new_s58)
VOXELIZE_GRID_BYTES = 0.25
VOXELIZE_FIXED_BYTES = 0.0
VOXELIZE_NEAR_BYTES = 24 * 0.9
VOXELIZE_TEXEL_BYTES = 900.0 - VOXELIZE_NEAR_BYTES * 14
DEFAULT_BAND = 3
#: the run holds, by what the code stores (docs/performance.md, "Memory, by what the code stores"), per grid voxel
#: the inside and free masks' bits (``model.mask.PackedMask``, 1/8 B each; the inside mask held 1 B before) and the
#: core's table entry of its signed distances stored by 8^3 bricks (4 B per brick: 1/128 B), and per texel the
#: bricks the core stores with their bytes (those within the distances' cap of 16 voxels of the surface, 512 B each;
#: the others, of one value, are their table entry only):
#: 59.5 B per texel at Spot 100 mm (282 307 of 1 854 884 bricks for 2 428 105 texels), 58.8 at 60 mm (100 205 of
#: 404 950 for 872 457), 52.1 at 20 mm (9 773 of 15 810 for 96 002; bench/results/mesh_100mm_shell1_bricks.json,
#: mesh_60mm_shell1_bricks.json, bricks_ab_20mm.json, distance_storage: 0.16, 0.26 and 0.65 B per grid voxel where
#: the core held 1 B); and per inside voxel the core's sparse sigma_t and albedo; then it peaks in one of two stages:
RUN_GRID_BYTES = 1.0 / 8 + 1.0 / 8 + 4.0 / 512
RUN_TEXEL_BYTES = 59.5
RUN_INSIDE_BYTES = 24.0
#: - a step: per free voxel the variables, momentum and index held through the run (48 B) and, at the step's peak,
#:   the smoothing's working arrays or the core's fixed-point gradient sums (48 B; taking the gradient converts them
#:   a block at a time and gives each block's memory back, so the float gradients are never beside all of them):
#:   108 B, fitted to Spot 40 mm all free, whose step peaked at 2.182 GiB in the smoothing, 54.6 B per free voxel
#:   above the step's start (bench/results/step_memory_spot.json, entry 40mm_after_gsum; 2.446 GiB in taking the
#:   gradient, 72.0 B, with the sums and the float gradients side by side, entry 40mm_before_gsum, where 130 B
#:   stood, fitted to Spot 20 mm, entry 20mm_after_mmap128k); per texel the passes' arrays (rgb, variances,
#:   adjoint, running average, target, normal: ~128 B);
STEP_FREE_BYTES = 108.0
STEP_TEXEL_BYTES = 128.0
#: - the figures (the start's, the baseline's, the result's): per free voxel the variables and momentum (40 B) and
#:   per texel the loss's SSIM window (~120 entries of 5 B, its square sharing them) and Sobel operators (~17 entries
#:   of 12 B), the metrics' temporaries, the figures' renders and what the allocator keeps of them: the 6.6 KB
#:   fitted to the peak of a whole run of Spot 20 mm (bench/results/footprint_spot.json, run_20mm, 0.82 GiB) less
#:   the 1.8 KB the loss's side no longer takes since its window is coded (4.0 -> 2.2 KB per texel:
#:   bench/results/stages_spot.json, 20mm_shell1_main and _new) and the 0.53 KB since its Sobel operators are built
#:   an axis at a time (Spot 60 mm with a 1 mm shell, the figures' loss side 3.022 -> 2.589 GiB over 872 457 texels:
#:   bench/results/mesh_60mm_shell1_gsum_nosobel.json and mesh_60mm_shell1_gsum.json)
FIGURES_FREE_BYTES = 40.0
FIGURES_TEXEL_BYTES = 4270.0
#: a run with a shell stores the core's medium only for its band (the free voxels: ``BandMedium``), so its held
#: per-inside term counts the free voxels. Its two stages are fitted to whole band runs of Spot (1 mm shell, one
#: iteration at 1 spp), each stage's own peak measured by bench/run_stages.py (bench/results/footprint_spot.json,
#: entries run_<H>mm_shell1_*; bench/results/mesh_60mm_shell1_whole_run.json; docs/performance.md, "The whole run's
#: peak stage by stage"); the band's free voxels grow with the area as the texels do, so the two are not told
#: apart and the per-free terms are what the code holds:
#: - a step: per texel the all-free step's 128 B and per free voxel 136 B (x and momentum, 40 B; the free index,
#:   which is the band's own, 8 B; the smoothed set's row numbers and guide keys and depths, 12 B; at the peak
#:   dE/dx, 20 B, and the smoothing's neighbours, weights and two copies of a column, 37 B, or the core's gradient
#:   sums, 48 B; and what the allocator keeps), fitted to Spot 100 mm through an iteration, 5.42 GiB (python
#:   bench/bench_mesh.py 100 --shell-mm 1 --iterations 1 --figure-metrics --renderer, bench/results/
#:   mesh_100mm_shell1_mem69.json; 146 B fitted the 5.70 GiB of mesh_100mm_shell1_mem68.json, whose smoothed set
#:   held 24 B a voxel, and 152 B the 6.66 GiB of mesh_100mm_shell1_mem.json with the inside mask's byte); Spot 40 mm's
#:   step measured 1.094 GiB, 0.99 estimated (python bench/bench_step_memory.py 40 --shell-mm 1 --iterations 1,
#:   bench/results/step_memory_spot.json, 40mm_shell1_mem_after). 195 B where the smoothing gathered its column and
#:   the set's indices and kept six neighbours and six weights per voxel, and the band kept its own index;
SHELL_STEP_FREE_BYTES = 136.0
SHELL_STEP_TEXEL_BYTES = STEP_TEXEL_BYTES
#: - the figures (the start's with the renderer held for the baseline guard, the guard's, the result's, and the
#:   renderer's builds): per free voxel the variables, momentum and index (48 B) and the renderer's band medium
#:   (34 B: 0.437 GiB held at 60 mm less the band's own copy of the index, 8 B, now the free index; Spot 100 mm's
#:   renderer build 6.14 -> 5.90 GiB, bench/results/mesh_100mm_shell1_bricks.json and mesh_100mm_shell1_mem.json,
#:   after_renderer), per texel what the renderer's build and the figures take beyond what the set-up
#:   holds: the loss's operators are found a block of rows at a time, not held (``neighbourhood.TexelNeighbours``),
#:   so the stage's peak is the renderer's build; 1.0 KB, between the 0.96 KB that fits 60 mm (2.049 GiB) and the
#:   1.18 KB that fits 40 mm (1.011 GiB) in whole runs of the code with the inside mask as bits, the distances
#:   built by slabs and the smoothed set's 12 B (python bench/bench_footprint.py run H --dir D --stages --tag _s69
#:   -- --shell-mm 1 --iterations 1 --spp 1 --forward-spp 1 --eval-spp 1, bench/results/footprint_spot.json,
#:   entries run_60mm_shell1_s69 and run_40mm_shell1_s69, fitted in fit_shell_s69; 1.23 KB fitted the runs of the
#:   dense distance build, 1.85 KB while the figures built and held the operators): 2.08 GiB at 60 mm, 0.94 at
#:   40 mm; the term per texel falls with the size (the renderer's build at 100 mm, bench/results/
#:   mesh_100mm_shell1_mem69.json, 4.77 GiB, would fit ~0.5 KB), so at 100 mm it is an upper bound (5.7 GiB);
#:   no fixed term (the figures' libraries and arenas, ~0.2 GiB, which the all-free terms do not count either, so
#:   that a band never estimates above every voxel free). The all-free ``FIGURES_TEXEL_BYTES`` is not refitted
#:   (no all-free run of that code measured): it over-estimates by up to the ~1.1 KB per texel the figures' loss side
#:   no longer takes (1536 -> 373 B per texel at 60 mm: bench/results/figure_side_spot.json)
SHELL_FIGURES_FREE_BYTES = 82.0
SHELL_FIGURES_TEXEL_BYTES = 1000.0
#: a slab's passes per texel: 254 s for 300 iterations of the reference slab's 41 772 texels
#: (experiments/results/printable.json, entry reference, report.seconds_iterations)
SLAB_SECONDS_PER_TEXEL = 254.0 / 300 / 41772
#: a slab's bytes per voxel: its (z, y, x, N) mixture (4 N), the dense sigma_s and sigma_a (24) and the free
#: voxel's state in a step (``STEP_FREE_BYTES``), the N = 5 of the default ink set's mixture included here
SLAB_VOXEL_BYTES = 4 * 5 + 24 + STEP_FREE_BYTES
#: share of the machine's available memory a job may plan to use (the estimate's own error and the other
#: processes' growth stay free)
MEMORY_MARGIN = 0.8
#: the environment variable that sets the memory a job may use (GiB) instead of the available memory
MEMORY_ENV = "INKOPT_MEMORY_GB"


@dataclass(frozen=True)
class MeshShape:
    """A placed mesh's measures: ``box_mm`` (x, y, z) its bounding box, ``area_mm2``, ``volume_mm3``, ``texel_factor``
    the area-weighted mean of max(|n_x|, |n_y|, |n_z|) over its faces (texels per area in voxel faces);
    ``mesh_bytes``: what the loaded mesh holds (its arrays, its texture and the float32 copy of it its colour
    look-ups make), whatever its scale."""

    box_mm: tuple[float, float, float]
    area_mm2: float
    volume_mm3: float
    texel_factor: float
    mesh_bytes: float = 0.0

    @property
    def height_mm(self) -> float:
        return self.box_mm[2]

    def scaled(self, factor: float) -> MeshShape:
        """The same shape ``factor`` times as large."""
        box = tuple(float(b * factor) for b in self.box_mm)
        return replace(self, box_mm=box, area_mm2=self.area_mm2 * factor**2, volume_mm3=self.volume_mm3 * factor**3)


def mesh_shape(mesh) -> MeshShape:
    """The ``MeshShape`` of a loaded ``TexturedMesh`` (its seam-merged solid)."""
    tm = mesh.solid_trimesh()
    areas = np.asarray(tm.area_faces, np.float64)
    normals = np.abs(np.asarray(tm.face_normals, np.float64))
    factor = float(areas @ normals.max(axis=1) / max(areas.sum(), 1e-300))
    box = tuple(float(v) for v in np.ptp(mesh.solid_vertices, axis=0))
    arrays = (mesh.vertices, mesh.faces, mesh.solid_vertices, mesh.solid_faces, mesh.uv, mesh.texture_alpha)
    held = sum(a.nbytes for a in arrays if a is not None)
    if mesh.texture is not None:
        held += mesh.texture.width * mesh.texture.height * (3 + 12)  # RGB bytes, and float32 RGB while looked up
    return MeshShape(box, float(tm.area), abs(float(tm.volume)), factor, float(held))


@dataclass(frozen=True)
class Footprint:
    """A job's expected counts and what they cost. ``kind``: "mesh" or "slab"; ``grid`` (x, y, z) voxels at ``dpi``;
    ``grid_voxels``, ``inside_voxels``, ``free_voxels``, ``texels``; ``n_inks``; ``band``: the voxelization's exact
    signed-distance band (voxels; meshes); ``mesh_bytes``: the loaded mesh's (``MeshShape``); ``shell``: only a
    shell below the surface is free; ``events``: a mesh's expected events per path from white (``walk``)."""

    kind: str
    dpi: float
    grid: tuple[int, int, int]
    grid_voxels: int
    inside_voxels: int
    free_voxels: int
    texels: int
    n_inks: int
    band: float = DEFAULT_BAND
    mesh_bytes: float = 0.0
    shell: bool = False
    events: float = 0.0

    def peak_bytes(self) -> float:
        """The expected peak resident memory (bytes): the largest of the voxelization's, a step's and the figures'
        (module docstring; ``stage_bytes``)."""
        return max(self.stage_bytes().values())

    def stage_bytes(self) -> dict[str, float]:
        """Each stage's expected peak resident memory (bytes): "voxelize", "step", "figures" (a slab: "run", its
        one stage), each with ``BASE_BYTES`` and the mesh."""
        fixed = BASE_BYTES + self.mesh_bytes
        if self.kind == "slab":
            return {"run": fixed + SLAB_VOXEL_BYTES * self.grid_voxels + FIGURES_TEXEL_BYTES * self.texels}
        per_texel = VOXELIZE_TEXEL_BYTES + VOXELIZE_NEAR_BYTES * self.band
        voxelize = VOXELIZE_GRID_BYTES * self.grid_voxels + VOXELIZE_FIXED_BYTES + per_texel * self.texels
        medium_voxels = self.free_voxels if self.shell else self.inside_voxels
        held = RUN_GRID_BYTES * self.grid_voxels + RUN_TEXEL_BYTES * self.texels + RUN_INSIDE_BYTES * medium_voxels
        step = held + STEP_FREE_BYTES * self.free_voxels + STEP_TEXEL_BYTES * self.texels
        figures = held + FIGURES_FREE_BYTES * self.free_voxels + FIGURES_TEXEL_BYTES * self.texels
        if self.shell:
            step = held + SHELL_STEP_FREE_BYTES * self.free_voxels + SHELL_STEP_TEXEL_BYTES * self.texels
            figures = held + SHELL_FIGURES_FREE_BYTES * self.free_voxels + SHELL_FIGURES_TEXEL_BYTES * self.texels
        return {"voxelize": fixed + voxelize, "step": fixed + step, "figures": fixed + figures}

    def fits(self, limit_bytes: float) -> bool:
        """Whether the job's peak is at most ``limit_bytes`` and its grid within the renderer's 2^31 voxels."""
        return self.peak_bytes() <= limit_bytes and self.grid_voxels <= MAX_GRID_VOXELS

    def seconds_per_iteration(self) -> float:
        """The expected seconds of one iteration from white on a quiet 2-core machine (``walk``)."""
        if self.kind == "slab":
            return SLAB_SECONDS_PER_TEXEL * self.texels + walk.STEP_SECONDS_PER_FREE * self.free_voxels
        return walk.iteration_seconds(self.texels, self.events, self.free_voxels)

    def setup_seconds(self) -> float | None:
        """The expected seconds of a mesh run's set-up on a quiet machine (``walk``; None: a slab, not modelled)."""
        return None if self.kind == "slab" else walk.setup_seconds(self.texels)

    def disk_bytes(self, iterations: int) -> int:
        """The run directory's bytes (``estimate`` module docstring: volume.npz, the checkpoint, scene.npz)."""
        n = self.n_inks
        return int(4 * n * self.inside_voxels + 12 * n * self.free_voxels + 64 * self.texels + 80 * iterations)

    def quantized_bytes(self) -> int:
        """What ``inkopt quantize`` adds (``estimate.quantized_bytes``)."""
        return quantized_bytes(self.texels, self.grid_voxels, self.kind == "mesh")

    def line(
        self,
        iterations: int,
        time_budget: float | None = None,
        limit: MemoryLimit | None = None,
        budget_name="time budget",
        coarse_disk: float = 0.0,
    ) -> str:
        """The dry run's line: the counts, the peak memory (against ``limit``), the time of up to ``iterations``
        (ended sooner by ``time_budget`` seconds when shorter, named ``budget_name``) and the disk (with
        ``coarse_disk`` bytes of a coarse stage and its start, said apart)."""
        each = self.seconds_per_iteration()
        total = each * iterations
        budget = ""
        if time_budget is not None and total > time_budget:
            budget = f"; the {budget_name} ({format_duration(time_budget)}) ends the run sooner"
        room = f" of {limit.bytes / 2**30:.1f} GiB {limit.source}" if limit is not None else ""
        nx, ny, nz = self.grid
        counts = (
            f"grid {nx} x {ny} x {nz} ({_count(self.grid_voxels)} voxels), {_count(self.inside_voxels)} inside, "
            f"{_count(self.free_voxels)} free, {_count(self.texels)} texels"
        )
        setup = "" if self.kind == "slab" else f"set-up ~{format_duration(self.setup_seconds())}, "
        disk = self.disk_bytes(iterations) + coarse_disk
        coarse = f" (of which {_size(coarse_disk)} the coarse stage and its start)" if coarse_disk else ""
        events = "" if self.kind == "slab" else f", {self.events:.0f} events per path"
        return (
            f"estimate from the {self.kind}'s size ({counts}): peak memory ~{self.peak_bytes() / 2**30:.1f} GiB{room}; "
            f"{setup}up to {iterations} iterations x {_seconds(each)} s = {format_duration(total)} (+ the final "
            f"evaluation; 2 quiet cores, from white{events}){budget}; disk ~{_size(disk)}{coarse} "
            f"(+ {_size(self.quantized_bytes())} after inkopt quantize)"
        )


def _count(n: float) -> str:
    return f"{n / 1e6:.1f} M" if n >= 1e6 else f"{n / 1e3:.0f} k" if n >= 1e4 else f"{n:.0f}"


def _seconds(s: float) -> str:
    return f"{s:.2g}" if s < 10 else f"{s:.0f}"


def _size(n: float) -> str:
    return f"{n / 1e9:.2f} GB" if n >= 1e8 else f"{n / 1e6:.1f} MB"


def mesh_footprint(shape: MeshShape, dpi: float, shell_mm: float | None, n_inks: int, band: float = 3.0) -> Footprint:
    """The ``Footprint`` of a mesh of ``shape`` voxelized at ``dpi`` (free within ``shell_mm`` of the surface, or
    every inside voxel), ``n_inks`` inks, ``band`` voxels of exact signed distance (module docstring)."""
    h = voxel_mm(dpi)
    grid = tuple(int(max(math.ceil(b / h - 1e-9), 1)) + 2 for b in shape.box_mm)
    grid_voxels = grid[0] * grid[1] * grid[2]
    inside = shape.volume_mm3 / h**3
    r = walk.thickness_mm(shape.volume_mm3, shape.area_mm2)  # the equal-ratio ball's radius (mm)
    # the texels' centres lie about half a voxel deep, where that ball has (1 - h / 2r)^2 of its area
    texels = min(shape.texel_factor * shape.area_mm2 / h**2 * max(1.0 - 0.5 * h / r, 0.0) ** 2, inside)
    free = inside
    if shell_mm is not None:
        shell = inside * (1.0 - (1.0 - min(shell_mm / r, 1.0)) ** 3)
        free = min(max(shell, texels), inside)
    counts = (grid_voxels, round(inside), round(free), round(texels))
    events = walk.events_per_path(r, shell_mm is not None and free < inside)
    return Footprint("mesh", dpi, grid, *counts, n_inks, band, shape.mesh_bytes, shell_mm is not None, events)


def mesh_band(voxel: float, *depths_mm) -> float:
    """The voxelization's band of exact signed distance (voxels) for a shell or translucent depth (mm), as
    ``scenes.mesh.build_mesh_scene`` sets it."""
    band = float(DEFAULT_BAND)
    for d in depths_mm:
        band = band if d is None else max(band, math.ceil(d / voxel) + 2.0)
    return band


def slab_footprint(size_mm, dpi: float, faces: int, n_inks: int) -> Footprint:
    """The ``Footprint`` of a slab of ``size_mm`` (W, H, D) at ``dpi`` with ``faces`` pictures (1 or 2)."""
    h = voxel_mm(dpi)
    nx, ny, nz = (max(1, int(round(v / h))) for v in size_mm)
    voxels = nx * ny * nz
    return Footprint("slab", dpi, (nx, ny, nz), voxels, voxels, voxels, nx * ny * faces, n_inks, 0.0)


@dataclass(frozen=True)
class MemoryLimit:
    """The memory a job may use: ``bytes`` and where the figure comes from (``source``, for the messages)."""

    bytes: float
    source: str


def available_bytes() -> float:
    """This machine's available memory (bytes): /proc/meminfo's MemAvailable, less the room left below a cgroup's
    memory.max when one is set; where /proc is missing, the free pages (``os.sysconf``)."""
    try:
        with open("/proc/meminfo") as f:
            fields = dict(line.split(":", 1) for line in f)
        avail = float(fields["MemAvailable"].split()[0]) * 1024
    except (OSError, KeyError, ValueError):
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    try:
        with open("/sys/fs/cgroup/memory.max") as f:
            cap = f.read().strip()
        with open("/sys/fs/cgroup/memory.current") as f:
            used = float(f.read().strip())
        if cap != "max":
            avail = min(avail, float(cap) - used)
    except (OSError, ValueError):
        pass
    return avail


def memory_limit(memory_gb: float | None = None) -> MemoryLimit:
    """The memory a job may use: ``memory_gb`` (GiB) when given, else ``INKOPT_MEMORY_GB``, else
    ``MEMORY_MARGIN`` of the available memory (``available_bytes``)."""
    if memory_gb is None and os.environ.get(MEMORY_ENV):
        try:
            memory_gb = float(os.environ[MEMORY_ENV])
        except ValueError:
            raise ParameterError(f"{MEMORY_ENV} must be a number of GiB, got '{os.environ[MEMORY_ENV]}'") from None
        source = f"({MEMORY_ENV})"
    else:
        source = "(`memory_gb`)"
    if memory_gb is not None:
        if not (math.isfinite(memory_gb) and memory_gb > 0):
            raise ParameterError(f"`memory_gb` must be a positive number of GiB, got {memory_gb:g}")
        return MemoryLimit(memory_gb * 2**30, source)
    return MemoryLimit(MEMORY_MARGIN * available_bytes(), f"({MEMORY_MARGIN:.0%} of the available memory)")


def spec_footprint(spec, n_inks: int, mesh=None) -> tuple[Footprint, MeshShape | None]:
    """The ``Footprint`` of a scene spec (``scenes.spec.SlabSpec`` or ``MeshSpec``, checked) for ``n_inks`` inks and,
    for a mesh, its ``MeshShape``; loads a mesh (``mesh``: one already loaded), never voxelizes it."""
    if spec.kind == "slab":
        return slab_footprint(spec.size_mm, spec.dpi, 1 if spec.bottom is None else 2, n_inks), None
    if mesh is None:
        from ..scenes.mesh import load_spec_mesh

        mesh = load_spec_mesh(spec)
    shape = mesh_shape(mesh)
    band = mesh_band(voxel_mm(spec.dpi), spec.shell_mm, spec.translucency_depth_mm if spec.translucency else None)
    return mesh_footprint(shape, spec.dpi, spec.shell_mm, n_inks, band), shape
