"""``inkopt select-inks --translucency``: the mask reaches every candidate's run as fixed shares of the transparent
ink, a set without a transparent ink is refused before any work, and a slab target's resume key is the one
selections wrote before translucency could be given."""

import json

import numpy as np
import pytest
from helpers import FAST_RUN
from PIL import Image

from inkopt import charts
from inkopt.cli import main
from inkopt.inksets import Selection
from inkopt.optim import OptimizeConfig
from inkopt.rundir import RunDir
from inkopt.scenes.spec import SlabSpec

pytest.importorskip("inkopt._core")

SIZE = "2x1.333x0.5"


@pytest.fixture(scope="module")
def chart_and_mask(tmp_path_factory):
    d = tmp_path_factory.mktemp("target")
    chart = charts.save(charts.colour_chart(24, 16), d / "chart.png")
    mask = np.zeros((16, 24), np.uint8)
    mask[:, :12] = 204  # share 0.8 in the left half
    Image.fromarray(mask).save(d / "mask.png")
    return chart, d / "mask.png"


def test_mask_reaches_every_candidates_run(chart_and_mask, tmp_path, capsys):
    chart, mask = chart_and_mask
    out = tmp_path / "sel"
    assert (
        main(
            [
                "select-inks",
                str(chart),
                "--size-mm",
                SIZE,
                "--translucency",
                str(mask),
                "--translucency-depth-mm",
                "0.17",
                "--candidates",
                "cyan,magenta",
                "--choose",
                "1",
                "--always",
                "black,white,transparent",
                "--out",
                str(out),
                *FAST_RUN,
            ]
        )
        == 0
    )
    runs = sorted((out / "runs").iterdir())
    assert [r.name for r in runs] == ["cyan", "magenta"]
    for run in runs + [out / "winner"]:
        rd = RunDir(run)
        rec, vol = rd.load_scene(), rd.load_volume()
        assert rec.translucency is not None and rec.translucency.ink == "transparent"
        assert rec.translucency.depth_mm == pytest.approx(0.17)
        region = rec.translucency.grid() > 0
        assert region.sum() == 2 * 16 * 12  # two layers (0.17 mm) under the left half
        t = vol.inks.index("transparent")
        assert np.all(vol.mixture[region][:, t] >= 0.8 - 1e-6)  # the fixed share holds in the result
        assert rd.read_report()["translucency"]["mean_share"] == pytest.approx(0.8, abs=0.01)


def test_translucency_needs_a_transparent_ink_in_always(chart_and_mask, tmp_path, capsys):
    chart, mask = chart_and_mask
    out = tmp_path / "sel"
    assert (
        main(
            [
                "select-inks",
                str(chart),
                "--size-mm",
                SIZE,
                "--translucency",
                str(mask),
                "--candidates",
                "cyan,transparent",
                "--choose",
                "1",
                "--out",
                str(out),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip()
    assert err.startswith("inkopt: error:") and "--always" in err and "\n" not in err
    assert not out.exists()


def test_slab_key_is_the_one_of_earlier_selections(chart_and_mask):
    """The state file's target of a slab without translucency is the object selections wrote before specs (kind
    "image"), so their --resume still matches; with a mask, the mask and its depth are part of it."""
    chart, mask = chart_and_mask
    cfg = OptimizeConfig(iterations=4)
    sel = Selection(SlabSpec(str(chart), (2.0, 1.333, 0.5)), "cyan,magenta", 1, ["black", "white"], cfg)
    assert json.loads(sel.key())["target"] == {
        "kind": "image",
        "top": str(chart),
        "bottom": None,
        "size_mm": [2.0, 1.333, 0.5],
        "dpi": 300.0,
    }
    sel.target = SlabSpec(str(chart), (2.0, 1.333, 0.5), translucency=str(mask))
    assert json.loads(sel.key())["target"]["translucency"] == str(mask)
