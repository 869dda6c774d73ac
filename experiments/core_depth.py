"""How deep must the band of free voxels be, and which fixed mixture must fill the core below it, for a mesh to
print as it does with every voxel free? Optimises Spot (20 mm by default) at equal iterations with every voxel free
and with bands of depth D (``--shell-mm D``) over cores C (``--core C``), evaluates every result noise-free
(``inkopt evaluate``: a texel sample with its standard errors, no baselines) and writes
experiments/results/core_depth.json (one entry per cell, kept across invocations) and a table.

    .venv/bin/python experiments/core_depth.py [--out bench-out/core] [--height-mm 20] [--dpi 150]
        [--iterations 60] [--cells free,1:white,1:start,1:deep,0.5:deep,2:deep,0.25:deep,1:grey]

A cell is "free" (every voxel free) or "D:C": band depth D mm and core C, one of ``white``, ``start`` (the
optimiser's 97 % white start), ``deep`` (the mean mixture of the every-voxel-free result's voxels deeper than
``--deep-mm``, measured from the "free" cell's run of the same settings, which therefore runs first), ``grey``
(``GREY``) or explicit shares ``ink=share+ink=share`` ("+" for ","). Runs whose report.json exists are not re-run,
evaluations whose file exists are not redone (delete them to redo). The "free" cell also records the mean mixture
of its voxels deeper than 0.25, 0.5, 1, 1.5 and 2 mm (``deep_mixture``): what the optimiser settles to below a band.
"""

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import add_study_entry, machine, provenance  # noqa: E402

SPOT = Path(__file__).resolve().parents[2] / "shared" / "data" / "spot" / "spot.obj"  # ../shared beside the repo
RESULT = "core_depth.json"
GREY = "white=0.5,black=0.5"
DEPTHS_MM = (0.25, 0.5, 1.0, 1.5, 2.0)
FIGURES = ("delta_e76_mean_corrected", "delta_e2000_mean", "ssim")


def deep_mixture(run_dir: Path, depths_mm=DEPTHS_MM) -> dict:
    """{depth mm: {"voxels": n, "mixture": {ink: mean share}}}: the mean mixture of a result's inside voxels
    deeper than each depth (Euclidean distance from the voxel centre to the nearest outside voxel's centre, minus
    half a voxel: the depth of ``--shell-mm`` to within half a voxel)."""
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


def optimize(a, d: Path, depth: str | None, core: str | None) -> None:
    cmd = [sys.executable, "-m", "inkopt", "optimize", str(SPOT), "--height-mm", f"{a.height_mm:g}"]
    cmd += ["--dpi", f"{a.dpi:g}", "--out", str(d), "--iterations", str(a.iterations), "--seed", "0"]
    cmd += ["--threads", str(a.threads), "--resume"]
    if depth is not None:
        cmd += ["--shell-mm", depth, "--core", core]
    print("$ inkopt " + " ".join(cmd[3:]), flush=True)
    subprocess.run(cmd, check=True)


def evaluate(a, d: Path) -> dict:
    """The continuous result's figures of ``inkopt evaluate`` (noise-free; a texel sample with standard errors)."""
    path = d / "core_evaluation.json"
    if not path.is_file():
        cmd = [sys.executable, "-m", "inkopt", "evaluate", str(d), "--no-baselines", "--seed", "0"]
        cmd += ["--threads", str(a.threads), "--out", str(path)]
        cmd += ["--texel-sample", str(a.texel_sample)]
        print("$ inkopt " + " ".join(cmd[3:]), flush=True)
        subprocess.run(cmd, check=True)
    return json.loads(path.read_text())


def cell_entry(a, d: Path, ev: dict, core: str | None) -> dict:
    rep = json.loads((d / "report.json").read_text())
    cont = ev["continuous"]
    keep = ("free_voxels", "inside_voxels", "seconds_per_iteration", "peak_rss_gb", "iterations", "time_split")
    return {
        **{k: rep.get(k) for k in keep},
        "shell_mm": rep.get("shell_mm"),
        "core": core,
        "core_shares": rep.get("core_shares"),
        "evaluation": {
            k: cont.get(k) for k in (*FIGURES, "stderr", "delta_e76_noise", "events_per_path", "spp", "seconds")
        },
        "evaluation_texels": ev.get("texels"),
        "texel_sample": ev.get("texel_sample"),
        "printed": {k: (ev.get("quantized") or {}).get(k) for k in (*FIGURES, "stderr", "delta_e76_noise")},
        "settings": {"height_mm": a.height_mm, "dpi": a.dpi, "iterations": a.iterations, "seed": 0},
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
        "--texel-sample",
        type=int,
        default=0,
        help="evaluate's --texel-sample (default 0: every texel, so that cells differ by their results only, not by "
        "a texel sample's error; the figures' noise is then the renders' alone)",
    )
    ap.add_argument("--cells", default="free,1:white,1:start,1:deep,0.5:deep,2:deep,0.25:deep,1:grey")
    a = ap.parse_args()
    prefix = Path(a.out) / f"spot{a.height_mm:g}_{a.dpi:g}dpi_{a.iterations}it"
    deep = None
    for cell in a.cells.split(","):
        depth, _, core = cell.partition(":")
        d = Path(f"{prefix}_{cell.replace(':', '_').replace('=', '').replace('+', '_')}")
        c = None if depth == "free" else core_arg(core, deep, a.deep_mm)
        if not (d / "report.json").is_file():
            optimize(a, d, None if depth == "free" else depth, c)
        entry = cell_entry(a, d, evaluate(a, d), core if c is None else f"{core} ({c})")
        if depth == "free":
            deep = entry["deep_mixture"] = deep_mixture(d)
        key = f"spot{a.height_mm:g}mm_{a.dpi:g}dpi_{a.iterations}it/{cell}"
        add_study_entry(RESULT, key, entry)
        ev = entry["evaluation"]
        se = (ev.get("stderr") or {}).get("delta_e76_mean_corrected", ev.get("delta_e76_noise"))
        print(
            f"{key}: ΔE76 {ev['delta_e76_mean_corrected']:.2f} (± {se}), "
            f"ΔE2000 {ev['delta_e2000_mean']:.2f}, SSIM {ev['ssim']:.3f}, "
            f"{entry['seconds_per_iteration']:.1f} s/iteration, {ev.get('events_per_path')} events/path",
            flush=True,
        )


if __name__ == "__main__":
    main()
