"""The command line as a user meets it: outputs, one-line errors with exit status 2, kill -9 and --resume."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from inkopt import charts
from inkopt.cli import main
from inkopt.model import InkTable, Volume

INKOPT = [sys.executable, "-m", "inkopt.cli"]


def small_volume(tmp_path, **kw):
    rng = np.random.default_rng(0)
    m = rng.dirichlet(np.ones(5), size=(4, 5, 6)).astype(np.float32)
    v = Volume.from_mixture(voxel_mm=(0.0847,) * 3, mixture=m, inks=InkTable.parse("vero-cmykw"), **kw)
    path = tmp_path / "v.npz"
    v.save(path)
    return path


def test_render_json_out_and_adjoint(tmp_path, capsys):
    path = small_volume(tmp_path)
    assert (
        main(
            [
                "render",
                str(path),
                "--spp",
                "4",
                "--seed",
                "1",
                "--face",
                "top",
                "--json",
                "--out",
                str(tmp_path / "o.npz"),
            ]
        )
        == 0
    )
    info = json.loads(capsys.readouterr().out)
    assert info["texels"] == 30 and info["paths"] == 30 * 4 * 3 and len(info["mean_rgb"]) == 3
    assert {"seconds", "events", "spp"} <= set(info)
    out = np.load(tmp_path / "o.npz")
    assert out["rgb"].shape == (30, 3) and out["position_mm"].shape == (30, 3)
    np.testing.assert_allclose(out["rgb"].mean(0), info["mean_rgb"], rtol=1e-5)
    np.testing.assert_array_equal(out["normal"], np.tile([0, 0, 1], (30, 1)))
    np.save(tmp_path / "adj.npy", np.ones((30, 3), np.float32))
    assert (
        main(
            [
                "render",
                str(path),
                "--spp",
                "4",
                "--face",
                "top",
                "--json",
                "--adjoint",
                str(tmp_path / "adj.npy"),
                "--out",
                str(tmp_path / "g.npz"),
            ]
        )
        == 0
    )
    g = np.load(tmp_path / "g.npz")
    assert g["grad_sigma_s"].shape == (4, 5, 6, 3) and g["grad_sigma_a"].shape == (4, 5, 6, 3)
    # More absorption anywhere near the top can only darken the top face: d(sum c)/d sigma_a <= 0 on average.
    assert g["grad_sigma_a"][-1].mean() < 0


def _bad_volume(tmp_path, name, **arrays):
    base = {
        "voxel_mm": np.array([0.1, 0.1, 0.1]),
        "sigma_s": np.ones((2, 3, 4, 3), np.float32),
        "sigma_a": np.ones((2, 3, 4, 3), np.float32),
    }
    base.update(arrays)
    base = {k: v for k, v in base.items() if v is not None}
    p = tmp_path / f"{name}.npz"
    np.savez(p, **base)
    return p


@pytest.mark.parametrize(
    "name,arrays,needle",
    [
        ("negative", {"sigma_a": -np.ones((2, 3, 4, 3), np.float32)}, "negative"),
        ("nan", {"sigma_s": np.full((2, 3, 4, 3), np.nan, np.float32)}, "NaN"),
        ("shape", {"sigma_s": np.ones((2, 3, 4), np.float32)}, "shape"),
        ("mismatch", {"sigma_a": np.ones((2, 3, 5, 3), np.float32)}, "differ"),
        ("zero_voxel", {"voxel_mm": np.array([0.1, 0.0, 0.1])}, "voxel_mm"),
        ("boundary", {"boundary": np.array("torus")}, "boundary"),
        ("missing", {"sigma_a": None}, "sigma_a"),
        ("huge", {"sigma_s": None, "sigma_a": None, "labels": np.zeros((1, 1, 1), np.uint8)}, "ink table"),
    ],
)
def test_render_bad_input_is_one_line_exit_2(tmp_path, name, arrays, needle):
    p = _bad_volume(tmp_path, name, **arrays)
    r = subprocess.run(INKOPT + ["render", str(p), "--json"], capture_output=True, text=True)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("inkopt: error:") and needle in lines[0], r.stderr


def test_render_refuses_volume_too_big_for_memory(tmp_path):
    p = small_volume(tmp_path)
    env = {**os.environ, "INKOPT_MAX_VOLUME_BYTES": "1000"}
    r = subprocess.run(INKOPT + ["render", str(p)], capture_output=True, text=True, env=env)
    assert r.returncode == 2 and "GiB" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_render_missing_and_garbage_files(tmp_path):
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    for f in (tmp_path / "nope.npz", tmp_path / "junk.npz"):
        r = subprocess.run(INKOPT + ["render", str(f)], capture_output=True, text=True)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1


@pytest.fixture
def chart(tmp_path):
    return charts.save(charts.colour_chart(48, 32), tmp_path / "chart.png")


def test_slab_bad_input(tmp_path, chart):
    cases = [
        (["slab", str(tmp_path / "none.png"), "--size-mm", "2x1.333x0.5"], "does not exist"),
        (["slab", str(chart), "--size-mm", "2x1x0.5"], "aspect"),
        (["slab", str(chart), "--size-mm", "2x1.333"], "size-mm"),
        (["slab", str(chart), "--size-mm", "2x1.333x0.5", "--inks", "cyan,unobtainium"], "unknown ink"),
        (["slab", str(chart), "--size-mm", "2x1.333x0.5", "--gamma", "1,2"], "gamma"),
        (["slab", str(chart), "--size-mm", "2x1.333x0.5", "--decay", "1"], "decay"),
        (["slab", str(chart), "--size-mm", "2x1.333x0.5", "--adjoint-ema", "1"], "--adjoint-ema must lie"),
    ]
    for args, needle in cases:
        out = tmp_path / "run"
        r = subprocess.run(INKOPT + args + ["--out", str(out)], capture_output=True, text=True)
        assert r.returncode == 2 and needle in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert not out.exists()  # nothing half-written


def test_slab_outputs(tmp_path, chart):
    out = tmp_path / "run"
    r = subprocess.run(
        INKOPT
        + [
            "slab",
            str(chart),
            "--bottom",
            str(chart),
            "--size-mm",
            "2x1.333x0.5",
            "--out",
            str(out),
            "--iterations",
            "4",
            "--spp",
            "2",
            "--eval-spp",
            "8",
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    rep = json.loads((out / "report.json").read_text())
    for k in (
        "initial_delta_e76_mean",
        "delta_e76_mean",
        "delta_e76_p95",
        "delta_e2000_mean",
        "loss",
        "e1",
        "e2",
        "e3",
        "iterations",
        "spp",
        "seconds",
        "ssim",
    ):
        assert k in rep and np.isfinite(rep[k]), k
    assert (rep["adjoint_ema"], rep["smooth"]) == (0.8, 1.5)  # the slab defaults (OptimizeConfig.for_scene)
    for f in ("volume.npz", "scene.npz", "face_top.png", "face_bottom.png", "loss.png", "checkpoint.npz"):
        assert (out / f).is_file(), f
    vol = Volume.load(out / "volume.npz")
    assert vol.form == "mixture" and vol.shape == (6, 16, 24)
    np.testing.assert_allclose(vol.mixture.sum(-1), 1, atol=1e-5)
    # The result renders with `inkopt render`.
    r2 = subprocess.run(
        INKOPT + ["render", str(out / "volume.npz"), "--spp", "1", "--json"], capture_output=True, text=True
    )
    assert r2.returncode == 0 and json.loads(r2.stdout)["texels"] > 0


def test_slab_survives_kill_9_and_resumes_exactly(tmp_path, chart):
    """A run killed with SIGKILL loses at most the iterations since its last checkpoint; --resume then ends
    exactly where an uninterrupted run ends (renders and gradients are deterministic)."""
    args = [
        "slab",
        str(chart),
        "--size-mm",
        "2x1.333x0.5",
        "--iterations",
        "24",
        "--spp",
        "2",
        "--eval-spp",
        "4",
        "--checkpoint-every",
        "3",
        "--threads",
        "2",
    ]
    ref = tmp_path / "ref"
    assert subprocess.run(INKOPT + args + ["--out", str(ref)], capture_output=True).returncode == 0
    out = tmp_path / "killed"
    proc = subprocess.Popen(INKOPT + args + ["--out", str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    while time.time() < deadline:
        ck = out / "checkpoint.npz"
        if ck.is_file():
            try:
                if int(np.load(ck)["iteration"]) >= 6:
                    break
            except Exception:  # being replaced right now: atomic rename means a retry sees a whole file
                pass
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done_before = int(np.load(out / "checkpoint.npz")["iteration"])
    assert 6 <= done_before <= 24
    r = subprocess.run(INKOPT + args + ["--out", str(out), "--resume"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    a = np.load(ref / "volume.npz")["mixture"]
    b = np.load(out / "volume.npz")["mixture"]
    np.testing.assert_array_equal(a, b)
    assert not list(out.glob("*.tmp*"))  # no temporary files left behind


def test_eval_spp_below_one_is_refused(tmp_path, capsys):
    """--eval-spp 0 is not silently taken as "adaptive": one line, exit 2, nothing written."""
    from PIL import Image

    Image.new("RGB", (12, 8), (200, 30, 30)).save(tmp_path / "p.png")
    code = main(["slab", str(tmp_path / "p.png"), "--size-mm", "1.5x1x0.5", "--out", str(tmp_path / "r"),
                 "--eval-spp", "0"])  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--eval-spp must be at least 1" in err[0]
    assert not (tmp_path / "r").exists()


def test_figure_texel_sample_is_taken_and_checked(tmp_path, capsys):
    """--figure-texel-sample N measures the start's and the baseline's figures on N texels (report.json says so);
    1 is refused in one line, exit 2, nothing written."""
    from PIL import Image

    Image.new("RGB", (12, 8), (200, 30, 30)).save(tmp_path / "p.png")
    args = ["slab", str(tmp_path / "p.png"), "--size-mm", "1.5x1x0.5", "--iterations", "1", "--spp", "2"]
    code = main([*args, "--out", str(tmp_path / "bad"), "--figure-texel-sample", "1"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "figure_texel_sample" in err[0].replace("-", "_"), err
    assert not (tmp_path / "bad").exists()
    assert main([*args, "--out", str(tmp_path / "r"), "--figure-texel-sample", "40"]) == 0
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert report["initial_texel_sample"]["sample"]["texels"] == 40
