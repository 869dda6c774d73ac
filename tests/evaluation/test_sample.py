"""Tests of inkopt.evaluation.sample: the texel sample, its estimators and their standard errors, the printer texels
of a sample, and a sampled evaluation against the full one."""

import json

import numpy as np
import pytest
from helpers import SPOT
from slab_run import make_run

from inkopt.cli import main
from inkopt.evaluation.evaluate import evaluate_run
from inkopt.evaluation.metrics import mottle_per_texel, prediction_metrics
from inkopt.evaluation.options import EvaluateOptions
from inkopt.evaluation.printed import average_to_scene, restrict
from inkopt.evaluation.sample import (
    SampleError,
    TexelSample,
    differences,
    mean_se,
    per_texel,
    quantile_se,
    sample_size,
    sampled_figures,
)
from inkopt.loss import TexelLoss
from inkopt.model import Texels

FIGURES = ("delta_e76_mean", "delta_e76_mean_corrected", "delta_e2000_mean", "ssim", "delta_e76_p95")


def test_draw_renders_every_window_whole():
    tex = Texels.box_faces((4, 30, 40), ["top", "front"])
    s = TexelSample.draw(tex, 300, 12, seed=7)
    assert len(s.points) == 300 and np.all(np.diff(s.points) > 0) and np.all(np.diff(s.windows) > 0)
    assert len(s.centres) == 12 and np.isin(s.centres, s.points).all()
    assert np.array_equal(s.windows[s.centre_rows], s.centres)
    pos, windows = tex.pos_vox, set(s.windows.tolist())
    for c in s.centres:  # every texel within the window's Chebyshev radius is rendered
        near = np.flatnonzero(np.abs(pos - pos[c]).max(1) <= s.radius)
        assert windows.issuperset(near.tolist())
    again = TexelSample.draw(tex, 300, 12, seed=7)
    assert np.array_equal(again.windows, s.windows) and np.array_equal(again.points, s.points)
    assert sample_size(0, None, 1000) == (0, 0) and sample_size(4000, None, 10**6) == (4000, 100)
    assert sample_size(10**9, 10**9, 500) == (500, 500)
    with pytest.raises(SampleError, match="at least 2"):
        sample_size(1, None, 500)


def test_window_values_at_centres_equal_the_full_loss():
    """A window centre's SSIM, edge and mottle terms on the rendered texels alone equal the full loss's (its window
    lies inside them), for any colours."""
    shape = (3, 24, 32)
    tex = Texels.box_faces(shape, ["top", "front", "right"])
    rng = np.random.default_rng(0)
    target, rgb = rng.uniform(0.05, 0.9, (2, len(tex), 3))
    var = rng.uniform(0, 1e-4, (len(tex), 3))
    s = TexelSample.draw(tex, 200, 15, seed=1)
    full = TexelLoss(target, tex.pos_vox, sigma=1.5)
    part = TexelLoss(target[s.windows], tex.subset(s.windows).pos_vox, sigma=1.5)
    w, p = s.windows, s.points
    v = per_texel(part, (rgb[w], var[w]), (rgb[p], var[p]), full.target_lab[p], s)
    centres = s.centres
    np.testing.assert_allclose(v["ssim"], full.ssim_map(rgb, var)[centres].mean(1), rtol=1e-12)
    p, _ = mottle_per_texel(full, rgb, var)
    flat = full.flat[centres]
    np.testing.assert_array_equal(np.isnan(v["mottle"]), ~flat)
    np.testing.assert_allclose(v["mottle"][flat], p[centres][flat], rtol=1e-10, atol=1e-12)
    n = len(tex)
    from inkopt.color import linear_to_lab, normalise_lab

    sob = full.S @ (normalise_lab(linear_to_lab(rgb)) - full.target_n)
    e3 = sum((sob[a * n + centres] ** 2).sum(1) for a in range(3)) * 100.0 / (3 * 4 * 32)
    np.testing.assert_allclose(v["e3"], e3, rtol=1e-10)


def test_a_sample_of_every_texel_gives_the_full_figures():
    """Every texel drawn, every texel a window centre: the estimates equal ``prediction_metrics`` (no sampling
    error: the standard errors of the means are 0), and a paired difference equals the difference of the figures."""
    tex = Texels.box_faces((3, 12, 16), ["top", "front"])
    rng = np.random.default_rng(4)
    target, rgb, rgb2 = rng.uniform(0.05, 0.9, (3, len(tex), 3))
    target[: len(tex) // 2] = 0.4  # a flat region, for the mottle
    var = rng.uniform(0, 1e-4, (len(tex), 3))
    s = TexelSample.draw(tex, len(tex), len(tex), seed=0)
    assert len(s.points) == len(s.windows) == len(s.centres) == len(tex)
    loss = TexelLoss(target, tex.pos_vox, sigma=1.5)
    values = {k: per_texel(loss, (c, var), (c, var), loss.target_lab, s) for k, c in (("a", rgb), ("b", rgb2))}
    est, err = sampled_figures(loss, values["a"], s)
    full = prediction_metrics(loss, rgb, var)
    for k, v in full.to_json().items():
        assert np.isclose(getattr(est, k), v, rtol=1e-9, atol=1e-12), (k, getattr(est, k), v)
    assert err["delta_e76_mean"] == 0 and err["ssim"] == 0
    d = differences(values, [("a", "b")], s)["a - b"]
    other = prediction_metrics(loss, rgb2, var)
    for k in ("delta_e76_mean", "delta_e2000_mean", "ssim", "delta_e76_mean_corrected"):
        assert np.isclose(d[k]["value"], getattr(full, k) - getattr(other, k), rtol=1e-9, atol=1e-12), k


def test_standard_errors_cover_the_population_figure():
    """Over repeated samples of a skewed population, mean ± 2 SE covers the population mean and the 95th
    percentile ± 2 SE covers the population's about 95 % of the time (binomial tolerance: 4 standard errors of
    the coverage over 400 draws)."""
    rng = np.random.default_rng(3)
    population = rng.gamma(2.0, 5.0, 20000)
    mu, q95 = population.mean(), np.percentile(population, 95)
    reps, n = 400, 1500
    hit_mean = hit_q = 0
    for _ in range(reps):
        x = population[rng.choice(len(population), n, replace=False)]
        m, se = mean_se(x, len(population))
        q, qse = quantile_se(x, 95.0, len(population))
        hit_mean += abs(m - mu) <= 2 * se
        hit_q += abs(q - q95) <= 2 * qse
    tol = 4 * np.sqrt(0.954 * 0.046 / reps)
    assert abs(hit_mean / reps - 0.954) < tol and abs(hit_q / reps - 0.954) < tol + 0.02, (hit_mean, hit_q)
    assert mean_se(population, len(population))[1] == 0  # the whole population: no sampling error


def test_restricted_printer_texels_average_like_the_full_map():
    rng = np.random.default_rng(2)
    n_scene, n_p = 30, 120
    to_scene = rng.integers(0, n_scene, n_p)
    to_scene[np.isin(to_scene, [3, 8, 17])] = 0  # three scene texels get no printer texel: stand-ins
    stand_in = np.full(n_scene, -1)
    stand_in[[3, 8, 17]] = rng.integers(0, n_p, 3)
    ptex = Texels(np.zeros((n_p, 3)), np.zeros(n_p), np.zeros((n_p, 3)))
    rgb_p, var_p = rng.random((n_p, 3)), rng.random((n_p, 3))
    rgb, var = average_to_scene(rgb_p, var_p, to_scene, stand_in, n_scene)
    subset = np.array([1, 3, 4, 8, 20, 29])
    sub, sub_to, sub_stand = restrict(ptex, to_scene, stand_in, subset)
    keep = np.union1d(np.flatnonzero(np.isin(to_scene, subset)), stand_in[[3, 8]])
    assert len(sub) == len(keep)
    r2, v2 = average_to_scene(rgb_p[keep], var_p[keep], sub_to, sub_stand, len(subset))
    np.testing.assert_allclose(r2, rgb[subset])
    np.testing.assert_allclose(v2, var[subset])


def within(sampled: dict, full: dict, err: dict, k: float = 4.0) -> list:
    """Figures whose sampled value is more than k standard errors from the full evaluation's."""
    return [(f, sampled[f], full[f], err[f]) for f in FIGURES if abs(sampled[f] - full[f]) > k * err[f]]


def test_sampled_evaluation_agrees_with_the_full_one(tmp_path, table3):
    """A slab's figures from 600 of its 2304 texels (8 windows) lie within 4 standard errors of the full
    evaluation's at the same spp; results rendered alike give a difference of exactly 0 (same texels, same seeds)."""
    make_run(tmp_path / "run", table3, "extrusion", shape=(3, 48, 48))
    full = evaluate_run(
        tmp_path / "run", EvaluateOptions(spp=16, table=table3, texel_sample=0, out=tmp_path / "full.json")
    ).to_json()
    sampled = dict(texel_sample=600, sample_windows=8, out=tmp_path / "s.json")
    typed = evaluate_run(tmp_path / "run", EvaluateOptions(spp=16, table=table3, **sampled))
    ev = json.loads((tmp_path / "s.json").read_text())
    assert ev == json.loads(json.dumps(typed.to_json())) and ev["format_version"] == 2
    assert full.get("texel_sample") is None and "stderr" not in full["continuous"]
    t = ev["texel_sample"]
    assert (t["population"], t["texels"], t["windows"]) == (2304, 600, 8) and t["window_texels"] < 2304
    assert ev["printer_texels"] == full["printer_texels"] > t["printer_texels_rendered"]
    assert "pictures" not in ev and not (tmp_path / "run" / "s_top.png").exists()
    for name in ("continuous", "quantized"):
        assert not within(ev[name], full[name], ev[name]["stderr"]), name
    for name in ("surface", "extrusion"):
        assert not within(ev["baselines"][name], full["baselines"][name], ev["baselines"][name]["stderr"]), name
    d = ev["differences"]
    assert d["quantized - extrusion"]["delta_e76_mean"] == {"value": 0.0, "stderr": 0.0}  # the run IS extrusion
    pair, fpair = (
        d["continuous - quantized"],
        {k: full["continuous"][k] - full["quantized"][k] for k in ("delta_e76_mean", "ssim")},
    )
    for k in ("delta_e76_mean", "ssim"):
        assert abs(pair[k]["value"] - fpair[k]) <= 4 * pair[k]["stderr"], (k, pair[k], fpair[k])


def test_cli_texel_sample_errors(tmp_path, table3, capsys):
    make_run(tmp_path / "run", table3)
    assert main(["evaluate", str(tmp_path / "run"), "--texel-sample", "1", "--no-baselines"]) == 2
    assert "--texel-sample must be 0" in capsys.readouterr().err
    assert main(["evaluate", str(tmp_path / "run"), "--texel-sample", "50", "--sample-windows", "1"]) == 2
    assert "--sample-windows must be at least 2" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.skipif(not SPOT.is_file(), reason="Spot data set not present")
def test_spot_sampled_figures_agree_with_the_full_evaluation(tmp_path):
    """Spot 6 mm, optimised 1 iteration and quantized: at 32 spp, each result's sampled figures (2000 of ~8 k
    texels, 40 windows) lie within 4 standard errors of the full evaluation's, and so do the paired differences."""
    run = tmp_path / "run"
    argv = ["optimize", str(SPOT), "--height-mm", "6", "--iterations", "1", "--eval-spp", "4", "--out", str(run)]
    assert main(argv) == 0 and main(["quantize", str(run)]) == 0
    base = ["evaluate", str(run), "--spp", "32"]
    assert main(base + ["--texel-sample", "0", "--out", str(tmp_path / "full.json")]) == 0
    assert main(base + ["--texel-sample", "2000", "--sample-windows", "40", "--out", str(tmp_path / "s.json")]) == 0
    full, ev = (json.loads((tmp_path / f).read_text()) for f in ("full.json", "s.json"))
    rows = {"continuous": ev["continuous"], "quantized": ev["quantized"], **ev["baselines"]}
    frows = {"continuous": full["continuous"], "quantized": full["quantized"], **full["baselines"]}
    for name, r in rows.items():
        assert not within(r, frows[name], r["stderr"]), name
    for pair, figs in ev["differences"].items():
        a, b = pair.split(" - ")
        for k in ("delta_e76_mean", "delta_e2000_mean", "ssim"):
            assert abs(figs[k]["value"] - (frows[a][k] - frows[b][k])) <= 4 * figs[k]["stderr"], (pair, k)
