"""Tests of the translucency measurements (inkopt.evaluation.translucency): diffuse transmittance against the
closed form of a non-scattering slab, the knife-edge spread on known cases, and ``inkopt evaluate`` of a
constrained slab beside an unconstrained run of the same target."""

import json

import numpy as np
import pytest
from helpers import FAST_RUN, load_file_module
from PIL import Image

from inkopt import charts, cli
from inkopt.evaluation.translucency import TranslucencyRenders, back_light, knife_edge_spread, transmittance
from inkopt.model import Texels, Volume

pytest.importorskip("inkopt._core")

VOX = 25.4 / 300
R0 = ((1.5 - 1) / (1.5 + 1)) ** 2  # Fresnel reflectance at normal incidence, index 1.5


def slab_t(sigma_a: float, d: float) -> float:
    """Transmittance of a non-scattering slab at normal incidence with all internal reflections (closed form)."""
    e = np.exp(-sigma_a * d)
    return (1 - R0) ** 2 * e / (1 - R0**2 * e**2)


def test_back_light_is_lit_behind_the_face():
    env = back_light(5).map  # top face: lit from below only
    assert np.all(env[:16] == 0) and np.all(env[16:] == 1)
    env = back_light(0).map  # -x face: lit where dir.x > 0, i.e. columns near longitude 0
    assert env[16, 0, 0] == 1 and env[16, 32, 0] == 0


@pytest.mark.parametrize("sigma_a", [0.0, 2.0])
def test_transmittance_of_non_scattering_slab(sigma_a):
    L = 12
    vol = Volume.from_coefficients(
        voxel_mm=(VOX,) * 3,
        sigma_s=np.zeros((L, 6, 6, 3), np.float32),
        sigma_a=np.full((L, 6, 6, 3), sigma_a + 1e-6, np.float32),
        g=0.4,
        ior=1.5,
    )
    y, var = transmittance(vol, Texels.box_faces(vol.shape, ["top"]), spp=128, threads=2)
    se = np.sqrt(var.sum()) / len(y)
    assert abs(y.mean() - slab_t(sigma_a, L * VOX)) < 4 * se + 2e-3


FAST_PROBE = TranslucencyRenders(probe_spp=16, threads=2)


def test_knife_edge_known_cases():
    """No scattering: the view ray goes straight through, E|dx| = 0 and the probe transmits the Fresnel value.
    Scattering spreads light sideways, more through a thicker slab; a strongly scattering (white) slab passes less
    light than a clear one."""
    clear = knife_edge_spread(np.zeros((6, 3)), np.full((6, 3), 1e-4), VOX, 0.4, 1.5, FAST_PROBE)
    assert clear["spread_mm"] == 0.0 and clear["probe_transmittance"] == pytest.approx(slab_t(0, 0), abs=0.01)
    thin = knife_edge_spread(np.full((4, 3), 9.0), np.full((4, 3), 0.01), VOX, 0.4, 1.5, FAST_PROBE, width=128)
    thick = knife_edge_spread(np.full((12, 3), 9.0), np.full((12, 3), 0.01), VOX, 0.4, 1.5, FAST_PROBE, width=128)
    assert thin["spread_mm"] > 5 * thin["spread_stderr_mm"]
    diff, se = thick["spread_mm"] - thin["spread_mm"], np.hypot(thick["spread_stderr_mm"], thin["spread_stderr_mm"])
    assert diff > 4 * se
    assert thick["probe_transmittance"] < thin["probe_transmittance"] < clear["probe_transmittance"]


def test_evaluate_constrained_beside_unconstrained(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("inkopt.evaluation.translucency.PROBE_SPP", 16)  # fast probes: only the order is tested
    monkeypatch.setattr("inkopt.evaluation.translucency.PROBE_WIDTH", 96)
    chart = charts.save(charts.colour_chart(24, 16), tmp_path / "chart.png")
    m = np.zeros((16, 24), np.uint8)
    m[:, :12] = 204  # 80 % transparent in the left half
    Image.fromarray(m).save(tmp_path / "mask.png")
    base = [
        "slab",
        str(chart),
        "--size-mm",
        "2.032x1.355x0.5",
        "--iterations",
        "2",
        "--spp",
        "1",
        "--forward-spp",
        "1",
        "--eval-spp",
        "2",
        "--threads",
        "2",
        "--inks",
        "vero-cmykwt",
    ]
    assert cli.main(base + ["--out", str(tmp_path / "free")]) == 0
    assert cli.main(base + ["--out", str(tmp_path / "tr"), "--translucency", str(tmp_path / "mask.png")]) == 0
    capsys.readouterr()
    assert (
        cli.main(
            [
                "evaluate",
                str(tmp_path / "tr"),
                "--spp",
                "4",
                "--no-baselines",
                "--threads",
                "2",
                "--translucency-compare",
                str(tmp_path / "free"),
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "unconstrained region 1" in text and "transmittance" in text
    row = next(line for line in text.splitlines() if line.startswith("unconstrained region 1"))
    assert row.split()[4] == "-"  # "unconstrained region 1", texels, then no required share
    ev = json.loads((tmp_path / "tr" / "evaluation.json").read_text())
    tr = ev["translucency"]
    assert len(tr["regions"]) == 1 and len(tr["compare"]["regions"]) == 1
    ours, theirs = tr["regions"][0], tr["compare"]["regions"][0]
    assert ours["texels"] == theirs["texels"] == 16 * 24 // 2
    assert ours["required_share"] == pytest.approx(0.8, abs=0.01)
    assert theirs["required_share"] is None  # the unconstrained run was required nothing
    se = np.hypot(ours["transmittance_stderr"], theirs["transmittance_stderr"])
    assert ours["transmittance"] - theirs["transmittance"] > 4 * se  # the constrained region lets light through
    for r in (ours, theirs, tr["whole"]):
        assert np.isfinite(r["spread_mm"]) and r["probe_layers"] == 6 and "delta_e76_mean" in r


@pytest.mark.slow
def test_evaluate_mesh_alpha_region(tmp_path, capsys, monkeypatch):
    """A 1 mm cube whose texture alpha asks for 80 % transparent ink on five faces: evaluate finds the region (all
    but the opaque top face), every texel axis gets its own back light, and the region transmits more than the
    unconstrained run's."""
    from pathlib import Path

    mod = load_file_module(Path(__file__).parents[1] / "scenes" / "test_translucency.py", "scene_tr")
    monkeypatch.setattr("inkopt.evaluation.translucency.PROBE_SPP", 16)
    monkeypatch.setattr("inkopt.evaluation.translucency.PROBE_WIDTH", 96)
    cube = mod._alpha_cube(tmp_path)
    base = [
        "optimize",
        str(cube),
        "--scale",
        "1",
        "--up",
        "z",
        *FAST_RUN,
        "--inks",
        "vero-cmykwt",
    ]
    assert (
        cli.main(base + ["--out", str(tmp_path / "tr"), "--translucency", "alpha", "--translucency-depth-mm", "0.3"])
        == 0
    )
    assert cli.main(base + ["--out", str(tmp_path / "free")]) == 0
    assert (
        cli.main(
            [
                "evaluate",
                str(tmp_path / "tr"),
                "--spp",
                "4",
                "--no-baselines",
                "--threads",
                "2",
                "--translucency-compare",
                str(tmp_path / "free"),
            ]
        )
        == 0
    )
    tr = json.loads((tmp_path / "tr" / "evaluation.json").read_text())["translucency"]
    ours, theirs = tr["regions"][0], tr["compare"]["regions"][0]
    assert len(tr["regions"]) == 1 and ours["texels"] > 0.6 * tr["whole"]["texels"]
    se = np.hypot(ours["transmittance_stderr"], theirs["transmittance_stderr"])
    assert ours["transmittance"] - theirs["transmittance"] > 4 * se
