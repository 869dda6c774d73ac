"""Peak memory, time and file size of a coarse-to-fine job's transfer alone, on the coarse result of a job that ran
(``RUN/coarse/volume.npz``): the coarse scene and its extrusion baseline B_c as the coarse stage makes them, the fine
scene, then the transfer of C and B_c onto the fine run's free voxels as the start file, with the resident-set
high-water mark after each phase (reset before the transfer, so that its own peak shows).

    python bench/bench_c2f_transfer.py RUN HEIGHT_MM [--mesh spot.obj] [--shell-mm 1] [--coarse-dpi 150]
        [--whole] [--name NAME]

Default: as ``coarse.run_coarse_to_fine`` does it (C and B_c held by their bands, ``model.banded``; the fine
baseline at the free voxels only; the start as the free voxels' rows, ``optim.startrows``). ``--whole``: as it was
done before, with the same library functions (C loaded whole, B_c made whole, the fine baseline for every inside
voxel, the start as a whole-grid volume file stored without zlib). The start file is written to a temporary folder
beside RUN and removed. Writes the entry NAME (default ``spot<H>_band`` or ``spot<H>_whole``) of
bench/results/c2f_transfer.json; run it with nothing else heavy on the machine for the seconds to mean anything.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "bench"))

SPOT = ROOT.parent / "shared" / "data" / "spot" / "spot.obj"  # ../shared beside the repository
RESULTS = ROOT / "bench" / "results" / "c2f_transfer.json"


def status_gib(key: str) -> float:
    """``key`` (VmHWM, VmRSS) of this process in GiB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return int(line.split()[1]) / 2**20
    raise RuntimeError(f"{key} not in /proc/self/status")


def coarse_baseline(coarse, whole: bool):
    """B_c of the coarse scene as the coarse stage holds it: by its band, or (``whole``) the whole grid's."""
    from inkopt.coarse import baseline_by_band
    from inkopt.evaluation.baselines import baseline_layers

    layers = baseline_layers("extrusion", coarse.volume, coarse.texels, coarse.target_rgb, coarse.fixed_share)
    return coarse.volume.with_mixture(layers.array()) if whole else baseline_by_band(coarse.volume, layers)


def transfer(run: Path, fine, b_c, path: Path, whole: bool) -> None:
    """Move ``run``'s coarse result onto ``fine`` as the correction transfer from the extrusion baseline, to
    ``path``."""
    from inkopt.evaluation.baselines import baseline_layers
    from inkopt.optim.transfer import (
        Baseline,
        coarse_result,
        destination,
        write_transferred_rows,
        write_transferred_volume,
    )
    from inkopt.rundir import RunDir

    volume = RunDir(run / "coarse").volume_file()
    args = (fine.volume, fine.texels, fine.target_rgb, fine.fixed_share)
    if whole:
        b_f = baseline_layers("extrusion", *args)
        c = RunDir(run / "coarse").load_volume()
        write_transferred_volume(c, fine.volume, fine.fixed_share, path, baseline=Baseline(b_c, b_f), compressed=False)
        return
    param = destination(fine.volume, fine.fixed_share)
    b_f = baseline_layers("extrusion", *args, only=param.free_index)
    write_transferred_rows(coarse_result(volume), fine.volume, param, path, baseline=Baseline(b_c, b_f))


def main(argv=None) -> dict:
    from common import machine, provenance, write

    from inkopt.model import InkTable
    from inkopt.run import release_freed_memory
    from inkopt.scenes import build_scene
    from inkopt.scenes.spec import MeshSpec

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="a coarse-to-fine job's folder (its coarse/volume.npz)")
    ap.add_argument("height_mm", type=float)
    ap.add_argument("--mesh", default=str(SPOT))
    ap.add_argument("--shell-mm", type=float, default=1.0)
    ap.add_argument("--coarse-dpi", type=float, default=150.0)
    ap.add_argument("--whole", action="store_true", help="the transfer with whole grids, as it was done before")
    ap.add_argument("--name")
    a = ap.parse_args(argv)
    inks = InkTable.parse("vero-cmykw")
    spec = MeshSpec(a.mesh, height_mm=a.height_mm, shell_mm=a.shell_mm or None, core="white" if a.shell_mm else None)
    peaks, held, seconds = {}, {}, {}
    t = time.perf_counter()
    coarse = build_scene(replace(spec, dpi=a.coarse_dpi), inks)
    b_c = coarse_baseline(coarse, a.whole)
    del coarse
    release_freed_memory()
    seconds["coarse_baseline"], peaks["coarse_baseline"], held["coarse_baseline"] = (
        time.perf_counter() - t,
        status_gib("VmHWM"),
        status_gib("VmRSS"),
    )
    t = time.perf_counter()
    fine = build_scene(spec, inks)
    seconds["fine_scene"], peaks["fine_scene"], held["fine_scene"] = (
        time.perf_counter() - t,
        status_gib("VmHWM"),
        status_gib("VmRSS"),
    )
    Path("/proc/self/clear_refs").write_text("5")  # the high-water mark from here: the transfer's own
    with tempfile.TemporaryDirectory(dir=a.run.parent) as tmp:
        path = Path(tmp) / "fine_start.npz"
        t = time.perf_counter()
        transfer(a.run, fine, b_c, path, a.whole)
        seconds["transfer"], peaks["transfer"], held["transfer"] = (
            time.perf_counter() - t,
            status_gib("VmHWM"),
            status_gib("VmRSS"),
        )
        size = path.stat().st_size
    name = a.name or f"spot{a.height_mm:g}_{'whole' if a.whole else 'band'}"
    result = {
        "run": str(a.run),
        "height_mm": a.height_mm,
        "shell_mm": a.shell_mm,
        "coarse_dpi": a.coarse_dpi,
        "whole": a.whole,
        "fine_grid_zyx": list(fine.volume.shape),
        "fine_band_voxels": None if fine.volume.band is None else int(fine.volume.band.index.size),
        "peak_gib_by_phase": peaks,
        "resident_gib_after_phase": held,
        "seconds_by_phase": seconds,
        "start_file_bytes": size,
        "machine": machine(),
        **provenance(),
    }
    data = json.loads(RESULTS.read_text()) if RESULTS.is_file() else {}
    data[name] = result
    write(RESULTS.name, data)
    print(json.dumps({name: {k: result[k] for k in ("peak_gib_by_phase", "seconds_by_phase", "start_file_bytes")}}))
    return result


if __name__ == "__main__":
    main()
