"""Fixtures of the soft-proof tests: a small evaluated mesh run (a two-coloured ball) and a small evaluated slab
run, each made once per test session through the command line, with their pages; the same with script planted in
every user string the command line takes (``hostile_*_run``: payloads.py), and then in every field of their files
(``planted_runs``)."""

import contextlib
import dataclasses
import itertools
import json
import re
import shutil

import numpy as np
import pytest
import trimesh
from PIL import Image
from proof.payloads import FILE_PAYLOADS, PAYLOADS

from inkopt import charts, cli
from inkopt.evaluation.colour_table import colour_table
from inkopt.evaluation.evaluate import evaluate_run
from inkopt.evaluation.options import EvaluateOptions
from inkopt.model import InkTable
from inkopt.rundir import RunDir

INKS = "cyan,magenta,white"  # three inks: the baselines' colour table is small


def _run(*argv):
    assert cli.main([str(a) for a in argv]) == 0


def _ball(root):
    """A 2 mm ball's PLY in ``root``: cyan above its equator, magenta below (vertex colours)."""
    sph = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    col = np.where(sph.vertices[:, 2:3] > 0, [[0, 200, 230, 255]], [[230, 0, 160, 255]]).astype(np.uint8)
    mesh = root / "ball.ply"
    trimesh.Trimesh(sph.vertices, sph.faces, vertex_colors=col, process=False).export(mesh)
    return mesh


@pytest.fixture(scope="session")
def mesh_run(tmp_path_factory):
    """A 2 mm ball, cyan above its equator and magenta below, optimised briefly, evaluated (baselines included,
    from a 6-patch colour table) and reported."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("INKOPT_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))
        mp.setattr("inkopt.scenes.mesh.scene.VIEW_SIZE", 64)
        root = tmp_path_factory.mktemp("proofmesh")
        mesh = _ball(root)
        run = root / "run"
        _run(
            "optimize",
            mesh,
            "--scale",
            1,
            "--up",
            "z",
            "--out",
            run,
            "--iterations",
            3,
            "--spp",
            2,
            "--eval-spp",
            8,
            "--inks",
            INKS,
        )
        table = colour_table(InkTable.parse(INKS), patch_mm=1.0, step=2, max_stderr=0.5)  # 6 patches
        evaluate_run(run, EvaluateOptions(spp=8, table=table))
        _run("report", run)
    return run


@pytest.fixture(scope="session")
def slab_run(tmp_path_factory):
    """A 2 x 1.333 x 0.5 mm slab with a colour chart on top, optimised briefly and reported before and after
    evaluation (``report_optimised.html``: the optimisation's prediction only)."""
    root = tmp_path_factory.mktemp("proofslab")
    chart = charts.save(charts.colour_chart(48, 32), root / "chart.png")
    run = root / "run"
    _run("slab", chart, "--size-mm", "2x1.333x0.5", "--out", run, "--iterations", 3, "--spp", 2, "--eval-spp", 8)
    _run("report", run, "--out", run / "report_optimised.html")
    _run("evaluate", run, "--spp", 8, "--no-baselines")
    _run("report", run)
    return run


def _hostile_inputs(root):
    """An ink file whose inks cyan, magenta and yellow are named by payloads (white is white; ink names hold no
    '/', as file names do not) and an environment map (uniform radiance 1) whose file name is one."""
    inks = [("cyan", FILE_PAYLOADS[0]), ("magenta", FILE_PAYLOADS[2]), ("yellow", FILE_PAYLOADS[3]), ("white", "white")]
    lib = InkTable.parse("cyan,magenta,yellow,white")
    table = {
        "inks": [{"name": n, "mu_t": list(lib.mu_t[i]), "albedo": list(lib.albedo[i])} for i, (_, n) in enumerate(inks)]
    }
    ink_file = root / "hostile inks.json"
    ink_file.write_text(json.dumps(table))
    light = root / f"{FILE_PAYLOADS[1]}.npy"
    np.save(light, np.ones((8, 16, 3), np.float32))
    return ink_file, light


@pytest.fixture(scope="session")
def hostile_slab_run(tmp_path_factory):
    """slab_run's slab with payloads in its ink names, lighting file name, picture file name and run directory
    name; evaluated (no baselines) and reported."""
    root = tmp_path_factory.mktemp("hostileslab")
    ink_file, light = _hostile_inputs(root)
    chart = charts.save(charts.colour_chart(48, 32), root / f"{FILE_PAYLOADS[0]}.png")
    run = root / f"run{FILE_PAYLOADS[1]}"
    common = ["--inks", ink_file, "--lighting", light]
    _run(
        "slab", chart, "--size-mm", "2x1.333x0.5", "--out", run, "--iterations", 2, "--spp", 2, "--eval-spp", 4, *common
    )
    _run("evaluate", run, "--spp", 4, "--no-baselines", "--lighting", light)
    _run("report", run)
    return run


@pytest.fixture(scope="session")
def hostile_mesh_run(tmp_path_factory):
    """A 2 mm ball (an OBJ with uv coordinates) with payloads in its file name, its texture's file name, its ink
    names, lighting file name and run directory name; evaluated (no baselines) and reported."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("INKOPT_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))
        mp.setattr("inkopt.scenes.mesh.scene.VIEW_SIZE", 64)
        root = tmp_path_factory.mktemp("hostilemesh")
        ink_file, light = _hostile_inputs(root)
        mesh = root / f"{FILE_PAYLOADS[0]}.obj"
        _write_uv_ball(mesh)
        texture = root / f"{FILE_PAYLOADS[2]}.png"
        half = np.zeros((16, 32, 3), np.uint8)
        Image.fromarray(np.concatenate([half + [0, 200, 230], half + [230, 0, 160]]).astype(np.uint8)).save(texture)
        run = root / f"run{FILE_PAYLOADS[2]}"
        args = ["--scale", 1, "--up", "z", "--texture", texture, "--out", run, "--iterations", 2, "--spp", 2]
        _run("optimize", mesh, *args, "--eval-spp", 4, "--inks", ink_file, "--lighting", light)
        _run("evaluate", run, "--spp", 4, "--no-baselines", "--lighting", light)
        _run("report", run)
    return run


def _write_uv_ball(path):
    """A unit icosphere as an OBJ with spherical uv coordinates (v = 1 at the top)."""
    sph = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    v = sph.vertices
    uv = np.stack(
        [0.5 + np.arctan2(v[:, 1], v[:, 0]) / (2 * np.pi), 0.5 + np.arcsin(np.clip(v[:, 2], -1, 1)) / np.pi], 1
    )
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in v] + [f"vt {a:.6f} {b:.6f}" for a, b in uv]
    lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in sph.faces + 1]
    path.write_text("\n".join(lines) + "\n")


#: fields a page does not show but checks first (the file's version, the digests of the files it was made from)
KEPT = ("format_version", "volume_digest", "quantized_digest")


def _planted(value, payloads):
    """``value`` (a JSON value) with every leaf replaced by the next of ``payloads`` (an endless iterator)."""
    if isinstance(value, dict):
        return {k: v if k in KEPT else _planted(v, payloads) for k, v in value.items()}
    if isinstance(value, list):
        return [_planted(v, payloads) for v in value]
    return next(payloads)


def plant_fields(src, dst, source: bool):
    """A copy ``dst`` of run directory ``src`` with a payload in every field of its files that the page reads:
    every value of report.json and evaluation.json (a baseline named by a payload added), a result named by a
    payload and the lighting in predictions.npz (and its ``source``, which then hides the evaluation, when
    ``source``), a slab's face names in scene.npz. Returns ``dst``."""
    shutil.copytree(src, dst)
    d = RunDir(dst)
    loop = itertools.cycle(PAYLOADS)
    report = json.loads(d.report_path.read_text())
    d.report_path.write_text(json.dumps(_planted(report, loop)))
    ev = json.loads(d.evaluation_path.read_text())
    ev["baselines"] = {FILE_PAYLOADS[0]: ev["quantized"]}
    d.evaluation_path.write_text(json.dumps(_planted(ev, loop)))
    pred = d.load_predictions()
    pred.rgb[FILE_PAYLOADS[2]] = pred.rgb["continuous"]
    pred.spp[FILE_PAYLOADS[2]] = 1
    pred.lighting = {"lighting": PAYLOADS[1], "lighting_rotate_deg": PAYLOADS[2]}
    if source:
        pred.source = PAYLOADS[3]
    d.save_predictions(pred)
    rec = d.load_scene()
    if rec.kind == "slab":
        rec.faces = [FILE_PAYLOADS[1] if f == "top" else f for f in rec.faces]
        rec.pix = {FILE_PAYLOADS[1] if f == "top" else f: p for f, p in rec.pix.items()}
        d.save_scene(rec)
    assert cli.main(["report", str(dst)]) == 0
    return dst


@pytest.fixture(scope="session")
def planted_runs(hostile_slab_run, hostile_mesh_run, tmp_path_factory):
    """The hostile runs with a payload in every field of their files (``plant_fields``): the slab's
    predictions.npz keeps its source (the page shows the evaluation), the mesh's does not."""
    root = tmp_path_factory.mktemp("planted")
    return {
        "slab": plant_fields(hostile_slab_run, root / "slab", source=False),
        "mesh": plant_fields(hostile_mesh_run, root / "mesh", source=True),
    }


def _payload_light(root) -> str:
    """A light file (flat power, 380-780 nm) whose name is a payload; its name is how the page shows it."""
    path = root / f"{FILE_PAYLOADS[0]}.csv"
    path.write_text("\n".join(f"{nm},1" for nm in range(380, 790, 10)) + "\n")
    return str(path)


@pytest.fixture(scope="session")
def spectral_slab_run(tmp_path_factory):
    """A colour chart slab with the library's spectral inks, optimised for D65 and a light file named by a payload,
    evaluated under D65, that file and F11 (no baselines) and reported: the page offers those lights and A."""
    root = tmp_path_factory.mktemp("spectralslab")
    chart = charts.save(charts.colour_chart(24, 16), root / "chart.png")
    run = root / "run"
    light = _payload_light(root)
    args = ["--size-mm", "2x1.333x0.5", "--out", run, "--iterations", 2, "--spp", 2, "--eval-spp", 4]
    _run("slab", chart, *args, "--inks", "vero-cmykw@spectral", "--illuminants", f"D65,{light}")
    _run("evaluate", run, "--spp", 4, "--no-baselines", "--illuminants", f"D65,{light},F11")
    _run("report", run)
    return run


@pytest.fixture(scope="session")
def spectral_mesh_run(tmp_path_factory):
    """mesh_run's two-coloured ball with the library's spectral inks under D65 and A, not evaluated (the page
    shows the optimisation's continuous result under each light)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("INKOPT_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))
        mp.setattr("inkopt.scenes.mesh.scene.VIEW_SIZE", 64)
        root = tmp_path_factory.mktemp("spectralmesh")
        mesh = _ball(root)
        run = root / "run"
        args = ["--scale", 1, "--up", "z", "--out", run, "--iterations", 2, "--spp", 2, "--eval-spp", 4]
        _run("optimize", mesh, *args, "--inks", "vero-cmykw@spectral", "--illuminants", "D65,A")
        _run("report", run)
    return run


#: the light names ``planted_spectral_run`` gives predictions.npz: payloads and a name JavaScript objects hold
PLANTED_LIGHTS = (*PAYLOADS[:3], "__proto__")


@pytest.fixture(scope="session")
def planted_spectral_run(spectral_slab_run, tmp_path_factory):
    """spectral_slab_run with predictions.npz's stored lights renamed ``PLANTED_LIGHTS``, reported."""
    run = tmp_path_factory.mktemp("plantedlights") / "run"
    shutil.copytree(spectral_slab_run, run)
    d = RunDir(run)
    pred = d.load_predictions()
    matrices = list(pred.bands.lights.values())  # the evaluation's three, the first again for the fourth
    pred.bands.lights = {n: matrices[i % len(matrices)] for i, n in enumerate(PLANTED_LIGHTS)}
    d.save_predictions(pred)
    _run("report", run)
    return run


def _noisy(run, seed: int):
    """Every result's predicted colours in ``run`` replaced by uniform noise per texel (pictures that compress
    badly, as a large noisy evaluation's do)."""
    d = RunDir(run)
    pred = d.load_predictions()
    rng = np.random.default_rng(seed)
    pred.rgb = {k: rng.uniform(0, 1, v.shape).astype(v.dtype) for k, v in pred.rgb.items()}
    d.save_predictions(pred)


@pytest.fixture(scope="session")
def large_mesh_run(mesh_run, tmp_path_factory):
    """mesh_run drawn on a coarse ball of the same radius (80 triangles about 7 texels a side) with noise for every
    result's colours, reported with the atlas's floor of ``bake.ATLAS_MIN`` pixels a side lifted (as for an
    object whose texels fill that many: the page's own atlas then has two pixels per texel, and any smaller one
    is downsampled). Its pages are written with the floor lifted too (``lifted_floor``)."""
    root = tmp_path_factory.mktemp("largemesh")
    run = root / "run"
    shutil.copytree(mesh_run, run)
    coarse = trimesh.creation.icosphere(subdivisions=1, radius=1.0)
    trimesh.Trimesh(coarse.vertices, coarse.faces, process=False).export(root / "coarse.ply")
    d = RunDir(run)
    rec = d.load_scene()
    rec.mesh = dataclasses.replace(rec.mesh, mesh_path=str(root / "coarse.ply"))
    d.save_scene(rec)
    _noisy(run, 1)
    with lifted_floor():
        _run("report", run)
    return run


@contextlib.contextmanager
def lifted_floor():
    """A context in which the mesh atlas has no floor of pixels a side (``bake.ATLAS_MIN`` 0)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("inkopt.proof.bake.ATLAS_MIN", 0)
        yield


@pytest.fixture(scope="session")
def large_slab_run(slab_run, tmp_path_factory):
    """slab_run with noise for every result's colours, reported."""
    run = tmp_path_factory.mktemp("largeslab") / "run"
    shutil.copytree(slab_run, run)
    _noisy(run, 2)
    _run("report", run)
    return run


def picture_bytes(path) -> int:
    """The bytes of a page's pictures: every data: URL of an image in its data block."""
    text = path.read_text()
    blob = text.split('id="inkopt-data">', 1)[1].split("</script>", 1)[0]
    return sum(len(s) for s in re.findall(r'"(data:image/[a-z]+;base64,[A-Za-z0-9+/=]*)"', blob))


@pytest.fixture(scope="session")
def budget_pages(large_mesh_run, large_slab_run):
    """The large runs' pages written with ``--max-mb`` set to hold their other parts and a third of their
    pictures (``small.html``): {kind: (path, budget in bytes, the default page's bytes)}."""
    pages = {}
    for kind, run in (("mesh", large_mesh_run), ("slab", large_slab_run)):
        full = run / "report.html"
        budget = full.stat().st_size - (2 * picture_bytes(full)) // 3
        with lifted_floor():
            _run("report", run, "--out", run / "small.html", "--max-mb", budget / 1e6)
        pages[kind] = (run / "small.html", budget, full.stat().st_size)
    return pages
