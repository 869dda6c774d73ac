"""Outputs tied to their inputs: quantized.npz, slice manifests and evaluation.json record the digest of the
volume.npz (and quantized.npz) they were made from; export and evaluate refuse a stale quantized volume in one line,
and a new run into an old directory removes what it would make stale."""

import json
import os

import numpy as np

from inkopt import charts
from inkopt.cli import main
from inkopt.io import file_digest, save_npz
from inkopt.model import InkTable, Texels, Volume
from inkopt.rundir import RunDir

V300 = 25.4 / 300


def make_run(d, shape=(4, 8, 10), seed=0):
    """A run directory as ``inkopt slab`` leaves it (volume.npz of random mixtures, scene.npz of a grey target)."""
    inks = InkTable.parse("vero-cmykw")
    mix = np.random.default_rng(seed).dirichlet(np.ones(len(inks.names)), size=shape).astype(np.float32)
    d.mkdir(parents=True, exist_ok=True)
    Volume.from_mixture(voxel_mm=[V300] * 3, mixture=mix, inks=inks).save(d / "volume.npz")
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


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_quantized_and_slices_record_their_sources(tmp_path, capsys):
    d = tmp_path / "r"
    make_run(d)
    assert run(capsys, "quantize", d)[0] == 0
    rd = RunDir(d)
    with np.load(d / "quantized.npz") as z:
        assert str(z["volume_digest"]) == file_digest(d / "volume.npz")
    assert run(capsys, "export", d)[0] == 0
    man = json.loads((d / "slices" / "manifest.json").read_text())
    assert man["volume_digest"] == file_digest(d / "volume.npz")
    assert man["quantized_digest"] == file_digest(d / "quantized.npz")
    for fmt in (["--format", "gcvf"], ["--format", "3mf"], ["--format", "3mf", "--labels"]):
        assert run(capsys, "export", d, *fmt)[0] == 0
    assert rd.remove_stale() == []  # everything was made from this volume.npz: nothing goes
    make_run(d, seed=1)  # a resumed run writes a new volume.npz: what was made from the old one goes
    gone = ["quantized.npz", "quantized_labels.layers", "slices", "slices.gcvf", "mixture.3mf", "quantized.3mf"]
    assert rd.remove_stale() == gone


def test_export_and_evaluate_refuse_a_stale_quantized_volume(tmp_path, capsys):
    d = tmp_path / "r"
    make_run(d)
    assert run(capsys, "quantize", d)[0] == 0
    assert run(capsys, "export", d)[0] == 0
    before = sorted(p.name for p in (d / "slices").iterdir())
    stamp = (d / "slices" / "manifest.json").stat().st_mtime_ns
    make_run(d, shape=(3, 6, 8), seed=1)  # the run was redone after quantizing: a different volume.npz
    for argv in (["export", d], ["export", d, "--format", "gcvf"], ["evaluate", d, "--spp", "2", "--no-baselines"]):
        code, out, err = run(capsys, *argv)
        lines = err.strip().splitlines()
        assert code == 2 and len(lines) == 1, err
        assert "was made from another volume.npz" in lines[0] and "inkopt quantize" in lines[0]
    assert sorted(p.name for p in (d / "slices").iterdir()) == before
    assert (d / "slices" / "manifest.json").stat().st_mtime_ns == stamp
    assert not (d / "slices.gcvf").exists() and not (d / "evaluation.json").exists()


def test_undigested_quantized_volume_older_than_the_volume_is_refused(tmp_path, capsys):
    d = tmp_path / "r"
    make_run(d)
    assert run(capsys, "quantize", d)[0] == 0
    with np.load(d / "quantized.npz") as z:  # as an older inkopt wrote it: no digest
        arrays = {k: z[k] for k in z.files if k != "volume_digest"}
    np.savez(d / "quantized.npz", **arrays)
    assert run(capsys, "export", d)[0] == 0  # newer than volume.npz: accepted
    t = (d / "quantized.npz").stat().st_mtime
    os.utime(d / "volume.npz", (t + 10, t + 10))
    code, _, err = run(capsys, "export", d)
    assert code == 2 and "is older than volume.npz" in err


def test_a_new_run_removes_what_it_would_make_stale(tmp_path, capsys):
    d = tmp_path / "r"
    make_run(d)
    assert run(capsys, "quantize", d)[0] == 0
    assert run(capsys, "export", d)[0] == 0
    (d / "evaluation.json").write_text(json.dumps({"volume_digest": "sha256:old"}))
    charts.save(charts.colour_chart(24, 16), tmp_path / "chart.png")
    argv = ["slab", tmp_path / "chart.png", "--size-mm", "2x1.333x0.5", "--out", d, "--iterations", "1"]
    code, out, err = run(capsys, *argv, "--spp", "1", "--forward-spp", "1", "--eval-spp", "2", "--threads", "1")
    assert code == 0, err
    gone = [line for line in err.splitlines() if line.startswith("removed the outputs of an earlier run")]
    assert len(gone) == 1
    for name in ("quantized.npz", "quantized_labels.layers", "slices", "evaluation.json", "volume.npz"):
        assert name in gone[0]
    left = {p.name for p in d.iterdir()}
    assert not left & {"quantized.npz", "quantized_labels.layers", "slices", "evaluation.json"}
    assert {"volume.npz", "report.json", "scene.npz"} <= left


def test_inspect_refuses_a_package_of_a_stale_quantized_volume(tmp_path, capsys):
    """A package made from quantized.npz is current only while quantized.npz is still made from volume.npz."""
    d = tmp_path / "r"
    make_run(d)
    assert run(capsys, "quantize", d)[0] == 0
    assert run(capsys, "export", d, "--format", "gcvf")[0] == 0
    assert run(capsys, "inspect", d / "slices.gcvf", "--run", d)[0] == 0
    make_run(d, seed=1)  # volume.npz rewritten by something that left the derived outputs in place
    code, _, err = run(capsys, "inspect", d / "slices.gcvf", "--run", d)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "was made from another volume.npz" in err
