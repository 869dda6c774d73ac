"""Chart design, the chart's CGATS columns, the identifiability check and the printable job."""

import numpy as np
import pytest

from inkopt.calibration import cgats
from inkopt.calibration.chart import ChartError, chart_from_table, check_identifiable, design_chart, start_table
from inkopt.calibration.job import chart_volume
from inkopt.model import InkTable

CMYKW = ("cyan", "magenta", "yellow", "black", "white")


def test_design_separates_every_ink():
    chart = design_chart(CMYKW)
    check_identifiable(chart)
    assert 80 <= len(chart) <= 110
    for k, name in enumerate(CMYKW):
        pure = [p for p in chart.patches if p.pure_ink() == k]
        if name == "white":
            assert {p.backing for p in pure} == {"none"} and len({p.thickness_mm for p in pure}) >= 2
        else:  # several thicknesses over white and alone
            assert {p.backing for p in pure} == {"white", "none"} and len({p.thickness_mm for p in pure}) >= 3
    for p in chart.patches:
        assert sum(p.shares) == pytest.approx(1.0, abs=1e-5)


def test_chart_table_round_trip(tmp_path):
    chart = design_chart(("cyan", "white"))
    path = cgats.write(tmp_path / "c.txt", chart.table())
    back = chart_from_table(cgats.read(path))
    assert back.inks == chart.inks and len(back) == len(chart)
    for a, b in zip(back.patches, chart.patches):
        assert a.sample_id == b.sample_id and a.backing == b.backing
        np.testing.assert_allclose(a.shares, b.shares, atol=1e-6)
        assert a.thickness_mm == b.thickness_mm and a.backing_mm == b.backing_mm


def _table(rows, fields=("SAMPLE_ID", "INK_CYAN", "INK_WHITE", "THICKNESS_MM", "BACKING", "BACKING_MM")):
    return cgats.CgatsTable(list(fields), [[str(v) for v in r] for r in rows])


@pytest.mark.parametrize(
    "rows,needle",
    [
        ([[1, 0.5, 0.4, 1, "white", 2]], "sum to 0.9"),
        ([[1, 1.2, -0.2, 1, "white", 2]], "must lie in [0, 1]"),
        ([[1, 1, 0, 0, "white", 2]], "THICKNESS_MM must lie in"),
        ([[1, 1, 0, 1, "paper", 2]], "BACKING 'paper'"),
        ([[1, 1, 0, 1, "none", 2]], "BACKING_MM must be 0"),
        ([[1, 1, 0, "x", "white", 2]], "'x', not a number"),
        ([[1, 1, 0, 1, "white", 2], [1, 1, 0, 2, "white", 2]], "appears twice"),
    ],
)
def test_bad_rows_are_one_line_errors(rows, needle):
    with pytest.raises(ChartError) as e:
        chart_from_table(_table(rows))
    assert needle in str(e.value) and "\n" not in str(e.value)


def test_missing_columns():
    with pytest.raises(ChartError, match="missing column"):
        chart_from_table(_table([[1, 1, 1]], ("SAMPLE_ID", "INK_CYAN", "THICKNESS_MM")))
    with pytest.raises(ChartError, match="no ink share column"):
        chart_from_table(_table([[1, 1, "none", 0]], ("SAMPLE_ID", "THICKNESS_MM", "BACKING", "BACKING_MM")))


def test_unidentifiable_charts_name_the_ink():
    one_thickness = _table([[1, 1, 0, 1, "white", 2], [2, 0, 1, 1, "none", 0], [3, 0, 1, 2, "none", 0]])
    with pytest.raises(ChartError, match=r"ink 'cyan': only one pure patch \(1 mm over 2 mm white\)"):
        check_identifiable(chart_from_table(one_thickness))
    mixtures_only = _table([[1, 0.5, 0.5, 1, "white", 2], [2, 0, 1, 1, "none", 0], [3, 0, 1, 2, "none", 0]])
    with pytest.raises(ChartError, match="ink 'cyan': no patch of the pure ink"):
        check_identifiable(chart_from_table(mixtures_only))
    with pytest.raises(ChartError, match="needs the printer's white"):
        design_chart(("cyan", "magenta"))


def test_unknown_ink_needs_a_start_table():
    chart = chart_from_table(
        _table(
            [[1, 1, 0, 1, "white", 2]],
            ("SAMPLE_ID", "INK_WOAD", "INK_WHITE", *("THICKNESS_MM", "BACKING", "BACKING_MM")),
        )
    )
    with pytest.raises(ChartError, match="unknown ink 'woad'"):
        start_table(chart, InkTable.parse("vero-cmykw"))
    assert start_table(chart_from_table(_table([[1, 1, 0, 1, "white", 2]])), InkTable.parse("paper-6")).names == (
        "cyan",
        "white",
    )


def test_chart_volume_stacks_each_patch():
    inks = InkTable.parse("cyan,white")
    chart = design_chart(inks.names)
    vol = chart_volume(chart, inks, 4.0)
    assert vol.voxel_mm[0] == pytest.approx(0.2) and vol.voxel_mm[2] == pytest.approx(0.1)
    # Patch 1 (top left, largest y): 2 mm white under 0.1 mm cyan; patch of white alone: no white under it.
    col = vol.mixture[:, -1, 0]
    inside = vol.inside.dense()[:, -1, 0]
    assert inside.sum() == 21 and np.all(col[:20, 1] == 1) and np.all(col[20, 0] == 1)
    assert not vol.inside.dense()[:, -1, 20:24].any()  # the gap between patches
