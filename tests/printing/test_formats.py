"""The format registry (inkopt.printing.formats): every format writes a job, is told by its contents and reads it
back to the same labels; the registry is what export, inspect and a new format go through."""

import inspect
import json
from pathlib import Path

import numpy as np
import pytest

from inkopt.model import InkTable, Volume
from inkopt.model.mixturefile import MixtureSource
from inkopt.printing.formats import FORMATS, Format, format_named, format_of, inspect_package
from inkopt.printing.formats.inspection import PackageError, PackageReport, Scan
from inkopt.printing.formats.job import LabelVoxels, MixtureVoxels, PrintJob, Provenance
from inkopt.printing.profiles import printer_profile
from inkopt.rundir import RunDir

VP = np.array([25.4 / 600, 25.4 / 300, 0.027])
INKS = ["cyan", "magenta", "yellow", "black", "white"]


def labels(shape=(4, 6, 9), seed=0):
    lab = np.random.default_rng(seed).integers(0, len(INKS), shape).astype(np.uint8)
    lab[:, :1] = 255
    return lab


def test_the_registry_holds_every_format_under_its_name():
    assert list(FORMATS) == ["png-slices", "gcvf", "3mf"]
    members = [n for n in vars(Format) if not n.startswith("_")] + list(Format.__annotations__)
    for name, fmt in FORMATS.items():
        assert fmt.name == name and format_named(name) is fmt
        assert all(hasattr(fmt, m) for m in members), name
        assert fmt.suffix == ("" if name == "png-slices" else f".{name}")
        printer_profile(fmt.default_printer)
        assert list(inspect.signature(fmt.write).parameters) == ["job", "path"]
    assert [f.name for f in FORMATS.values() if f.takes_mixture] == ["3mf"]
    with pytest.raises(ValueError, match=r"unknown export format 'stl'; use one of \['png-slices', 'gcvf', '3mf'\]"):
        format_named("stl")


@pytest.mark.parametrize("name", list(FORMATS))
def test_every_format_writes_and_reads_back_the_labels(tmp_path, name):
    fmt = FORMATS[name]
    lab = labels()
    job = PrintJob(LabelVoxels(lab, VP, INKS), printer_profile("j750"), provenance=Provenance("q.npz", "sha256:0a"))
    path = tmp_path / f"job{fmt.suffix}"
    summary = fmt.write(job, path)
    assert summary["layer_count"] == lab.shape[0] and json.dumps(summary)
    line = fmt.describe(summary)
    assert "\n" not in line and line.startswith(f"{lab.shape[0]} ") and "cyan" in line
    assert format_of(path) is fmt
    report, scan = inspect_package(path, labels=True)
    np.testing.assert_array_equal(scan.labels, lab)
    assert report.kind == name and (report.layers, report.height, report.width) == lab.shape
    assert report.source["digest"] == "sha256:0a"
    assert [m["voxel_count"] for m in report.materials] == [np.sum(lab == i) for i in range(len(INKS))]


def test_run_outputs_are_the_run_directorys_files(tmp_path):
    d = RunDir(tmp_path)
    assert FORMATS["png-slices"].run_output(d) == d.slices_path
    assert FORMATS["gcvf"].run_output(d) == d.gcvf_path
    assert FORMATS["3mf"].run_output(d) == d.threemf_path(labels=True)
    assert FORMATS["3mf"].run_output(d, mixture=True) == d.threemf_path()


def test_slice_formats_refuse_a_mixture(tmp_path):
    inks = InkTable.parse("vero-cmykw")
    mix = np.full((2, 3, 4, len(inks)), 1 / len(inks), np.float32)
    Volume.from_mixture(voxel_mm=[25.4 / 300] * 3, mixture=mix, inks=inks).save(tmp_path / "volume.npz")
    with MixtureSource(tmp_path / "volume.npz") as src:
        job = PrintJob(MixtureVoxels(src))
        assert job.inks == tuple(inks.names) and job.voxels.shape == (2, 3, 4)
        for name in ("png-slices", "gcvf"):
            with pytest.raises(TypeError, match="one ink per voxel"):
                FORMATS[name].write(job, tmp_path / f"x{FORMATS[name].suffix}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["volume.npz"]


class _Text:
    """A toy format: one line per layer of labels as digits (the shape a new format module takes)."""

    name, suffix, default_printer, takes_mixture = "text", ".txt", "generic", False

    def write(self, job: PrintJob, path) -> dict:
        lab = job.voxels.labels
        Path(path).write_text("\n".join("".join(str(v % 10) for v in layer.ravel()) for layer in lab))
        return {"layer_count": lab.shape[0]}

    def recognises(self, path: Path) -> bool:
        return path.suffix == self.suffix

    def check(self, path: Path, keep_layers=(), labels: bool = False) -> tuple[PackageReport, Scan]:
        rows = Path(path).read_text().splitlines()
        if not rows:
            raise PackageError(f"{path} holds no layer")
        scan = Scan(len(rows), 1, len(rows[0]), 10, keep_layers, labels)
        for k, row in enumerate(rows):
            scan.add(k, np.array([[int(c) for c in row]], np.uint8))
        return PackageReport(self.name, str(path), len(rows), len(rows[0]), 1, None, None, [], scan.box()), scan

    def run_output(self, run, mixture: bool = False) -> Path:
        return run.path / "slices.txt"

    def describe(self, summary: dict) -> str:
        return f"{summary['layer_count']} text layers"


def test_a_new_format_is_one_class_and_one_registry_line(tmp_path, monkeypatch):
    monkeypatch.setitem(FORMATS, "text", _Text())
    fmt = format_named("text")
    fmt.write(
        PrintJob(LabelVoxels(np.arange(6, dtype=np.uint8).reshape(2, 1, 3), VP, INKS + ["orange"])), tmp_path / "a.txt"
    )
    report, scan = inspect_package(tmp_path / "a.txt", labels=True)
    assert report.kind == "text" and report.bounding_box == [0, 0, 0, 3, 1, 2]
    (tmp_path / "b.bin").write_text("?")
    with pytest.raises(PackageError, match=r"no printer package inkopt reads \(png-slices, gcvf, 3mf, text\)"):
        format_of(tmp_path / "b.bin")
