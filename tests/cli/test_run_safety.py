"""A run folder's files are safe from the commands that write beside them: an output never replaces a file its
command did not write (``io.check_output``), a damaged file is called damaged (not stale), and quantized.npz
covers its labels file with a digest every reader checks. Every refusal is one line, exit status 2, nothing
changed."""

import json
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from PIL import Image

from inkopt.cli import main
from inkopt.io import file_digest
from inkopt.model.labelfile import LabelLayersWriter, load_label_file
from inkopt.rundir import RunDir
from inkopt.rundir.lock import LOCK_NAME, Holder

FAST = ["--iterations", "2", "--spp", "1", "--eval-spp", "4", "--threads", "1"]


@pytest.fixture(scope="module")
def done_run(tmp_path_factory):
    """A slab run quantized, evaluated, exported (slices and GCVF) and reported."""
    base = tmp_path_factory.mktemp("run")
    pic = np.random.default_rng(0).uniform(0, 255, (8, 12, 3)).astype(np.uint8)
    Image.fromarray(pic).save(base / "p.png")
    d = base / "r"
    assert main(["slab", str(base / "p.png"), "--size-mm", "1.5x1x0.5", "--out", str(d), *FAST]) == 0
    for argv in (
        ["quantize"],
        ["evaluate", "--spp", "4", "--no-baselines"],
        ["export"],
        ["export", "--format", "gcvf"],
    ):
        assert main([argv[0], str(d), *argv[1:]]) == 0
    assert main(["report", str(d)]) == 0
    return d


@pytest.fixture
def run(done_run, tmp_path, capsys):
    d = tmp_path / "r"
    shutil.copytree(done_run, d)
    capsys.readouterr()
    return d


def refused(capsys, *argv) -> str:
    """The one error line of a command that must fail with exit status 2."""
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("inkopt: error: "), err
    return err[0]


def snapshot(d):
    return {p.relative_to(d): file_digest(p) for p in sorted(d.rglob("*")) if p.is_file()}


@pytest.mark.parametrize(
    "argv, target, what",
    [
        (["report", "{d}", "--out", "{d}/volume.npz"], "volume.npz", "a soft-proof page"),
        (["report", "{d}", "--out", "{d}/face_top.png"], "face_top.png", "a soft-proof page"),
        (["evaluate", "{d}", "--out", "{d}/report.json", "--spp", "2"], "report.json", "an evaluation"),
        (["evaluate", "{d}", "--out", "{d}/scene.json", "--spp", "2"], "scene.json", "an evaluation"),
        (
            ["evaluate", "{d}", "--out", "{d}/face.json", "--spp", "2"],
            "face_top.png",
            "not a picture of the evaluation",
        ),
        (["export", "{d}", "--format", "gcvf", "--out", "{d}/volume.npz"], "volume.npz", "a GCVF package"),
        (["export", "{d}", "--out", "{d}/report.json"], "report.json", "an inkopt slice folder"),
    ],
)
def test_an_output_never_replaces_another_kind_of_file(run, capsys, argv, target, what):
    (run / "scene.json").write_text('{"mine": 1}\n')  # a user's own JSON file
    before = snapshot(run)
    line = refused(capsys, *(a.format(d=run) for a in argv))
    assert f"{run / target}" in line and what in line
    assert snapshot(run) == before  # nothing written, nothing replaced
    assert main(["report", str(run)]) == 0  # the run reads as before


def test_a_commands_own_earlier_output_is_replaced(run, capsys):
    for argv in (
        ["report", run, "--out", run / "page.html"],
        ["report", run, "--out", run / "page.html"],
        ["report", run, "--out", run / "report.html"],
        ["evaluate", run, "--out", run / "evaluation.json", "--spp", "2", "--no-baselines"],
        ["evaluate", run, "--out", run / "e2.json", "--spp", "2", "--no-baselines"],
        ["evaluate", run, "--out", run / "e2.json", "--spp", "2", "--no-baselines"],
    ):
        assert main([str(a) for a in argv]) == 0
    assert json.loads((run / "e2.json").read_text())["spp"] == 2
    assert main(["report", str(run)]) == 0  # report.json is still the run's report


def test_a_damaged_volume_is_damaged_not_stale(run, capsys):
    data = (run / "volume.npz").read_bytes()
    (run / "volume.npz").write_bytes(data[: len(data) // 2])  # truncated (a full disk, a copy cut short)
    for argv in (["export", run], ["evaluate", run, "--spp", "2"], ["report", run], ["quantize", run]):
        line = refused(capsys, *argv)
        assert f"{run / 'volume.npz'} is damaged (cannot be read: " in line and "another volume.npz" not in line
    flipped = bytearray(data)
    flipped[len(data) // 2] ^= 0xFF  # one byte changed inside a compressed member: its checksum fails
    (run / "volume.npz").write_bytes(bytes(flipped))
    assert "volume.npz is damaged (cannot be read: " in refused(capsys, "export", run)


def test_a_damaged_quantized_volume_is_one_line(run, capsys):
    (run / "quantized.npz").write_bytes((run / "quantized.npz").read_bytes()[:500])
    for argv in (["export", run], ["evaluate", run, "--spp", "2"], ["export", run, "--format", "3mf", "--labels"]):
        line = refused(capsys, *argv)
        assert f"{run / 'quantized.npz'} is damaged (cannot be read: BadZipFile" in line and "inkopt quantize" in line


def test_the_labels_file_is_covered_by_a_digest(run, capsys):
    path = run / "quantized_labels.layers"
    labels = load_label_file(path)
    with np.load(run / "quantized.npz") as z:
        assert str(z["labels_digest"]) == file_digest(path)  # streamed while written
        inks = len(z["ink_names"])
    changed = labels.copy()
    flat = changed[len(labels) // 2].reshape(-1)
    flat[:16] = (flat[:16] + 1) % inks  # 16 labels set to another valid ink: a readable file, other labels
    w = LabelLayersWriter(path, labels.shape)
    for k in range(len(changed)):
        w[k] = changed[k]
    w.commit()
    for argv in (
        ["export", run],
        ["export", run, "--format", "gcvf"],
        ["inspect", run / "slices.gcvf", "--run", run],
        ["evaluate", run, "--spp", "2"],
    ):
        line = refused(capsys, *argv)
        assert f"{path} is damaged or was changed" in line and "inkopt quantize" in line
    assert main(["quantize", str(run)]) == 0 and main(["export", str(run)]) == 0


def test_a_quantized_volume_without_a_labels_digest_reads_as_before(run, capsys):
    with np.load(run / "quantized.npz") as z:
        arrays = {k: z[k] for k in z.files if k != "labels_digest"}
    np.savez_compressed(run / "quantized.npz", **arrays)  # as an inkopt before the digest wrote it
    d = RunDir(run)
    d.check_quantized_current()
    assert d.load_quantized().form == "labels"
    assert main(["export", str(run)]) == 0


def test_two_runs_into_one_folder_at_once(done_run, tmp_path, capsys):
    """A second ``inkopt slab`` into the folder of one under way is refused in one line naming the folder and the
    first job's pid, before it writes anything; once the first job is killed, its lock is taken over."""
    out, pic = tmp_path / "r", done_run.parent / "p.png"
    argv = ["slab", str(pic), "--size-mm", "1.5x1x0.5", "--out", str(out), "--threads", "1", "--spp", "1"]
    first = subprocess.Popen(
        [sys.executable, "-m", "inkopt.cli", *argv, "--iterations", "100000", "--checkpoint-every", "1000"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.time() + 60
        while not (out / "scene.npz").is_file() and time.time() < deadline:
            time.sleep(0.05)
        assert Holder.read(out / LOCK_NAME).pid == first.pid
        before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
        line = refused(capsys, *argv, "--iterations", "2", "--eval-spp", "4")
        assert f"{out} is in use by another inkopt job (pid {first.pid} " in line
        assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == before  # the second wrote nothing
    finally:
        first.send_signal(signal.SIGKILL)
        first.wait()
    assert main([*argv, "--iterations", "2", "--eval-spp", "4"]) == 0
    assert f"took over the lock of pid {first.pid}" in capsys.readouterr().err
    assert not (out / LOCK_NAME).exists()
