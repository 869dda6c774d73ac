"""Paired comparison of mesh suite results of one mesh and size: each candidate's continuous result and its print
(blue noise, the defaults of ``inkopt quantize``) rendered on the same sampled scene texels with the same seeds at a
fixed number of samples per texel, as ``inkopt evaluate`` renders them (``experiments/figure_disagreement.py``'s
``render_results``), and every candidate's per-texel noise-corrected ΔE76 and ΔE2000 differenced with the first's.
Writes the entry NAME of bench/results/mesh_suite_paired.json.

    nice -n 10 python bench/mesh_suite_paired.py NAME LABEL=SOURCE [LABEL=SOURCE ...] [--texels 3000] [--spp 512]
    python bench/mesh_suite_paired.py checkpoint RUN DEST PASSES [TEXTURE]   # RUN's last iterate, PASSES smoothings

SOURCE is a suite run folder (its volume.npz and quantized.npz), or ``RUN:fine_start`` (the volume its coarse stage
handed to the fine stage, ``RUN/coarse/fine_start.npz``), or ``RUN:unsmoothed`` (the last iterate of the
checkpoint, before the finishing smoothing: ``OptimizeConfig.finish_smooth``), or ``RUN:smoothed`` (that iterate after
one pass, where the mesh names its texture: what ``--finish-smooth 1`` returns). The last three are quantized here into
a temporary copy of the run; nothing is written into a run folder. All sources must share one scene (the same mesh,
size and DPI: scene.npz's texels). The first candidate is the reference of the differences.

Noise: ΔE76 is corrected per texel by ``NoiseModel`` as ``evaluate`` corrects it; ΔE2000 by figure_disagreement's
simulated inflation. The ± of a difference is the standard error of the mean of the per-texel differences over the
sampled texels (finite-population corrected): it holds the sampling of texels and the render noise of both.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
from common import ROOT, machine, provenance  # noqa: E402
from figure_disagreement import mean_se, per_texel, render_results  # noqa: E402

RESULTS = ROOT / "bench" / "results" / "mesh_suite_paired.json"
COPIED = ("scene.npz", "report.json", "volume.npz")
#: the per-texel values compared (figure_disagreement.per_texel's names)
VALUES = ("de76_corrected", "de2000_corrected", "de76", "de2000")


def checkpoint_volume(run: Path, out: Path, passes: int = 0, texture: str | None = None) -> None:
    """Write to ``out`` the volume of ``run``'s checkpoint iterate (its last iterate: the result before its
    finishing smoothing) after ``passes`` passes of the mesh defaults' step smoothing (``Optimization.finish``'s
    operator, guided by the target: ``texture`` where the mesh names none). The run's volume.npz with the free
    voxels' mixtures of the checkpoint's variables ``x`` (F, N)."""
    from inkopt.model import Volume
    from inkopt.optim import OptimizeConfig
    from inkopt.optim.checkpoint import read_checkpoint
    from inkopt.optim.loop import Optimization
    from inkopt.scenes import build_scene
    from inkopt.scenes.spec import MeshSpec

    report = json.loads((run / "report.json").read_text())
    inks = Volume.load(run / "volume.npz").inks
    spec = MeshSpec(report["mesh_path"], height_mm=report["height_mm"], texture=texture, constant_color=not passes)
    scene = build_scene(spec, inks)
    cfg = OptimizeConfig(iterations=0, init=str(run / "volume.npz"), lr=1.0).for_scene("mesh")
    opt = Optimization(scene, cfg)
    x = read_checkpoint(run / "checkpoint.npz")["x"]
    if x.shape != opt.x.shape:
        raise SystemExit(f"{run}/checkpoint.npz holds x {x.shape}, the scene's variables are {opt.x.shape}")
    for _ in range(passes):
        x = opt.smoother.apply(x)
    scene.volume.save_with_mixture(out, opt.param.mixture_slabs(x), inks)


def checkpoint_run(run: Path, dest: Path, passes: int = 0, texture: str | None = None) -> None:
    """A run folder ``dest`` holding ``run``'s last iterate after ``passes`` finishing passes
    (``checkpoint_volume``) with ``run``'s scene.npz and report.json (the report's ``finish_smooth`` set to
    ``passes``, ``finish_smooth_from`` naming ``run``), for ``inkopt quantize`` and ``inkopt evaluate``: what
    ``--finish-smooth PASSES`` returns after the same iterations."""
    dest.mkdir(parents=True, exist_ok=False)
    shutil.copy2(run / "scene.npz", dest / "scene.npz")
    checkpoint_volume(run, dest / "volume.npz", passes, texture)
    report = json.loads((run / "report.json").read_text())
    report.update(finish_smooth=passes, finish_smooth_from=str(run))
    (dest / "report.json").write_text(json.dumps(report, indent=2) + "\n")


def start_volume(run: Path, path: Path) -> None:
    """``run``'s coarse-to-fine start (``RUN/coarse/fine_start.npz``, its fine run's free voxels' rows) as a mixture
    volume file of the whole grid at ``path`` (the run's volume.npz's geometry, its scene's fixed shares)."""
    from inkopt.model import Volume
    from inkopt.optim.startrows import is_start_rows
    from inkopt.optim.transfer import write_start_volume
    from inkopt.rundir import RunDir

    start = run / "coarse" / "fine_start.npz"
    if not is_start_rows(start):  # a whole-grid start (written before the start held its free voxels only)
        shutil.copy2(start, path)
        return
    base = Volume.load(run / "volume.npz")
    write_start_volume(start, base, RunDir(run).load_scene().fixed_share(base.inks, base.shape), path)


def candidate_run(source: str, tmp: Path) -> Path:
    """The run folder to render for ``source`` (module docstring): the run itself, or a copy in ``tmp`` with the
    volume the source names, quantized with the defaults."""
    run, _, part = source.partition(":")
    run = Path(run)
    if not part:
        return run
    dest = tmp / f"{run.name}_{part}"
    dest.mkdir()
    for name in COPIED:
        shutil.copy2(run / name, dest / name)
    if part == "fine_start":
        start_volume(run, dest / "volume.npz")
    elif part in ("unsmoothed", "smoothed"):
        checkpoint_volume(run, dest / "volume.npz", int(part == "smoothed"))
    else:
        raise SystemExit(f"unknown part {part!r} of {source}: fine_start, unsmoothed or smoothed")
    cmd = [sys.executable, "-m", "inkopt", "quantize", str(dest)]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return dest


def compare(candidates: dict[str, str], texels: int, spp: int, threads: int, seed: int) -> dict:
    """Each candidate's means of ``VALUES`` for its continuous result and its print, [mean, standard error], and
    their paired differences from the first candidate's; plus the extrusion baseline (printed) of the first."""
    per, population = {}, None
    with tempfile.TemporaryDirectory(prefix="mesh_suite_paired_") as tmp:
        for label, source in candidates.items():
            data = render_results(candidate_run(source, Path(tmp)), texels, spp, threads, seed)
            population = data["population"]
            tl = data["target_lab"]
            per[label] = {name: per_texel(tl, *data["results"][key]) for name, key in RESULT_KEYS.items()}
            if "extrusion" not in per:
                per["extrusion"] = {"printed": per_texel(tl, *data["results"]["extrusion"])}
            print(f"{label}: " + summary_line(per[label]), flush=True)
    first = next(iter(candidates))
    out = {}
    for label, results in per.items():
        out[label] = {r: {k: mean_se(v[k], population) for k in VALUES} for r, v in results.items()}
        if label in (first, "extrusion"):
            continue
        for r, v in results.items():
            ref = per[first][r]
            out[label][f"{r} - {first}"] = {k: mean_se(v[k] - ref[k], population) for k in VALUES}
    for label in candidates:
        ext = per["extrusion"]["printed"]
        out[label]["printed - extrusion"] = {k: mean_se(per[label]["printed"][k] - ext[k], population) for k in VALUES}
    out["population"] = population
    return out


#: the results of figure_disagreement.render_results compared, by this script's names
RESULT_KEYS = {"continuous": "continuous", "printed": "quantized"}


def summary_line(results: dict) -> str:
    return ", ".join(
        f"{r} ΔE76c {v['de76_corrected'].mean():.2f} ΔE2000c {v['de2000_corrected'].mean():.2f}"
        for r, v in results.items()
    )


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["checkpoint"]:  # checkpoint RUN DEST PASSES [TEXTURE]: the run folder of checkpoint_run
        checkpoint_run(Path(argv[1]), Path(argv[2]), int(argv[3]), argv[4] if len(argv) > 4 else None)
        return 0
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name", help="the entry's name in the results file")
    ap.add_argument("candidates", nargs="+", help="LABEL=SOURCE (module docstring); the first is the reference")
    ap.add_argument("--texels", type=int, default=3000, help="scene texels sampled (default 3000)")
    ap.add_argument("--spp", type=int, default=512, help="samples per scene texel (default 512)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--results", type=Path, default=RESULTS)
    a = ap.parse_args(argv)
    candidates = dict(c.split("=", 1) for c in a.candidates)
    entry = {**provenance(), "candidates": candidates, "texels_sampled": a.texels, "spp": a.spp, "seed": a.seed}
    entry["results"] = compare(candidates, a.texels, a.spp, a.threads, a.seed)
    entry.update(machine())
    data = json.loads(a.results.read_text()) if a.results.is_file() else {}
    data[a.name] = entry
    tmp = a.results.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    tmp.replace(a.results)
    for label, r in entry["results"].items():
        if label == "population":
            continue
        for key, v in r.items():
            if " - " in key:
                d76, d00 = v["de76_corrected"], v["de2000_corrected"]
                print(f"{label}: {key}: ΔE76c {d76[0]:+.2f} ± {d76[1]:.2f}, ΔE2000c {d00[0]:+.2f} ± {d00[1]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
