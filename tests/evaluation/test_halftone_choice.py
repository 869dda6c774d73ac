"""Tests of inkopt.evaluation.halftone_choice: ``inkopt quantize --compensate-auto`` keeps the compensated labels
only where the run's printed prediction says they are closer to its target."""

import math

import numpy as np
import pytest

from inkopt.cli import main
from inkopt.errors import ParameterError
from inkopt.evaluation import halftone_choice as hc
from inkopt.io import save_npz
from inkopt.model import InkTable, Quantization, Texels, Volume
from inkopt.printing import compensate as C
from inkopt.printing.quantize import quantize_volume
from inkopt.render import Renderer
from inkopt.rundir import RunDir

V300 = 25.4 / 300
SHAPE = (8, 12, 12)  # z, y, x optimisation voxels: 0.68 mm deep, 1 mm square, 144 top texels


def test_the_rule_asks_a_de76_gain_beyond_two_standard_errors_and_no_de2000_loss_beyond_them():
    assert hc.compensate_wins((-0.25, 0.05), (-0.05, 0.03))
    assert hc.compensate_wins((-0.25, 0.05), (+0.05, 0.03))  # ΔE2000 within its noise
    assert not hc.compensate_wins((-0.09, 0.05), (-0.5, 0.03))  # ΔE76 gain within its noise
    assert not hc.compensate_wins((-0.25, 0.05), (+0.07, 0.03))  # ΔE2000 lost beyond its noise
    assert not hc.compensate_wins((0.0, 0.0), (0.0, 0.0))  # identical labels: the plain dither stays
    assert not hc.compensate_wins((-1.0, math.nan), (-1.0, 0.1))


def yellow_run(path, yellow: float, target_yellow: float) -> RunDir:
    """A slab run of the default inks, every voxel ``yellow`` in white, whose top face's target is the continuous
    render of ``target_yellow`` in white (256 spp: its noise is far below the halftone's effect)."""
    inks = InkTable.parse("vero-cmykw")
    y, w = inks.names.index("yellow"), inks.names.index("white")

    def mixture(share):
        m = np.zeros(SHAPE + (len(inks),), np.float32)
        m[..., y], m[..., w] = share, 1.0 - share
        return m

    tex = Texels.box_faces(SHAPE, ["top"])
    target = Volume.from_mixture(voxel_mm=[V300] * 3, mixture=mixture(target_yellow), inks=inks)
    target_rgb = Renderer(target).render(tex, 256, seed=7).rgb.astype(np.float32)
    d = RunDir.create(path)
    d.save_volume(Volume.from_mixture(voxel_mm=[V300] * 3, mixture=mixture(yellow), inks=inks))
    ny, nx = SHAPE[1:]
    pix = (np.arange(ny)[::-1, None] * nx + np.arange(nx)[None, :]).astype(np.int32)
    scene = {**tex.to_arrays(), "target_rgb": target_rgb, "kind": np.array("slab"), "faces": np.array(["top"])}
    save_npz(d.scene_path, {**scene, "fixed_share": np.zeros(SHAPE + (len(inks),), np.float32), "pix_top": pix})
    return d


@pytest.fixture
def shipped_compensation(monkeypatch, tmp_path):
    """The default inks' shipped factors, nothing measured or cached outside ``tmp_path``."""
    monkeypatch.setenv("INKOPT_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(C, "_MEMORY", {})
    monkeypatch.setattr(C, "measure_compensation", lambda *a, **k: pytest.fail("measured"))


def test_auto_compensates_where_the_plain_print_is_lighter_than_its_mixture(tmp_path, capsys, shipped_compensation):
    """A target that is the mixture's own continuous render: the plain print of 0.15 yellow looks like less yellow
    (yellow's package factor, k = 0.34), the compensated one like the mixture, so auto keeps the compensated labels,
    exactly those ``--compensate`` makes, and leaves no candidate folder behind."""
    d = yellow_run(tmp_path / "r", 0.15, 0.15)
    assert main(["quantize", str(d.path), "--compensate-auto"]) == 0
    out = capsys.readouterr().out
    assert "compensation auto: compensated" in out
    got = d.load_quantized()
    assert got.quantization.compensate is True
    kept = d.compensation_choice()["compensation_choice"]  # quantized.npz keeps the choice, the labels check out
    assert kept["compensate"] is True and kept["delta_e76"] < -2 * kept["delta_e76_stderr"]
    expect = quantize_volume(d.load_volume(), Quantization(compensate=True))
    np.testing.assert_array_equal(got.labels, expect.labels)
    assert sorted(p.name for p in d.path.iterdir() if p.name.startswith(".")) == []
    # what a killed choice leaves is one of the temporaries the next job under the run's lock removes
    killed = d.path / f"{hc.STAGE_PREFIX}abcd_123.tmp"
    (killed / "plain").mkdir(parents=True)
    assert main(["quantize", str(d.path), "--no-compensate"]) == 0
    assert not killed.exists()


def test_auto_keeps_the_plain_print_where_the_compensation_overshoots(tmp_path, shipped_compensation):
    """A target of the less yellow mixture the plain print of 0.15 yellow looks like (0.15 / (1 + 0.34 x 0.85)):
    the compensated print is the one too yellow now; auto keeps the plain labels, and says by how much."""
    d = yellow_run(tmp_path / "r", 0.15, 0.116)
    lines, choice = hc.quantize_run_auto(d, Quantization())
    assert not choice.compensate and choice.delta_e76 > 2 * choice.delta_e76_stderr
    assert choice.texels == choice.population == SHAPE[1] * SHAPE[2]
    got = d.load_quantized()
    assert got.quantization.compensate is False
    np.testing.assert_array_equal(got.labels, quantize_volume(d.load_volume(), Quantization()).labels)
    assert any("method count-adaptive" in line for line in lines)


def test_auto_refines_each_candidate_and_flags_keep_their_meaning(tmp_path, shipped_compensation):
    """With ``--refine 1`` each candidate is refined on its own dither's render: the chosen labels are those
    ``--refine 1`` with the chosen compensation makes."""
    d = yellow_run(tmp_path / "r", 0.15, 0.15)
    d.write_report({"gamma": [1.0, 0.0, 0.0], "smooth": 0.0})  # the refinement's loss weights
    _, choice = hc.quantize_run_auto(d, Quantization(refine=1))
    got = d.load_quantized()
    assert got.quantization.refine == 1 and got.quantization.compensate is choice.compensate
    assert (
        main(["quantize", str(d.path), "--refine", "1", "--compensate" if choice.compensate else "--no-compensate"])
        == 0
    )
    np.testing.assert_array_equal(d.load_quantized().labels, got.labels)
    with pytest.raises(ParameterError, match="compensate"):
        hc.quantize_run_as(d, Quantization(), "sometimes")
    assert main(["quantize", str(d.path), "--compensate"]) == 0  # alone: on
    assert d.load_quantized().quantization.compensate is True
    assert main(["quantize", str(d.path), "--no-compensate"]) == 0
    assert d.load_quantized().quantization.compensate is False
    assert main(["quantize", "--compensate", str(d.path)]) == 0  # the flag takes no value: DIR after it
    assert d.load_quantized().quantization.compensate is True
    assert main(["quantize", str(d.path), "--compensate", "--compensate-auto"]) == 0  # the last one counts
    assert d.load_quantized().quantization.compensate is choice.compensate


def test_auto_dithers_a_job_without_a_target_plain(tmp_path, capsys, shipped_compensation):
    """The calibration chart's job has no scene.npz: its patches are dithered plain, as the chart is measured."""
    d = yellow_run(tmp_path / "r", 0.15, 0.15)
    d.scene_path.unlink()
    assert main(["quantize", str(d.path), "--compensate-auto"]) == 0
    assert "no target" in capsys.readouterr().out
    assert d.load_quantized().quantization.compensate is False
    assert "no target" in d.compensation_choice()["compensation_choice"]["reason"]
    assert main(["quantize", str(d.path), "--no-compensate"]) == 0
    assert d.compensation_choice() == {}  # a quantization without a choice records none


def test_auto_does_not_measure_a_compensation_unasked(tmp_path, capsys, monkeypatch, shipped_compensation):
    """Inks whose factors are neither shipped nor cached are dithered plain, and the line says how to measure them."""
    d = yellow_run(tmp_path / "r", 0.15, 0.15)
    monkeypatch.setattr(C, "PACKAGED", tmp_path / "nothing shipped")
    assert main(["quantize", str(d.path), "--compensate-auto"]) == 0
    assert "--compensate` measures it" in capsys.readouterr().out
    assert d.load_quantized().quantization.compensate is False


@pytest.mark.parametrize(
    "report, says",
    [({"lighting": "studio.hdr"}, "seen under 'studio.hdr'"), ({"viewing": {"lights": ["D50"]}}, "spectral run")],
)
def test_auto_does_not_judge_a_run_seen_under_other_lights(tmp_path, report, says, shipped_compensation):
    """The choice renders RGB under the uniform light: a run optimised under a map or in spectral bands is plain."""
    d = yellow_run(tmp_path / "r", 0.15, 0.15)
    d.write_report(report)
    lines, choice = hc.quantize_run_auto(d, Quantization())
    assert not choice.compensate and says in choice.reason and says in choice.line()
    assert d.load_quantized().quantization.compensate is False


def test_a_print_too_large_to_render_keeps_the_plain_labels(tmp_path, monkeypatch, shipped_compensation):
    """The candidates are made layer by layer; where their renders do not fit, the plain labels are the run's."""
    from inkopt.model import VolumeError

    def too_large(*a, **k):
        raise VolumeError("the labels volume needs 9 GB to render (INKOPT_MAX_VOLUME_BYTES 1 GB)")

    d = yellow_run(tmp_path / "r", 0.15, 0.15)
    monkeypatch.setattr(hc, "paired_figures", too_large)
    _, choice = hc.quantize_run_auto(d, Quantization())
    assert not choice.compensate and "could not be rendered here (the labels volume needs 9 GB" in choice.reason
    np.testing.assert_array_equal(d.load_quantized().labels, quantize_volume(d.load_volume(), Quantization()).labels)
    assert not [p for p in d.path.iterdir() if p.name.startswith(".")]
