"""Tests of the printable-output commands: inkopt quantize, export, evaluate (cli.main and one subprocess)."""

import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from inkopt.cli import main
from inkopt.io import save_npz
from inkopt.model import InkTable, Quantization, Texels, Volume
from inkopt.printing.formats.png_slices import read_png_slices
from inkopt.printing.grid import _enclosing, printer_grid
from inkopt.printing.quantize import quantize

V300 = 25.4 / 300
ROOT = Path(__file__).resolve().parents[2]


def make_run(d, shape=(4, 8, 10), normals=False, inks="vero-cmykw"):
    inks = InkTable.parse(inks)
    mix = np.random.default_rng(0).dirichlet(np.ones(len(inks.names)), size=shape).astype(np.float32)
    kw = {}
    if normals:
        c = np.indices(shape).transpose(1, 2, 3, 0)[..., ::-1] + 0.5 - np.array(shape[::-1]) / 2
        kw = dict(
            inside=np.linalg.norm(c, axis=-1) < min(shape) / 2,
            normals=(c / np.linalg.norm(c, axis=-1, keepdims=True)).astype(np.float32),
        )
    vol = Volume.from_mixture(voxel_mm=[V300] * 3, mixture=mix, inks=inks, **kw)
    d.mkdir(parents=True, exist_ok=True)
    vol.save(d / "volume.npz")
    tex = Texels.box_faces(shape, ["top"])
    ny, nx = shape[1:]
    save_npz(
        d / "scene.npz",
        {
            **tex.to_arrays(),
            "target_rgb": np.full((len(tex), 3), 0.4, np.float32),
            "kind": np.array("slab"),
            "fixed_share": np.zeros(mix.shape, np.float32),
            "faces": np.array(["top"]),
            "pix_top": (np.arange(ny)[::-1, None] * nx + np.arange(nx)).astype(np.int32),
        },
    )
    return vol


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_quantize_writes_renderable_labels(tmp_path, capsys):
    vol = make_run(tmp_path / "r")
    code, out, err = run(capsys, "quantize", tmp_path / "r")
    assert code == 0 and "printer grid 20 x 8 x 13" in out and "cyan" in out, out + err
    q = Volume.load(tmp_path / "r" / "quantized.npz")
    shape_p, vp = printer_grid(vol.shape, vol.voxel_mm)
    # the defaults: count-adaptive with the inks lightest first, seed 0, nearest
    labels, _ = quantize(vol, Quantization("count-adaptive", 0, ink_order="lightness"))
    np.testing.assert_array_equal(q.labels, labels)
    np.testing.assert_allclose(q.voxel_mm, vp)
    assert q.quantization.method == "count-adaptive" and q.quantization.seed == 0
    np.testing.assert_allclose(q.quantization.dpi, [600, 300, 25.4 / 0.027])
    assert q.inks.names == vol.inks.names and q.inside is None and q.normals is None
    # renderable by `inkopt render` (a fresh process, as a user would run it)
    env = {**os.environ, "PYTHONPATH": str(ROOT / "python")}
    proc = subprocess.run(
        [sys.executable, "-m", "inkopt.cli", "render", str(tmp_path / "r" / "quantized.npz"), "--spp", "1", "--json"],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["texels"] == 2 * (20 * 8 + 20 * 13 + 8 * 13) and all(0 < v < 1.2 for v in summary["mean_rgb"])


def test_quantize_options(tmp_path, capsys):
    vol = make_run(tmp_path / "r")
    code, out, err = run(
        capsys,
        "quantize",
        tmp_path / "r",
        "--method",
        "random",
        "--dpi",
        "300x300x600",
        "--seed",
        "4",
        "--upsample",
        "linear",
    )
    assert code == 0, err
    q = Volume.load(tmp_path / "r" / "quantized.npz")
    labels, vp = quantize(vol, Quantization("random", 4, (300, 300, 600), "linear"))
    np.testing.assert_array_equal(q.labels, labels)
    assert q.quantization.method == "random" and q.quantization.upsample == "linear"
    code, _, _ = run(capsys, "quantize", tmp_path / "r", "--layer-um", "14")
    assert code == 0 and Volume.load(tmp_path / "r" / "quantized.npz").voxel_mm[2] == pytest.approx(0.014)


def test_quantize_upsamples_mesh_normals(tmp_path, capsys):
    vol = make_run(tmp_path / "m", shape=(6, 6, 6), normals=True)
    assert run(capsys, "quantize", tmp_path / "m")[0] == 0
    q = Volume.load(tmp_path / "m" / "quantized.npz")
    Z, Y, X = q.labels.shape
    iz, iy, ix = (
        _enclosing(Z, q.voxel_mm[2], 6, V300),
        _enclosing(Y, q.voxel_mm[1], 6, V300),
        _enclosing(X, q.voxel_mm[0], 6, V300),
    )
    np.testing.assert_array_equal(q.normals.dense(), vol.normals.dense()[np.ix_(iz, iy, ix)])
    np.testing.assert_array_equal(q.labels == 255, ~vol.inside.dense()[np.ix_(iz, iy, ix)])
    tex = Texels.for_volume(q)  # one texel per printer surface voxel, from the normals
    assert len(tex) > 0 and np.all(np.abs(np.linalg.norm(tex.normal, axis=1) - 1) < 1e-5)


def test_export_png_slices(tmp_path, capsys):
    make_run(tmp_path / "r")
    assert run(capsys, "export", tmp_path / "r")[0] == 2  # no quantized.npz yet
    assert run(capsys, "quantize", tmp_path / "r")[0] == 0
    q = Volume.load(tmp_path / "r" / "quantized.npz")
    code, out, err = run(
        capsys,
        "export",
        tmp_path / "r",
        "--format",
        "png-slices",
        "--out",
        tmp_path / "s",
        "--printer",
        "j750",
        "--palette",
        '{"white": "#F0F0F0"}',
    )
    assert code == 0, err
    assert len(list((tmp_path / "s").glob("slice_*.png"))) == q.labels.shape[0]
    labels, man = read_png_slices(tmp_path / "s")
    np.testing.assert_array_equal(labels, q.labels)
    assert man["materials"][4]["hex"] == "#F0F0F0" and man["max_materials"] == 6
    code, out, err = run(capsys, "export", tmp_path / "r")  # default: DIR/slices
    assert code == 0 and (tmp_path / "r" / "slices" / "manifest.json").is_file()


def test_export_gcvf(tmp_path, capsys):
    make_run(tmp_path / "r", inks="vero-cmykw+orange")
    assert run(capsys, "quantize", tmp_path / "r")[0] == 0
    q = Volume.load(tmp_path / "r" / "quantized.npz")
    code, out, err = run(capsys, "export", tmp_path / "r", "--format", "gcvf")  # default printer: J750
    assert code == 0, err
    path = tmp_path / "r" / "slices.gcvf"
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
    assert {"ConfigFile.xml", "Mesh.stl", "Zbuffer.png", "MeshBbx.ktn"} <= set(names)
    assert sum(n.startswith("layer_") for n in names) == q.labels.shape[0]
    assert "cyan #00FFFF = VeroCY-V" in out and "orange #FF8000," not in out and f"wrote {path}" in out
    for fmt in (["gcvf"], ["3mf"], ["3mf", "--labels"]):  # the continuous 3MF loads every ink of the table
        code, out, err = run(capsys, "export", tmp_path / "r", "--format", *fmt, "--printer", "j55")
        assert code == 2 and "6 inks" in err and "J55 Prime holds 5" in err and len(err.strip().splitlines()) == 1
    assert not list((tmp_path / "r").glob("*.3mf"))
    code, out, err = run(capsys, "export", tmp_path / "r", "--format", "3mf", "--labels", "--printer", "j850")
    assert code == 0 and "warning:" not in err  # J850 prints 600 x 300 DPI at 27 um: the run's grid


def test_export_refuses_more_inks_than_slots(tmp_path, capsys):
    """Seven inks on a six-slot J750: one line naming the inks and the limit; no folder, no package."""
    inks = "cyan,magenta,yellow,black,white,transparent,orange"
    make_run(tmp_path / "r", shape=(4, 12, 12), inks=inks)
    assert run(capsys, "quantize", tmp_path / "r", "--method", "random")[0] == 0
    assert len(np.unique(Volume.load(tmp_path / "r" / "quantized.npz").labels)) >= 7
    for fmt, out in (("png-slices", "s"), ("gcvf", "p.gcvf")):
        code, _, err = run(
            capsys, "export", tmp_path / "r", "--format", fmt, "--printer", "j750", "--out", tmp_path / out
        )
        lines = err.strip().splitlines()
        assert code == 2 and len(lines) == 1, err
        assert lines[0] == (
            f"inkopt: error: the print uses 7 inks ({inks.replace(',', ', ')}) but Stratasys J750 "
            "holds 6 materials per job; use an ink set of at most 6 inks or a printer with more "
            "material slots (--printer)"
        )
        assert sorted(p.name for p in tmp_path.iterdir()) == ["r"], "nothing written, no temporary left"
    assert run(capsys, "export", tmp_path / "r", "--printer", "j850", "--out", tmp_path / "s")[0] == 0


@pytest.mark.parametrize(
    "argv, message",
    [
        (["quantize", "{tmp}/nope"], "does not exist"),
        (["quantize", "{tmp}/empty"], "volume.npz does not exist"),
        (["quantize", "{tmp}/r", "--method", "floyd"], "unknown quantization --method 'floyd'"),
        (["quantize", "{tmp}/r", "--dpi", "600"], "--dpi"),
        (["quantize", "{tmp}/r", "--dpi", "600x300x900", "--layer-um", "14"], "layer thickness once"),
        (["export", "{tmp}/r", "--format", "gcvf", "--labels"], "--labels goes with --format 3mf"),
        (["export", "{tmp}/r", "--material", "white"], "--material takes INK=NAME"),
        (["export", "{tmp}/r", "--format", "3mf", "--material", "teal=X"], "unknown ink 'teal'"),
        (["inspect", "{tmp}/nope.gcvf"], "does not exist"),
        (["export", "{tmp}/r", "--format", "stl"], "unknown export format"),
        (["export", "{tmp}/r", "--printer", "x9"], "unknown printer"),
        (["export", "{tmp}/r", "--format", "gcvf", "--printer", "x9"], "unknown printer"),
        (["export", "{tmp}/r", "--palette", "{bad"], "--palette is neither a JSON object"),
        (["export", "{tmp}/r", "--palette", "[1]"], "--palette must be a JSON object"),
        (["inspect", "{tmp}/r"], "r/manifest.json is missing or malformed"),
        (["evaluate", "{tmp}/nope"], "does not exist"),
        (["evaluate", "{tmp}/r", "--method", "floyd"], "unknown quantization --method 'floyd'"),
        (["evaluate", "{tmp}/r", "--spp", "0"], "--spp"),
        (["evaluate", "{tmp}/r", "--time-budget", "0"], "--time-budget must be a positive number of seconds"),
        (["evaluate", "{tmp}/r", "--texel-sample", "1"], "--texel-sample must be 0 (every texel) or at least 2"),
        (["evaluate", "{tmp}/r", "--patch-mm", "-1"], "--patch-mm must be a positive thickness"),
    ],
)
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, argv, message):
    make_run(tmp_path / "r")
    (tmp_path / "empty").mkdir()
    code, out, err = run(capsys, *[a.replace("{tmp}", str(tmp_path)) for a in argv])
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("inkopt: error:") and message in lines[0], err


def test_evaluate_cli_json(tmp_path, capsys):
    make_run(tmp_path / "r")
    code, out, err = run(capsys, "evaluate", tmp_path / "r", "--spp", "2", "--no-baselines", "--json")
    assert code == 0, err
    ev = json.loads(out)
    assert ev == json.loads((tmp_path / "r" / "evaluation.json").read_text())
    assert ev["quantized"]["method"] == "count-adaptive" and np.isfinite(ev["quantized"]["delta_e76_mean"])
    assert (tmp_path / "r" / "quantized.npz").is_file() and (tmp_path / "r" / "evaluation_top.png").is_file()
    code, out, err = run(capsys, "evaluate", tmp_path / "r", "--spp", "2", "--no-baselines")
    assert code == 0 and "dE76 mean" in out and "quantized" in out


def test_export_3mf_and_inspect(tmp_path, capsys):
    """export --format 3mf (mixture, --labels), gcvf with --material; inspect prints, --json, --preview; --run
    refuses a package whose source changed since (quantize again with another seed)."""
    make_run(tmp_path / "r")
    assert run(capsys, "quantize", tmp_path / "r")[0] == 0
    code, out, err = run(capsys, "export", tmp_path / "r", "--format", "3mf")
    assert code == 0 and "mixture of cyan" in out and (tmp_path / "r" / "mixture.3mf").is_file(), err
    code, out, err = run(capsys, "export", tmp_path / "r", "--format", "3mf", "--labels")
    assert code == 0 and "labels of" in out and (tmp_path / "r" / "quantized.3mf").is_file(), err
    code, out, err = run(capsys, "export", tmp_path / "r", "--format", "gcvf", "--material", "white=VeroPureWht")
    assert code == 0 and "white #FFFFFF = VeroPureWht" in out, err
    assert run(capsys, "export", tmp_path / "r")[0] == 0
    q = Volume.load(tmp_path / "r" / "quantized.npz")
    for name in ("slices.gcvf", "quantized.3mf", "slices"):
        code, out, err = run(capsys, "inspect", tmp_path / "r" / name, "--run", tmp_path / "r", "--json")
        rep = json.loads(out)
        assert code == 0 and rep["layers"] == q.labels.shape[0], err
        assert sum(m["voxel_count"] for m in rep["materials"]) == int(np.sum(q.labels != 255))
    code, out, err = run(capsys, "inspect", tmp_path / "r" / "mixture.3mf", "--run", tmp_path / "r")
    assert code == 0 and "the parts agree" in out and "made from volume.npz sha256:" in out, err
    code, out, _ = run(capsys, "inspect", tmp_path / "r" / "slices.gcvf", "--preview", tmp_path / "p.png")
    assert code == 0 and (tmp_path / "p.png").is_file() and "VeroPureWht" in out
    assert run(capsys, "quantize", tmp_path / "r", "--seed", "5")[0] == 0
    for name in ("slices.gcvf", "slices"):
        code, out, err = run(capsys, "inspect", tmp_path / "r" / name, "--run", tmp_path / "r")
        assert code == 2 and len(err.strip().splitlines()) == 1 and "is stale" in err and "export it again" in err
