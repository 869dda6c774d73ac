"""What a single run (``slab``, ``optimize``) settles before anything large is built: its footprint from its size
(``inkopt.footprint``: a mesh is loaded, not voxelized), the refusal of a job beyond the memory it may use
(``--memory-gb``), the band of a mesh given no ``--shell-mm`` whose every voxel free does not fit, the time plan of
a run given neither ``--time-budget`` nor ``--iterations``, and a dry run answered from the footprint."""

from __future__ import annotations

from dataclasses import replace


def plan_job(args, spec, inks, cfg, options):
    """Check that the job of ``spec`` (checked) with the ink set ``inks`` fits the memory (a one-line ParameterError
    naming the largest size that fits; a dry run keeps it for after its estimate), give a mesh without
    ``--shell-mm`` the band when every voxel free does not fit (``footprint.fits.choose_shell``; ``--shell-mm 0``:
    every voxel free) and a run without ``--time-budget`` or ``--iterations`` its time plan (each logged before
    the run's first line). Returns (the spec the job runs, ``cfg``, ``options``, a dry run's answer or None): the
    answer for a mesh's dry run and for any job that does not fit."""
    from ..errors import ParameterError
    from ..footprint import memory_limit, spec_footprint
    from ..footprint.fits import choose_shell
    from .common import flag_of

    limit = memory_limit(args.memory_gb)
    automatic = getattr(args, "shell_mm", None) is None  # `--shell-mm 0`: every voxel free by choice
    n_inks = len(inks)
    kept = _resumed_shell(args, inks) if automatic and spec.kind == "mesh" else None
    if kept is not None:  # a resumed run keeps its band, or every voxel free, whatever the memory is now
        automatic = False
        if kept > 0:
            spec = replace(spec, shell_mm=kept, core="white", shell_chosen=f"kept from the run resumed in {args.out}")
    refusal, note = None, None
    try:
        choice = choose_shell(spec, n_inks, limit, automatic)
        spec, fp, note, shape = choice.spec, choice.footprint, choice.note, choice.shape
    except ParameterError as exc:
        if not args.dry_run:
            raise
        refusal = exc  # a dry run prints its estimate first
        fp, shape = spec_footprint(spec, n_inks)
    if note is not None:
        note = ParameterError(note).render(flag_of)  # the library's parameter names as flags
        options = replace(options, log=_first_line(options.log, note))
    planned = args.iterations is None and cfg.time_budget is None
    if planned:
        budget, line = _time_plan(fp)
        cfg = replace(cfg, time_budget=budget)
        options = replace(options, log=_first_line(options.log, line))
    dry = None
    if args.dry_run and (spec.kind == "mesh" or refusal is not None):
        coarse = _coarse_disk(args, spec, shape, fp, cfg) if spec.kind == "mesh" else 0.0
        dry = _FootprintDryRun(fp, cfg.iterations, limit, refusal, planned, note, coarse)
    return spec, cfg, options, dry


def _coarse_disk(args, spec, shape, fp, cfg) -> float:
    """The disk (bytes) a mesh job's coarse stage adds when it goes coarse to fine (``--coarse-dpi``, or a time
    budget's deadline plan: half the DPI, ``coarse.deadline_plan``): the coarse run's folder (its footprint at that
    DPI) and the fine stage's start (``optim.startrows``: 8 + 4N bytes per free voxel); 0 when it does not."""
    from ..coarse import DEADLINE_COARSE_FACTOR
    from ..footprint import mesh_band, mesh_footprint
    from ..units import voxel_mm

    dpi = args.coarse_dpi
    if dpi is None and cfg.time_budget is not None:
        dpi = DEADLINE_COARSE_FACTOR * spec.dpi
    if not dpi or not 0 < dpi < spec.dpi:
        return 0.0
    depth = spec.translucency_depth_mm if spec.translucency else None
    coarse = mesh_footprint(shape, dpi, spec.shell_mm, fp.n_inks, mesh_band(voxel_mm(dpi), spec.shell_mm, depth))
    return coarse.disk_bytes(cfg.iterations) + (8 + 4 * fp.n_inks) * fp.free_voxels


def _resumed_shell(args, inks) -> float | None:
    """What the mesh run ``--resume`` continues in ``--out`` optimised (its fine stage's scene.npz, else its coarse
    stage's): its shell (mm) when it optimised a band over a white core of ``inks``, as a band chosen for the memory
    is; 0 when every voxel was free; None when there is no such run to continue, or it had another core."""
    from pathlib import Path

    import numpy as np

    from ..rundir import RunDir

    if not args.resume:
        return None
    white = np.eye(len(inks), dtype=np.float32)[list(inks.names).index("white")] if "white" in inks.names else None
    for folder in (Path(args.out), Path(args.out) / "coarse"):
        if (folder / RunDir.SCENE).is_file() and (folder / RunDir.CHECKPOINT).is_file():
            mesh = RunDir(folder).load_scene().mesh
            if mesh is None or white is None:
                return None
            if mesh.shell_mm is None:
                return 0.0
            held = np.asarray(mesh.core_share if mesh.core_share is not None else white, np.float32)
            return float(mesh.shell_mm) if np.array_equal(held, white) else None
    return None


def _first_line(log, line: str):
    """``log`` that writes ``line`` before its first message: a run's first log line, while a one-line error
    before anything is logged stays one line."""
    pending = [line]

    def out(msg: str) -> None:
        while pending:
            log(pending.pop())
        log(msg)

    return out


def _time_plan(fp) -> tuple[float, str]:
    """The time budget of a run given neither ``--time-budget`` nor ``--iterations`` (``coarse.default_time_budget``
    from the footprint's seconds per iteration) and the line that says so."""
    from ..coarse import PLAN_ITERATIONS, PLAN_MAX_SECONDS, PLAN_MIN_SECONDS, default_time_budget
    from ..units import format_duration

    each = fp.seconds_per_iteration()
    budget = default_time_budget(each)
    why = f"{PLAN_ITERATIONS} iterations' time at the estimated {each:.3g} s each"
    if budget > PLAN_ITERATIONS * each:
        why = f"at least {format_duration(PLAN_MIN_SECONDS)}; {why} is less"
    elif budget < PLAN_ITERATIONS * each:
        why = (
            f"at most {format_duration(PLAN_MAX_SECONDS)}, mesh to printer package within 3 hours; {why} "
            f"({format_duration(PLAN_ITERATIONS * each)}) is more"
        )
    return budget, (
        f"time plan: {format_duration(budget)} (no --time-budget or --iterations given; {why}, the deadline "
        "that reached within 1 ΔE76 of 300 iterations on Spot and the reference slab, docs/performance.md; "
        "--time-budget or --iterations to choose)"
    )


class _FootprintDryRun:
    """A dry run from the footprint (a mesh's, or a job that does not fit): its line for ``iterations`` against the
    memory ``limit``; ``refusal``: the error the run would end with (None: it fits); ``planned``: its time budget is
    the time plan; ``note``: the line of a band chosen for the memory (None: none), printed first; ``coarse_disk``:
    the bytes a coarse stage adds to the disk (``_coarse_disk``)."""

    def __init__(self, fp, iterations: int, limit, refusal=None, planned=False, note=None, coarse_disk: float = 0.0):
        self.fp, self.iterations, self.limit, self.refusal, self.planned = fp, iterations, limit, refusal, planned
        self.note, self.coarse_disk = note, coarse_disk

    def line(self, time_budget: float | None = None) -> str:
        from ..errors import ParameterError
        from .common import flag_of

        budget_name = "time plan" if self.planned else "time budget"
        line = self.fp.line(self.iterations, time_budget, self.limit, budget_name, self.coarse_disk)
        line = ParameterError(line).render(flag_of)  # the memory limit's source may name a parameter
        return line if self.note is None else f"{self.note}\n{line}"
