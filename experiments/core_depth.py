"""How deep must the band of free voxels be, and which fixed mixture must fill the core below it, for a mesh to
print as it does with every voxel free? Optimises Spot (20 mm by default) at equal iterations with every voxel free
and with bands of depth D (``--shell-mm D``) over cores C (``--core C``), renders every continuous result on every
texel at the same samples and seed (``evaluate``: noise-corrected ΔE76, ΔE2000, noise-corrected SSIM, events per
path, and each cell's per-texel ΔE76 and ΔE2000 paired against the every-voxel-free result's, with the standard error
of the mean difference) and writes experiments/results/core_depth.json (one entry per cell, kept across
invocations).

    .venv/bin/python experiments/core_depth.py [--out bench-out/core] [--height-mm 20] [--dpi 150]
        [--iterations 60] [--cells free,1:white,1:start,1:deep,0.5:deep,2:deep,0.25:deep,1:grey]
        [--eval-spp 256] [--optimize-only | --thickness-only]

A cell is "free" (every voxel free) or "D:C", either with "@S" for the run's seed S (default 0; "free@1": the
all-free run's spread between seeds, the yardstick of "within noise"): band depth D mm and core C, one of
``white``, ``start`` (the optimiser's 97 % white start), ``deep`` (the mean mixture of the every-voxel-free result's
voxels deeper than ``--deep-mm``: from the "free" cell when it is among the cells, which then runs first, else the
``deep_mixture`` the results file records for the "free" cell of the same settings), ``grey`` (``GREY``) or explicit
shares ``ink=share+ink=share`` ("+" for ","). The runs' own final figures are cut short (``--eval-spp 8``); the
study's are its own paired renders, which need the "free" cell's render. Runs whose report.json exists are not
re-run, renders whose file (core_eval_SPPspp.npz) exists are not redone (delete them to redo). The "free" cell also
records the mean mixture of its voxels deeper than 0.25, 0.5, 1, 1.5 and 2 mm (``deep_mixture``): what the
optimiser settles to below a band.
"""

import argparse
import json
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import add_study_entry, machine, provenance  # noqa: E402

SPOT = Path(__file__).resolve().parents[2] / "shared" / "data" / "spot" / "spot.obj"  # ../shared beside the repo
RESULT = "core_depth.json"
THICK_RESULT = "core_depth_thickness.json"
GREY = "white=0.5,black=0.5"
DEPTHS_MM = (0.25, 0.5, 1.0, 1.5, 2.0)
FIGURES = ("delta_e76_mean_corrected", "delta_e2000_mean", "ssim")
EVAL_SEED = 2**61 + 7  # the figures' render seed, the same for every cell (paired: same texels, same seed)


def deep_mixture(run_dir: Path, depths_mm=DEPTHS_MM) -> dict:
    """{depth mm: {"voxels": n, "mixture": {ink: mean share}, "white_percentiles": {"5": share, ..., "95": share}}}:
    the mean mixture of a result's inside voxels deeper than each depth (Euclidean distance from the voxel centre to
    the nearest outside voxel's centre, minus half a voxel: the depth of ``--shell-mm`` to within half a voxel) and
    the 5th, 25th, 50th, 75th and 95th percentiles of their white share (with a white ink): how far the mean is from
    the typical deep voxel."""
    from scipy.ndimage import distance_transform_edt

    from inkopt.rundir import RunDir

    vol = RunDir(run_dir).load_volume()
    inside = vol.inside_mask()
    depth = distance_transform_edt(inside, sampling=tuple(np.asarray(vol.voxel_mm)[::-1])) - vol.voxel_mm[0] / 2
    m = vol.mixture
    out = {}
    for d in depths_mm:
        sel = inside & (depth > d)
        mean = m[sel].astype(np.float64).mean(0) if sel.any() else np.zeros(m.shape[-1])
        out[f"{d:g}"] = {"voxels": int(sel.sum()), "mixture": {n: float(v) for n, v in zip(vol.inks.names, mean)}}
        if "white" in vol.inks.names and sel.any():
            white = m[sel][:, list(vol.inks.names).index("white")].astype(np.float64)
            out[f"{d:g}"]["white_percentiles"] = {f"{q}": float(np.percentile(white, q)) for q in (5, 25, 50, 75, 95)}
    return out


def core_arg(core: str, deep: dict | None, deep_mm: float) -> str:
    """The ``--core`` value of a cell's core name (``deep``: the free run's mean mixture below ``deep_mm``,
    rounded to 4 decimals and renormalised onto white)."""
    if core == "grey":
        return GREY
    if core != "deep":
        return core.replace("+", ",")
    if deep is None:
        raise SystemExit("the 'deep' core needs the 'free' cell first (its result's deep mixture)")
    mix = {k: round(v, 4) for k, v in deep[f"{deep_mm:g}"]["mixture"].items() if round(v, 4) > 0}
    mix["white"] = round(mix.get("white", 0.0) + 1.0 - sum(mix.values()), 4)
    return ",".join(f"{k}={v:g}" for k, v in mix.items())


def stored_deep_mixture(a) -> dict | None:
    """The ``deep_mixture`` recorded for the "free" cell of ``a``'s settings in the results file, or None."""
    from common import STUDY_RESULTS

    path = STUDY_RESULTS / RESULT
    key = f"spot{a.height_mm:g}mm_{a.dpi:g}dpi_{a.iterations}it/free"
    entry = json.loads(path.read_text())["results"].get(key, {}) if path.is_file() else {}
    return entry.get("deep_mixture")


def optimize(a, d: Path, depth: str | None, core: str | None, seed: int) -> None:
    cmd = [sys.executable, "-m", "inkopt", "optimize", str(SPOT), "--height-mm", f"{a.height_mm:g}"]
    cmd += ["--dpi", f"{a.dpi:g}", "--out", str(d), "--iterations", str(a.iterations), "--seed", str(seed)]
    cmd += ["--threads", str(a.threads), "--resume", "--eval-spp", "8"]  # its own figures unused
    if depth is not None:
        cmd += ["--shell-mm", depth, "--core", core]
    print("$ inkopt " + " ".join(cmd[3:]), flush=True)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, check=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    (d / "optimize_cpu.json").write_text(json.dumps({"cpu_seconds": cpu}))


def evaluate(a, d: Path, ref: Path | None) -> dict:
    """The continuous result's figures at ``a.eval_spp`` samples per texel on every texel, seed ``EVAL_SEED``
    (``evaluation.metrics.prediction_metrics``: ΔE76 corrected for the renders' noise, ΔE2000, SSIM with the
    noise removed from its statistics), the renders' events per path, and with ``ref`` (the every-voxel-free run)
    the paired difference of the per-texel ΔE76 and ΔE2000 with its standard error (over texels: the texels are
    the same, so the difference's error is that of the two renders' noise and the texels' spread of the
    difference). Per-texel values are kept in ``d``/core_eval.npz."""
    from inkopt.color import delta_e76, delta_e2000
    from inkopt.evaluation.metrics import prediction_metrics
    from inkopt.loss import TexelLoss
    from inkopt.render import Renderer
    from inkopt.rundir import RunDir

    cache = d / f"core_eval_{a.eval_spp}spp.npz"
    rd = RunDir(d)
    rec = rd.load_scene()
    loss = TexelLoss(rec.target_rgb, rec.texels.pos_vox)
    if not cache.is_file():
        print(f"rendering {d} at {a.eval_spp} spp", flush=True)
        r = Renderer(rd.load_volume(), a.threads).render(rec.texels, a.eval_spp, seed=EVAL_SEED)
        np.savez(cache, rgb=r.rgb, var_mean=r.var_mean, events_per_path=r.events / max(r.paths, 1), seconds=r.seconds)
    z = np.load(cache)
    m = prediction_metrics(loss, z["rgb"], z["var_mean"]).to_json()
    out = {k: m.get(k) for k in (*FIGURES, "delta_e76_noise", "delta_e76_noise_contribution", "delta_e76_mean")}
    out.update(events_per_path=float(z["events_per_path"]), seconds=float(z["seconds"]), spp=a.eval_spp)
    out["delta_e76_mean_stderr"] = float(np.std(_lab_de(loss, z["rgb"], delta_e76)) / np.sqrt(len(z["rgb"])))
    if ref is not None:
        zr = np.load(ref / f"core_eval_{a.eval_spp}spp.npz")
        for name, fn in (("delta_e76", delta_e76), ("delta_e2000", delta_e2000)):
            diff = _lab_de(loss, z["rgb"], fn) - _lab_de(loss, zr["rgb"], fn)
            out[f"{name}_minus_free"] = float(diff.mean())
            out[f"{name}_minus_free_stderr"] = float(diff.std() / np.sqrt(len(diff)))
            if name == "delta_e76":
                out["delta_e76_minus_free_by_thickness"] = by_thickness(diff, thickness(ref))
    return out


#: the bins of ``thickness`` (mm): the deepest inside point near a texel, about half the local thickness up to
#: ``THICK_RADIUS_MM``: thinner than 1 mm, 1-2 mm, 2-3 mm, thicker
THICK_BINS_MM = (0.5, 1.0, 1.5)
THICK_RADIUS_MM = 1.5


def thickness(free_dir: Path) -> np.ndarray:
    """(I,) float64 mm: for each texel of the every-voxel-free run in ``free_dir`` the largest depth (as
    ``deep_mixture``'s, from the voxel centre to the nearest outside voxel's centre) of the inside voxels in the cube
    of +-``THICK_RADIUS_MM`` around its voxel: about half the object's thickness there for features thinner than twice
    the radius (an ear, a horn), the radius or more in the body. From the run's scene.npz, whose free mask is the
    inside when every voxel is free (written at the run's start); cached beside it (thickness.npy)."""
    from scipy.ndimage import distance_transform_edt, maximum_filter

    from inkopt.rundir import RunDir

    cache = free_dir / "thickness.npy"
    if cache.is_file():
        return np.load(cache)
    rec = RunDir(free_dir).load_scene()
    vox = np.asarray(rec.mesh.voxel_mm, np.float64)[::-1]  # (z, y, x) mm
    depth = distance_transform_edt(rec.free_mask, sampling=tuple(vox))
    near = maximum_filter(depth.astype(np.float32), size=[2 * int(np.ceil(THICK_RADIUS_MM / v)) + 1 for v in vox])
    z, y, x = rec.texels.voxel.T
    out = near[z, y, x].astype(np.float64)
    np.save(cache, out)
    return out


def by_thickness(diff: np.ndarray | None, thick: np.ndarray) -> dict:
    """The paired per-texel difference ``diff`` binned by ``thickness``: {"<0.5" | "0.5-1" | ... | ">=1.5":
    {"texels": n, "mean": mean difference, "stderr": its standard error}} (whether a thin band loses colour where
    the object is thin and light could travel sideways through the core); ``diff`` None: the texel counts only."""
    edges = (0.0, *THICK_BINS_MM, np.inf)
    out = {}
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = (thick >= lo) & (thick < hi)
        name = f"<{hi:g}" if lo == 0 else (f">={lo:g}" if np.isinf(hi) else f"{lo:g}-{hi:g}")
        n = int(sel.sum())
        out[name] = {"texels": n}
        if diff is not None:
            out[name]["mean"] = float(diff[sel].mean()) if n else None
            out[name]["stderr"] = float(diff[sel].std() / np.sqrt(n)) if n > 1 else None
    return out


def _lab_de(loss, rgb, fn) -> np.ndarray:
    from inkopt.color import linear_to_lab

    return fn(linear_to_lab(np.asarray(rgb, np.float64)), loss.target_lab)


def cell_entry(a, d: Path, ev: dict, core: str | None, seed: int) -> dict:
    rep = json.loads((d / "report.json").read_text())
    ck = np.load(d / "checkpoint.npz")
    keep = ("free_voxels", "inside_voxels", "seconds_per_iteration", "peak_rss_gb", "iterations", "time_split")
    cpu = d / "optimize_cpu.json"  # the optimize process's CPU seconds, set-up and its own short figures included
    cpu = json.loads(cpu.read_text())["cpu_seconds"] if cpu.is_file() else None
    return {
        **{k: rep.get(k) for k in keep},
        "cpu_seconds": cpu,
        "cpu_seconds_per_iteration": None if cpu is None else cpu / max(rep.get("iterations") or 1, 1),
        "shell_mm": rep.get("shell_mm"),
        "core": core,
        "core_shares": rep.get("core_shares"),
        "evaluation": ev,
        "training_delta_e76": [round(float(v), 3) for v in ck["hist_delta_e76"]],
        "step_scale": float(ck["opt_v"][0]),  # the exponentiated-gradient step's frozen scale s (lr / s moves)
        "evaluation_texels": len(np.load(d / f"core_eval_{a.eval_spp}spp.npz")["rgb"]),
        "settings": {"height_mm": a.height_mm, "dpi": a.dpi, "iterations": a.iterations, "seed": seed},
        **machine(),
        **provenance(),
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="bench-out/core")
    ap.add_argument("--height-mm", type=float, default=20.0)
    ap.add_argument("--dpi", type=float, default=150.0)
    ap.add_argument("--iterations", type=int, default=60)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--deep-mm", type=float, default=1.0, help="the 'deep' core: the mean below this depth")
    ap.add_argument(
        "--eval-spp",
        type=int,
        default=256,
        help="the figures' samples per texel, the same for every cell (default 256)",
    )
    ap.add_argument("--cells", default="free,1:white,1:start,1:deep,0.5:deep,2:deep,0.25:deep,1:grey")
    ap.add_argument(
        "--optimize-only",
        action="store_true",
        help="run the cells' optimisations and stop (another invocation renders them): cells run side by side",
    )
    ap.add_argument(
        "--thickness-only",
        action="store_true",
        help="the 'free' cell's texels by the object's local half-thickness (``thickness``; its scene.npz only), "
        f"into experiments/results/{THICK_RESULT}",
    )
    a = ap.parse_args()
    prefix = Path(a.out) / f"spot{a.height_mm:g}_{a.dpi:g}dpi_{a.iterations}it"
    deep, ref = stored_deep_mixture(a), Path(f"{prefix}_free")
    if a.thickness_only:
        counts = by_thickness(None, thickness(ref))
        entry = {"texels_by_half_thickness_mm": counts, "radius_mm": THICK_RADIUS_MM, **provenance()}
        add_study_entry(THICK_RESULT, f"spot{a.height_mm:g}mm_{a.dpi:g}dpi", entry)
        print(json.dumps(counts))
        return
    for cell in a.cells.split(","):
        setting, _, seed = cell.partition("@")
        depth, _, core = setting.partition(":")
        seed = int(seed or 0)
        d = Path(f"{prefix}_{cell.replace(':', '_').replace('=', '').replace('+', '_').replace('@', '_seed')}")
        c = None if depth == "free" else core_arg(core, deep, a.deep_mm)
        if not (d / "report.json").is_file():
            optimize(a, d, None if depth == "free" else depth, c, seed)
        if a.optimize_only:
            continue
        ev = evaluate(a, d, None if cell == "free" else ref)
        entry = cell_entry(a, d, ev, core if c in (None, core) else f"{core} ({c})", seed)
        if cell == "free":
            deep = entry["deep_mixture"] = deep_mixture(d)
        key = f"spot{a.height_mm:g}mm_{a.dpi:g}dpi_{a.iterations}it/{cell}"
        add_study_entry(RESULT, key, entry)
        ev = entry["evaluation"]
        gap = ev.get("delta_e76_minus_free")
        gap = "" if gap is None else f" ({gap:+.3f} ± {ev['delta_e76_minus_free_stderr']:.3f} against all free)"
        print(
            f"{key}: ΔE76 {ev['delta_e76_mean_corrected']:.2f}{gap}, "
            f"ΔE2000 {ev['delta_e2000_mean']:.2f}, SSIM {ev['ssim']:.3f}, "
            f"{entry['seconds_per_iteration']:.1f} s/iteration, {ev.get('events_per_path')} events/path",
            flush=True,
        )


if __name__ == "__main__":
    main()
