"""Tests of the refinement on the printed prediction (inkopt.printing.refine) and its place in a run's quantization
(``Quantization.refine``, ``inkopt quantize --refine``)."""

import numpy as np
import pytest

from inkopt.color import delta_e76, linear_to_lab
from inkopt.errors import ParameterError
from inkopt.model import InkTable, Quantization, Texels, Volume
from inkopt.printing.quantize import check_quantization, quantize_volume
from inkopt.printing.refine import PrintedLoss, PrintedRefinement, refine_mixture
from inkopt.printing.stream import quantize_run, run_target
from inkopt.printing.texelmap import average_to_scene, map_texels, printer_texels
from inkopt.render import Renderer
from inkopt.rundir import RunDir
from inkopt.rundir.records import SceneRecord

V300 = 25.4 / 300
SHAPE = (6, 12, 16)
INKS = InkTable.from_names(["cyan", "magenta", "yellow", "white"])


def slab_case():
    """A slab of a uniform grey-ish start mixture under a two-colour target on top (left: red-ish, right: blue-ish),
    far from the start, so that a few refinement steps move the printed colours by much more than their noise."""
    tex = Texels.box_faces(SHAPE, ["top"])
    right = tex.voxel[:, 2] >= SHAPE[2] // 2
    target = np.where(right[:, None], [[0.15, 0.3, 0.6]], [[0.6, 0.2, 0.15]]).astype(np.float32)
    mix = np.full(SHAPE + (len(INKS),), 0.25, np.float32)
    vol = Volume.from_mixture(voxel_mm=[V300] * 3, mixture=mix, inks=INKS)
    return vol, PrintedLoss(texels=tex, target_rgb=target, kind="slab", gamma=(1.0, 0.0, 0.0), smooth=1.0)


def printed_delta_e(vol, target: PrintedLoss, spp: int, seed: int) -> tuple[float, float]:
    """Mean ΔE76 of ``vol``'s blue-noise print on the top texels and its standard error over texels, at ``spp``."""
    labels = quantize_volume(vol, Quantization())
    ptex = printer_texels(labels, target.texels, "slab")
    to_scene, stand_in = map_texels(ptex, labels.voxel_mm, target.texels, vol.voxel_mm)
    res = Renderer(labels, 2).render(ptex, spp, seed)
    rgb, _ = average_to_scene(res.rgb.astype(np.float64), res.var_mean, to_scene, stand_in, len(target.texels))
    de = delta_e76(linear_to_lab(rgb), linear_to_lab(target.target_rgb.astype(np.float64)))
    return float(de.mean()), float(de.std() / np.sqrt(len(de)))


def test_refinement_lowers_the_printed_error_beyond_its_noise():
    vol, target = slab_case()
    refined, history = refine_mixture(vol, target, Quantization(refine=4), threads=2)
    assert len(history) == 4 and all(np.isfinite(h["loss"]) for h in history)
    # the refined mixture stays a mixture of the same grid and inks
    assert refined.shape == vol.shape and refined.inks.names == vol.inks.names
    np.testing.assert_allclose(refined.mixture.sum(-1), 1.0, atol=1e-5)
    before, se_b = printed_delta_e(vol, target, 64, 11)
    after, se_a = printed_delta_e(refined, target, 64, 11)
    # the texel spread bounds each mean's Monte Carlo and texel noise; the drop must exceed 4 of them combined
    assert before - after > 4.0 * np.hypot(se_b, se_a), (before, after, se_b, se_a)


def test_refinement_is_identical_for_any_thread_count():
    vol, target = slab_case()
    a = PrintedRefinement(vol, target, Quantization(refine=2), threads=1)
    b = PrintedRefinement(vol, target, Quantization(refine=2), threads=2)
    for _ in range(2):
        a.step(), b.step()
    np.testing.assert_array_equal(a.x, b.x)
    assert [h["loss"] for h in a.history] == [h["loss"] for h in b.history]


def test_refinement_keeps_the_fixed_shares():
    vol, target = slab_case()
    from inkopt.model import FixedShares

    free = np.ones(SHAPE, bool)
    free[:2] = False  # the bottom two layers held at pure white
    fixed = FixedShares(free, np.array([0, 0, 0, 1], np.float32))
    mix = np.array(vol.mixture)
    mix[:2] = [0, 0, 0, 1]
    vol = vol.with_mixture(mix)
    refined, _ = refine_mixture(vol, PrintedLoss(**{**target.__dict__, "fixed_share": fixed}), Quantization(refine=1))
    np.testing.assert_allclose(refined.mixture[:2], mix[:2], atol=1e-6)
    assert not np.allclose(refined.mixture[2:], mix[2:])


def write_run(path):
    vol, target = slab_case()
    d = RunDir.create(path)
    d.save_volume(vol)
    rec = SceneRecord(kind="slab", texels=target.texels, target_rgb=target.target_rgb)
    d.save_scene(rec)
    d.write_report({"gamma": [1.0, 0.0, 0.0], "smooth": 1.0})
    return d, vol, target


def test_a_runs_quantization_refines_first_and_records_it(tmp_path):
    d, vol, target = write_run(tmp_path / "r")
    q = Quantization(refine=2, seed=5)
    quantize_run(d, q)
    got = d.load_quantized()
    assert got.quantization.refine == 2 and got.quantization.to_json()["refine"] == 2
    refined, _ = refine_mixture(vol, run_target(d, vol), q)
    np.testing.assert_array_equal(np.asarray(got.labels), quantize_volume(refined, q).labels)
    # without refinement the record is what it always was (no refine entry)
    quantize_run(d, Quantization(seed=5))
    plain = d.load_quantized()
    assert plain.quantization.refine == 0 and "refine" not in plain.quantization.to_json()
    assert "refine" not in Quantization().arrays()


@pytest.mark.parametrize("bad", [-1, 1.5, "2"])
def test_a_bad_refine_count_is_refused_in_its_name(bad):
    with pytest.raises(ParameterError) as e:
        check_quantization(Quantization(refine=bad))
    assert e.value.parameters == ("refine",)


def test_the_command_line_takes_refine():
    from inkopt.cli import build_parser
    from inkopt.cli.quantize import quantization_of

    args = build_parser().parse_args(["quantize", "RUN", "--refine", "3"])
    assert quantization_of(args).refine == 3
    assert quantization_of(build_parser().parse_args(["quantize", "RUN"])).refine == 0
