"""The two commands end to end: ``calibration-chart`` writes a chart that ``quantize`` and ``export`` print and
that ``calibrate`` reads back with measurements; ``calibrate`` writes an ink file ``--inks`` takes, with its
provenance, report and picture; bad input is one line on stderr, exit status 2, and no output."""

import json

import numpy as np
import pytest

from inkopt.calibration import cgats
from inkopt.calibration.chart import chart_from_table
from inkopt.calibration.fit import predict_lab
from inkopt.calibration.report import CalibrationReport
from inkopt.cli import main
from inkopt.io import file_digest
from inkopt.model import InkTable
from inkopt.model.inks import read_ink_file

pytest.importorskip("iadpython")


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    """A cyan + white chart with Lab D50 from a hidden table (adding-doubling, no noise)."""
    d = tmp_path_factory.mktemp("chart")
    assert main(["calibration-chart", "--inks", "cyan,white", "--out", str(d), "--patch-mm", "3"]) == 0
    table = cgats.read(d / "chart.txt")
    chart = chart_from_table(table)
    inks = InkTable.parse("cyan,white")
    truth = InkTable(inks.names, inks.sigma_s * [[1.3, 0.8, 1.1], [0.9, 1.2, 1.0]], inks.sigma_a * 1.25, 0.4)
    lab = predict_lab(chart, truth, "D50")
    for k, row in enumerate(table.rows):
        row[-3:] = [float(round(v, 3)) for v in lab[k]]
    cgats.write(d / "measured.txt", table)
    return d


def test_chart_job_prints(measured, capsys):
    job = measured / "job"
    assert (measured / "layout.png").is_file()
    assert main(["quantize", str(job)]) == 0
    assert main(["export", str(job), "--format", "gcvf", "--printer", "j750"]) == 0
    assert (job / "slices.gcvf").is_file()


def test_calibrate_writes_an_ink_file(measured, tmp_path, capsys):
    out = tmp_path / "mine.json"
    assert main(["calibrate", str(measured / "measured.txt"), "--out", str(out), "--holdout", "0.2"]) == 0
    text = capsys.readouterr().out
    assert "held out" in text
    inks = InkTable.parse(str(out))
    assert inks.names == ("cyan", "white")
    prov = read_ink_file(out)["provenance"]
    assert prov["measurement_digest"] == file_digest(measured / "measured.txt") and prov["illuminant"] == "D50"
    rep = CalibrationReport.from_json(tmp_path / "mine.report.json")
    assert rep.holdout_count == sum(p.held_out for p in rep.patches) > 0
    # noise-free measurements from the model itself: the fit and the held-out predictions are near exact
    assert rep.fit_mean_delta_e2000 < 0.05 and rep.holdout_mean_delta_e2000 < 0.1
    assert (tmp_path / "mine.swatches.png").is_file()


def _fails(args, capsys, needle):
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("inkopt: error:") and needle in err[0], err


def test_bad_input_is_one_line_and_writes_nothing(measured, tmp_path, capsys):
    table = cgats.read(measured / "measured.txt")
    table.rows[3][-2] = ""
    cgats.write(tmp_path / "gap.txt", table)
    out = tmp_path / "x.json"
    _fails(["calibrate", str(tmp_path / "gap.txt"), "--out", str(out)], capsys, "patch 4 has no measurement")
    table.rows[3][-2] = "300"
    cgats.write(tmp_path / "range.txt", table)
    _fails(["calibrate", str(tmp_path / "range.txt"), "--out", str(out)], capsys, "patch 4: L*a*b*")
    _fails(["calibrate", str(measured / "measured.txt"), "--out", str(tmp_path / "x.toml")], capsys, ".json ink file")
    _fails(["calibrate", str(measured / "measured.txt"), "--out", str(out), "--illuminant", "F2"], capsys, "illuminant")
    _fails(["calibrate", str(tmp_path / "none.txt"), "--out", str(out)], capsys, "no such file")
    _fails(
        ["calibration-chart", "--inks", "paper-6", "--out", str(tmp_path / "c"), "--printer", "j750"], capsys, "8 inks"
    )
    _fails(["calibration-chart", "--inks", "cyan,magenta", "--out", str(tmp_path / "c")], capsys, "white")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gap.txt", "range.txt"]


def test_ink_files_old_and_new(tmp_path):
    old = tmp_path / "old.json"
    old.write_text(
        json.dumps({"g": 0.4, "inks": [{"name": "cyan", "mu_t": [9, 4.5, 7.5], "albedo": [0.05, 0.7, 0.98]}]})
    )
    assert InkTable.parse(str(old)).names == ("cyan",)
    future = tmp_path / "future.json"
    future.write_text(json.dumps({**json.loads(old.read_text()), "format_version": 9}))
    with pytest.raises(ValueError, match="format version 9"):
        InkTable.parse(str(future))
    assert np.isfinite(InkTable.parse(str(old)).sigma_s).all()


def test_instrument_file_matched_to_the_chart(measured, tmp_path, capsys):
    """An i1Profiler-style export (SampleID, SAMPLE_NAME, Lab_L Lab_a Lab_b, in another order) with --chart."""
    full = cgats.read(measured / "measured.txt")
    lab = [r[-3:] for r in full.rows]
    rows = [[str(k + 1), f"A{k + 1}", *v] for k, v in reversed(list(enumerate(lab)))]
    inst = cgats.CgatsTable(["SampleID", "SAMPLE_NAME", "Lab_L", "Lab_a", "Lab_b"], rows, {"ORIGINATOR": "i1Profiler"})
    cgats.write(tmp_path / "i1.txt", inst)
    out = tmp_path / "i1.json"
    chart = measured / "chart.txt"
    assert (
        main(["calibrate", str(tmp_path / "i1.txt"), "--chart", str(chart), "--out", str(out), "--holdout", "0"]) == 0
    )
    prov = read_ink_file(out)["provenance"]
    assert prov["chart_digest"] == file_digest(chart) and prov["fit_mean_delta_e2000"] < 0.05
    inst.rows = inst.rows[1:]
    cgats.write(tmp_path / "short.txt", inst)
    capsys.readouterr()
    _fails(
        ["calibrate", str(tmp_path / "short.txt"), "--chart", str(chart), "--out", str(out)],
        capsys,
        "has no measurement",
    )


def test_a_new_chart_in_the_same_folder_removes_the_old_print(tmp_path, capsys):
    """Writing another chart over an old one removes the old job's quantized print and packages, which would
    otherwise print the old chart."""
    assert main(["calibration-chart", "--inks", "cyan,white", "--out", str(tmp_path), "--patch-mm", "3"]) == 0
    job = tmp_path / "job"
    assert main(["quantize", str(job)]) == 0 and main(["export", str(job), "--format", "gcvf"]) == 0
    assert main(["calibration-chart", "--inks", "magenta,white", "--out", str(tmp_path), "--patch-mm", "3"]) == 0
    assert not (job / "quantized.npz").exists() and not (job / "slices.gcvf").exists()


def test_argyll_ti3_with_the_chart(measured, tmp_path):
    """An ArgyllCMS .ti3 of the chart (XYZ on the 0-100 scale, D50; spectral keywords carried along) matched to
    the chart by SAMPLE_ID reads back as the CIELAB it was made from."""
    import colour

    from inkopt.calibration.calibrate import merge_measurements
    from inkopt.calibration.measure import measured_lab, white_xy

    lab_true, _ = measured_lab(cgats.read(measured / "measured.txt"), "D50")
    xyz = colour.Lab_to_XYZ(lab_true, white_xy("D50")) * 100
    rows = [[str(k + 1), f"A{k + 1}", *(float(round(v, 4)) for v in x)] for k, x in enumerate(xyz)]
    ti3 = cgats.CgatsTable(
        ["SAMPLE_ID", "SAMPLE_LOC", "XYZ_X", "XYZ_Y", "XYZ_Z"], rows[::-1], {"SPECTRAL_NORM": "100"}, "CTI3"
    )
    cgats.write(tmp_path / "m.ti3", ti3)
    merged = merge_measurements(cgats.read(measured / "chart.txt"), cgats.read(tmp_path / "m.ti3"), "m.ti3")
    assert merged.header["SPECTRAL_NORM"] == "100"
    lab, kind = measured_lab(merged, "D50")
    assert kind == "xyz"
    np.testing.assert_allclose(lab, lab_true, atol=2e-3)


def test_a_sample_id_measured_twice_is_refused(measured, tmp_path, capsys):
    inst = cgats.read(measured / "measured.txt")
    keep = [i for i, f in enumerate(inst.fields) if f in ("SAMPLE_ID", "LAB_L", "LAB_A", "LAB_B")]
    rows = [[r[i] for i in keep] for r in inst.rows]
    rows.append(list(rows[2]))
    cgats.write(tmp_path / "twice.txt", cgats.CgatsTable([inst.fields[i] for i in keep], rows))
    out = tmp_path / "x.json"
    argv = ["calibrate", str(tmp_path / "twice.txt"), "--chart", str(measured / "chart.txt"), "--out", str(out)]
    _fails(argv, capsys, f"twice.txt: SAMPLE_ID {rows[2][0]} appears twice (data rows 3 and {len(rows)})")
    assert not out.exists()


def test_an_unwritable_out_folder_is_refused_before_the_fit(measured, tmp_path, capsys, monkeypatch):
    """A folder that takes no new file: refused at once, not after the fit (the probe file is made there)."""
    import os
    import tempfile

    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    if os.geteuid() == 0:  # root writes anywhere: the folder refuses the probe as it would refuse a user

        def refuse(*args, dir=None, **kw):
            raise PermissionError(13, "Permission denied", str(dir))

        monkeypatch.setattr(tempfile, "mkstemp", refuse)
    try:
        _fails(
            ["calibrate", str(measured / "measured.txt"), "--out", str(ro / "x.json")],
            capsys,
            f"--out: cannot write in folder {ro} (Permission denied)",
        )
    finally:
        ro.chmod(0o755)
    assert list(ro.iterdir()) == []
