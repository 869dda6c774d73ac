"""Size and writing time of the soft-proof page (``inkopt report``) of existing run directories, within its size
budget, and of a synthetic page with as many texels as a larger object has. ``seconds`` is wall time,
``cpu_seconds`` the process's CPU time (all threads): on a shared machine the second is the steadier.

    .venv/bin/python bench/bench_report.py RUN [RUN ...] [--max-mb 30] [--name report_pages.json]
    .venv/bin/python bench/bench_report.py --synthetic RUN --texels 2430000 --height-mm 100 [--noise 0.05] ...

Each run is reported in this process (``proof.write_proof``, to RUN/report.html, with ``ProofOptions(max_mb)``)
and its page size, the seconds it took, the results shown, the atlas size, what the budget chose (``reduced``,
JPEG ``quality``, ``pixels_per_texel``, the page's size without the budget: ``unreduced_mb``) and the run's texel
count and evaluation samples are recorded in bench/results/NAME. The runs are made beforehand, e.g. by ``inkopt
demo`` (demo-out/slab, demo-out/spot) or by ``inkopt optimize MESH --height-mm 40`` and ``inkopt evaluate
--texel-sample 0``; the page's size depends on how noisy the predictions are (JPEG textures), so the evaluation's
spp is recorded with it.

``--synthetic RUN`` writes a page (to bench-out/synthetic_report.html) through the page's own functions for the
run's mesh scaled to ``--height-mm`` with ``--texels`` texels sampled at random by area on its surface (the texel
size: the square root of the area per texel). Each texel takes every result's colour (the four of an evaluated
run; a result the run lacks: its continuous one) from the run's nearest texel plus independent Gaussian noise of
``--noise`` (linear RGB, per channel, per result): pictures noisier than a real evaluation's, which compress
worse. ``--lights N``: N sets of pictures, each with its own noise, as a spectral run's page under N lights. The
page's other parts are the run's own. It shows that the budget holds at a texel count no run on this machine
reaches.
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(Path(__file__).resolve().parent))


def _row(p, run, rep: dict, ev: dict) -> dict:
    return {
        "run": str(run),
        "kind": ev.get("kind", "slab" if "size_mm" in rep else "mesh"),
        "height_mm": rep.get("height_mm"),
        "size_mm": rep.get("size_mm"),
        "texels": rep.get("texels"),
        "evaluation_spp": ev.get("spp"),
        "page_mb": p.bytes / 1e6,
        "seconds": p.seconds,
        "results": p.results,
        "atlas": p.atlas,
        "downsampled": p.downsampled,
        "max_mb": p.max_mb,
        "reduced": p.reduced,
        "quality": p.quality,
        "pixels_per_texel": p.pixels_per_texel,
        "step": p.step,
        "unreduced_mb": None if p.unreduced_bytes is None else p.unreduced_bytes / 1e6,
    }


def _noisy_pictures(target, results: dict, noise: float, lights: int):
    """``lights`` sets of (sRGB8 colours, heat maps) of ``results`` {name: (I, 3) linear RGB}, each result with
    Gaussian noise ``noise`` drawn afresh per light, against ``target`` (I, 3); and the heat maps' scale."""
    from inkopt.color import delta_e76, linear_to_lab
    from inkopt.proof.bake import heat_rgb8, heat_scale, srgb8

    rng = np.random.default_rng(0)
    target_lab = linear_to_lab(target)
    shown = []
    for _ in range(lights):
        colours = {"target": target}
        for k, v in results.items():
            colours[k] = np.clip(v + rng.normal(0, noise, v.shape), 0, 1).astype(np.float32)
        shown.append((colours, {k: delta_e76(linear_to_lab(colours[k]), target_lab) for k in results}))
    scale = heat_scale([v for _, de in shown for v in de.values()])
    bake = lambda cs, de: ({k: srgb8(c) for k, c in cs.items()}, {k: heat_rgb8(v, scale) for k, v in de.items()})  # noqa: E731
    return [bake(cs, de) for cs, de in shown], scale


def synthetic(run, texels: int, height_mm: float, noise: float, lights: int, options, out: Path) -> dict:
    """The page of ``run``'s mesh at ``height_mm`` with ``texels`` texels (module docstring), written to ``out``."""
    import trimesh
    from scipy.spatial import cKDTree

    from inkopt import proof
    from inkopt.proof.bake import encode, heat_legend
    from inkopt.proof.lights import light_bar
    from inkopt.proof.markup import html
    from inkopt.proof.page import data_uri, page_html
    from inkopt.rundir import RunDir
    from inkopt.scenes.mesh.load import load_mesh

    t0 = time.perf_counter()
    d = RunDir(run)
    report, rec, pred, ev = proof._read_run(d)
    info = rec.mesh
    factor = height_mm / float(info.height_mm)
    load = lambda s: load_mesh(info.mesh_path, scale=s, up=info.up, constant_color=True)  # noqa: E731
    src, big = load(info.mesh_scale), load(info.mesh_scale * factor)
    shift = big.solid_vertices.mean(0) - factor * src.solid_vertices.mean(0)  # the run's frame -> the scaled one
    tm = trimesh.Trimesh(big.solid_vertices, big.solid_faces, process=False)
    points, face = trimesh.sample.sample_surface(tm, texels, seed=0)
    nearest = cKDTree(factor * info.texel_closest_mm + shift).query(points, workers=-1)[1]
    base = {k: pred.rgb.get(k, pred.rgb["continuous"])[nearest] for k in proof.ORDER[1:]}
    keys = ["target", *base]
    baked, scale = _noisy_pictures(rec.target_rgb[nearest], base, noise, lights)
    pictures = proof.Pictures(keys, baked, data_uri(encode(heat_legend(scale)), "image/png"), scale, options)
    voxel = float(np.sqrt(tm.area / texels))
    fake = SimpleNamespace(
        mesh=SimpleNamespace(
            mesh_path=info.mesh_path,
            mesh_scale=info.mesh_scale * factor,
            up=info.up,
            voxel_mm=[voxel] * 3,
            texel_closest_mm=points,
        ),
        texels=SimpleNamespace(normal=tm.face_normals[face]),
    )
    sections = proof._sections(d, report, ev, None, pred)
    data = {"shade": proof.SHADE, "results": keys, "heat_scale": scale}
    names = [f"light {i}" for i in range(lights)]
    if lights > 1:
        data["lights"] = names

    def compose(kind, view, view_data, picture_bytes):
        view = html("{}{}", light_bar(names), view) if lights > 1 else view
        page = page_html("synthetic", "synthetic", {**data, kind: view_data}, view, sections, True)
        return proof.Composed(page.encode(), picture_bytes)

    fit = proof._fit_mesh(fake, pictures, compose)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_bytes(fit.page)
    return {
        "run": f"synthetic from {run}",
        "kind": "mesh",
        "height_mm": height_mm,
        "texels": texels,
        "texel_mm": voxel,
        "noise_linear_rgb": noise,
        "lights": lights,
        "page_mb": len(fit.page) / 1e6,
        "seconds": time.perf_counter() - t0,
        "results": keys,
        "atlas": fit.atlas.size,
        "downsampled": fit.atlas.downsampled,
        "max_mb": options.max_mb,
        "reduced": fit.reduced,
        "quality": fit.quality,
        "pixels_per_texel": fit.atlas.pixels_per_texel,
        "tries": fit.tries,
        "unreduced_mb": fit.first_bytes / 1e6,
    }


def main() -> None:
    from common import machine, write

    from inkopt.proof import ProofOptions, write_proof

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="*")
    ap.add_argument("--max-mb", type=float, default=ProofOptions().max_mb, help="the pages' size budget (MB)")
    ap.add_argument("--synthetic", metavar="RUN", help="also a synthetic page from this mesh run (see above)")
    ap.add_argument("--texels", type=int, default=2_430_000)
    ap.add_argument("--height-mm", type=float, default=100.0)
    ap.add_argument("--noise", type=float, default=0.05, help="synthetic: per-texel noise (linear RGB)")
    ap.add_argument("--lights", type=int, default=1, help="synthetic: lights (own pictures each)")
    ap.add_argument("--name", default="report_pages.json")
    args = ap.parse_args()
    options = ProofOptions(max_mb=args.max_mb)
    rows = []
    for run in args.runs:
        cpu = time.process_time()
        p = write_proof(run, options=options)
        cpu = time.process_time() - cpu
        rep = json.loads((Path(run) / "report.json").read_text())
        ev_path = Path(run) / "evaluation.json"
        ev = json.loads(ev_path.read_text()) if ev_path.is_file() else {}
        rows.append({**_row(p, run, rep, ev), "cpu_seconds": cpu})
        print(json.dumps(rows[-1]))
    if args.synthetic:
        out = ROOT / "bench-out" / "synthetic_report.html"
        cpu = time.process_time()
        row = synthetic(args.synthetic, args.texels, args.height_mm, args.noise, args.lights, options, out)
        rows.append({**row, "cpu_seconds": time.process_time() - cpu})
        print(json.dumps(rows[-1]))
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    print(write(args.name, {"machine": machine(), "pages": rows, "peak_rss_gb": peak_gb}))


if __name__ == "__main__":
    main()
