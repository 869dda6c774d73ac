"""Tests of the translucency figures under lights (inkopt.evaluation.translucency_lights): flat spectra against the
RGB figures, a spectrally non-flat ink whose transmittance differs between D65 and A against its bands' own
transmittances weighed by each light, and ``inkopt evaluate`` of a constrained spectral slab."""

import json

import numpy as np
import pytest
from PIL import Image

from inkopt import charts, cli
from inkopt.evaluation.translucency import TranslucencyRenders, knife_edge_spread, transmittance
from inkopt.evaluation.translucency_lights import band_spread, band_transmittance, luminance_weights
from inkopt.model import InkTable, Texels, Volume
from inkopt.model.inks import mix
from inkopt.model.spectral import SpectralInkTable
from inkopt.spectral.lights import named_light

pytest.importorskip("inkopt._core")

VOX = 25.4 / 300
WL = np.linspace(400.0, 700.0, 16)
RENDERS = TranslucencyRenders(spp=64, probe_spp=16, seed=3, threads=2)
#: two inks flat over wavelength: a scattering white and a clear one, (N, 3) mm^-1
FLAT_S, FLAT_A = np.array([[6.0] * 3, [0.05] * 3]), np.array([[0.02] * 3, [0.01] * 3])


def weights(*names):
    return luminance_weights(tuple(named_light(n).colour_map(WL) for n in names))


def flat_tables() -> tuple[InkTable, SpectralInkTable]:
    """The two flat inks as an RGB table and as a 16-band table of the same coefficients in every band."""
    rgb = InkTable(("W", "T"), FLAT_S, FLAT_A, 0.4)
    band = lambda sig: np.repeat(sig[:, :1], len(WL), axis=1)
    return rgb, SpectralInkTable(("W", "T"), WL, band(FLAT_S), band(FLAT_A), 0.4)


def slab(inks, shares, layers=12) -> tuple[Volume, Texels]:
    """A 6 x 6 x ``layers`` slab of one mixture ``shares`` (N,) of ``inks`` and its top texels."""
    m = np.broadcast_to(np.asarray(shares, np.float32), (layers, 6, 6, len(shares))).copy()
    vol = Volume.from_mixture((VOX,) * 3, m, inks, g=0.4, ior=1.5)
    return vol, Texels.box_faces(vol.shape, ["top"])


def mean_se(y, var):
    return float(np.mean(y)), float(np.sqrt(np.sum(var)) / len(y))


def test_flat_spectra_transmittance_as_rgb_under_every_light():
    rgb, table = flat_tables()
    vol, tex = slab(rgb, [0.3, 0.7])
    y, var = transmittance(vol, tex, RENDERS.spp, RENDERS.seed, RENDERS.threads)
    ref, ref_se = mean_se(y, var)
    t, tv = band_transmittance(vol, tex, table, RENDERS)
    for name, w in weights("D65", "A", "F11").items():
        got, se = mean_se(t @ w, tv @ w**2)
        assert abs(got - ref) < 4.5 * np.hypot(se, ref_se), name
        assert 0.05 < got < 0.95  # the slab lets some light through and scatters some back


def test_flat_spectra_spread_as_rgb():
    rgb, table = flat_tables()
    mixture = np.tile([0.5, 0.5], (8, 1))
    s_s, s_a = mix(mixture, rgb)
    ref = knife_edge_spread(s_s, s_a, VOX, 0.4, 1.5, RENDERS, width=128)
    for name, got in band_spread(mixture, table, VOX, 0.4, 1.5, RENDERS, weights("D65", "A"), width=128).items():
        se = np.hypot(got["spread_stderr_mm"], ref["spread_stderr_mm"])
        assert abs(got["spread_mm"] - ref["spread_mm"]) < 4.5 * se, name
        assert got["spread_mm"] > 5 * got["spread_stderr_mm"]
        assert got["probe_transmittance"] == pytest.approx(ref["probe_transmittance"], rel=0.05)


def test_non_flat_ink_transmits_by_the_light():
    """An ink clear below 550 nm and dark above: under each light its transmittance is its clear bands' share of the
    light's luminance times a clear slab's transmittance plus the rest times a dark one's (both rendered as RGB),
    and it differs between D65 and A (A has less blue) by many standard errors."""
    blue = WL < 550.0
    sigma_a = np.where(blue, 0.01, 8.0)[None]
    table = SpectralInkTable(("C",), WL, np.full((1, len(WL)), 1.0), sigma_a, 0.4)
    parts = {}
    for name, a in (("clear", 0.01), ("dark", 8.0)):
        vol, tex = slab(InkTable(("C",), np.full((1, 3), 1.0), np.full((1, 3), a), 0.4), [1.0])
        parts[name] = mean_se(*transmittance(vol, tex, RENDERS.spp, RENDERS.seed + 17, RENDERS.threads))
    vol, tex = slab(InkTable(("C",), np.full((1, 3), 1.0), np.full((1, 3), 0.01), 0.4), [1.0])
    t, tv = band_transmittance(vol, tex, table, RENDERS)
    got = {}
    for name, w in weights("D65", "A").items():
        got[name] = mean_se(t @ w, tv @ w**2)
        share = w[blue].sum()
        want = share * parts["clear"][0] + (1 - share) * parts["dark"][0]
        se = np.hypot(got[name][1], np.hypot(share * parts["clear"][1], (1 - share) * parts["dark"][1]))
        assert abs(got[name][0] - want) < 4.5 * se, name
    diff, se = got["D65"][0] - got["A"][0], np.hypot(got["D65"][1], got["A"][1])
    assert diff > 10 * se


def test_evaluate_constrained_spectral_slab(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("inkopt.evaluation.translucency.PROBE_SPP", 8)  # fast probes: the entry's shape is tested
    monkeypatch.setattr("inkopt.evaluation.translucency.PROBE_WIDTH", 64)
    monkeypatch.setattr("inkopt.evaluation.translucency.DEFAULT_SPP", 8)
    chart = charts.save(charts.colour_chart(24, 16), tmp_path / "chart.png")
    m = np.zeros((16, 24), np.uint8)
    m[:, :12] = 204  # 80 % transparent in the left half
    Image.fromarray(m).save(tmp_path / "mask.png")
    args = ["slab", str(chart), "--size-mm", "2.032x1.355x0.5", "--iterations", "1", "--spp", "1", "--forward-spp"]
    args += ["1", "--eval-spp", "2", "--threads", "2", "--inks", "vero-cmykwt@spectral", "--illuminants", "D65,A"]
    args += ["--out", str(tmp_path / "tr"), "--translucency", str(tmp_path / "mask.png")]
    assert cli.main(args) == 0
    evaluate = ["evaluate", str(tmp_path / "tr"), "--spp", "2", "--no-baselines", "--threads", "2", "--json"]
    capsys.readouterr()
    assert cli.main(evaluate) == 0
    tr = json.loads(capsys.readouterr().out)["translucency"]
    assert tr["lights"] == ["D65", "A"] and len(tr["regions"]) == 1
    region = tr["regions"][0]
    assert region["texels"] == 16 * 24 // 2 and region["required_share"] == pytest.approx(0.8, abs=0.01)
    for r in (region, tr["whole"]):
        assert set(r["by_light"]) == {"D65", "A"}
        assert r["transmittance"] == r["by_light"]["D65"]["transmittance"]  # the first light's at the top level
        for f in r["by_light"].values():
            assert 0 < f["transmittance"] < 1 and np.isfinite(f["spread_mm"]) and r["probe_layers"] == 6
    file = json.loads((tmp_path / "tr" / "evaluation_lights.json").read_text())
    assert file["translucency"]["regions"][0]["by_light"] == region["by_light"]
    assert cli.main(evaluate[:-1]) == 0  # the lines: the first light's figures
    assert "translucency under D65" in capsys.readouterr().out
    assert cli.main(["evaluate", str(tmp_path / "tr"), "--spp", "2", "--no-baselines", "--no-translucency"]) == 0
    assert "translucency" not in json.loads((tmp_path / "tr" / "evaluation_lights.json").read_text())
