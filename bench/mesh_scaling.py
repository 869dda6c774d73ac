"""The scaling table of the mesh pipeline (docs/performance.md), from the results of `bench/bench_mesh.py` at
several heights.

    python bench/bench_mesh.py 10 --iterations 2     # and 20, 40, 60 (one process each)
    python bench/mesh_scaling.py [10 20 40 60mm_shell2 ...]

Reads bench/results/mesh_<height>mm.json (an argument with letters names the file stem after "mesh_", e.g.
60mm_shell2 for a run with ``--out bench/results/mesh_60mm_shell2.json``) and prints a markdown table (grid voxels,
inside voxels, texels, events per path, seconds per iteration split into render / gradient / rest, CPU seconds,
peak memory) and how each cost grows with size between successive heights (the exponent k in cost ~
height^k).
"""

import json
import math
import sys
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


def load(arg: str) -> dict:
    stem = f"{float(arg):g}mm" if arg.replace(".", "", 1).isdigit() else arg
    path = RESULTS / f"mesh_{stem}.json"
    if not path.is_file():
        raise SystemExit(f"{path} is missing: run python bench/bench_mesh.py HEIGHT --iterations 2 [--out {path}]")
    return json.loads(path.read_text())


def row(d: dict) -> dict:
    t = d["time_split"]
    rest = d["seconds_per_iteration"] - t["render_s"] - t["gradient_s"]
    ev = d.get("events_per_path") or {}
    label = f"{d['height_mm']:g} mm" + (f", --shell-mm {d['shell_mm']:g}" if d.get("shell_mm") else "")
    return {
        "label": label,
        "height": d["height_mm"],
        "grid": d["voxels"],
        "inside": d["inside_voxels"],
        "free": d["free_voxels"],
        "texels": d["texels"],
        "events": ev.get("forward"),
        "s_it": d["seconds_per_iteration"],
        "render": t["render_s"],
        "gradient": t["gradient_s"],
        "rest": rest,
        "cpu": d["cpu_seconds_per_iteration"],
        "gb": d["peak_rss_gb"],
    }


def main(argv) -> None:
    rows = [row(load(a)) for a in argv or ["10", "20", "40", "60"]]
    print(
        "| height | grid voxels | inside (free) voxels | texels | events per path | s per iteration (render / "
        "gradient / rest) | CPU s per iteration | peak memory |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        ev = "–" if r["events"] is None else f"{r['events']:.0f}"
        free = "" if r["free"] == r["inside"] else f" ({r['free'] / 1e6:.2f} M)"
        print(
            f"| {r['label']} | {r['grid'] / 1e6:.1f} M | {r['inside'] / 1e6:.2f} M{free} | {r['texels'] / 1e3:.0f} k "
            f"| {ev} | {r['s_it']:.1f} ({r['render']:.1f} / {r['gradient']:.1f} / {r['rest']:.1f}) "
            f"| {r['cpu']:.0f} | {r['gb']:.2f} GB |"
        )
    print()
    for a, b in zip(rows, rows[1:]):
        if b["height"] == a["height"]:  # another setting at the same height (e.g. a shell): no growth to fit
            continue
        lh = math.log(b["height"] / a["height"])
        k = {key: math.log(b[key] / a[key]) / lh for key in ("inside", "texels", "cpu", "gb") if a[key] and b[key]}
        if a["events"] and b["events"]:
            k["events"] = math.log(b["events"] / a["events"]) / lh
        print(
            f"{a['height']:g} -> {b['height']:g} mm: cost ~ height^k with k = "
            + ", ".join(f"{key} {v:.2f}" for key, v in k.items())
        )


if __name__ == "__main__":
    main(sys.argv[1:])
