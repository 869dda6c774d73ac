"""Display lighting from the user's side (``inkopt.lighting`` and ``--lighting``): reading maps (.hdr, .exr, .npy),
one-line errors for bad maps, the map's orientation as the renderer sees it, and the commands that take it.
(The renderer under maps against references: tests/render/test_lighting_render.py.)"""

import json

import numpy as np
import pytest

from inkopt import charts
from inkopt.cli import main
from inkopt.lighting import Lighting, load_lighting, mean_radiance, read_map, write_map
from inkopt.model import Texels, Volume
from inkopt.render import Renderer


def smooth_map(h=16):
    rng = np.random.default_rng(1)
    return rng.uniform(0.05, 4.0, (h, 2 * h, 3)).astype(np.float32)


@pytest.mark.parametrize("suffix,rtol", [(".npy", 0), (".exr", 0), (".hdr", 2**-7)])
def test_maps_round_trip_through_their_files(tmp_path, suffix, rtol):
    """.npy and OpenEXR keep float32 exactly; Radiance RGBE keeps 8 mantissa bits shared by a pixel's channels
    (relative error at most 2^-8 of the pixel's largest channel)."""
    env = smooth_map()
    path = write_map(tmp_path / f"m{suffix}", env)
    back = read_map(path)
    assert back.shape == env.shape and back.dtype == np.float32
    scale = env.max(axis=2, keepdims=True)
    assert np.all(np.abs(back - env) <= rtol * scale), np.abs(back - env).max()
    light = load_lighting(path, 15.0)
    assert light.source == f"m{suffix}" and light.rotate_deg == 15.0 and not light.uniform
    assert light.describe()["lighting_map_shape"] == [16, 32, 3]


def test_mean_radiance_is_solid_angle_weighted():
    env = np.zeros((64, 128, 3), np.float32)
    env[:32] = 1.0  # upper hemisphere: half the sphere
    np.testing.assert_allclose(mean_radiance(env), 0.5, atol=1e-12)
    np.testing.assert_allclose(mean_radiance(np.full((8, 16, 3), 2.0, np.float32)), 2.0)


@pytest.mark.parametrize(
    "arr,needle",
    [
        (np.ones((4, 6, 3)), "not an equirectangular map: 6 x 4"),
        (np.ones((4, 8)), "(H, W, 3)"),
        (np.ones((4, 8, 4)), "(H, W, 3)"),
        (np.where(np.arange(96).reshape(4, 8, 3) == 50, -1.0, 1.0), "negative radiance -1 at row 2, column 0"),
        (np.where(np.arange(96).reshape(4, 8, 3) == 7, np.nan, 1.0), "NaN or infinite at row 0, column 2"),
    ],
)
def test_bad_maps_are_one_line_errors(tmp_path, capsys, arr, needle):
    path = tmp_path / "bad.npy"
    np.save(path, arr)
    with pytest.raises(ValueError, match=None) as e:
        read_map(path)
    assert needle in str(e.value) and "\n" not in str(e.value)
    vol = tmp_path / "v.npz"
    Volume.from_coefficients(
        voxel_mm=(0.1,) * 3, sigma_s=np.ones((2, 2, 2, 3), np.float32), sigma_a=np.ones((2, 2, 2, 3), np.float32)
    ).save(vol)
    assert main(["render", str(vol), "--spp", "1", "--lighting", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("inkopt: error:") and needle in err[0]


def test_unreadable_lighting(tmp_path):
    (tmp_path / "junk.hdr").write_text("not a picture")
    for spec, needle in [
        (tmp_path / "none.exr", "no such file"),
        (tmp_path / "junk.hdr", "not a readable .hdr"),
        (tmp_path / "sky.png", "use 'uniform' or a map file"),
    ]:
        with pytest.raises(ValueError, match=needle):
            load_lighting(spec)
    with pytest.raises(ValueError, match="no meaning with uniform"):
        load_lighting("uniform", 90)


@pytest.mark.parametrize("suffix", [".hdr", ".exr"])
def test_map_headers_give_the_size(tmp_path, suffix):
    from inkopt.lighting import _map_size

    assert _map_size(write_map(tmp_path / f"m{suffix}", np.ones((6, 12, 3), np.float32))) == (12, 6)


def test_huge_maps_are_refused_before_decoding(tmp_path):
    """A Radiance header declaring 20000 x 10000 pixels (a few bytes of data): refused by its header, in one line
    naming the file, its pixel count and the limit."""
    path = tmp_path / "bomb.hdr"
    path.write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 10000 +X 20000\n" + b"\x02\x02\x4e\x20" * 4)
    with pytest.raises(ValueError, match=r"^lighting '.*bomb.hdr' has 20000 x 10000 px, 200,000,000 pixels, more"):
        load_lighting(path)


def _lobe_map(axis, h=32):
    """Radiance 1 + 4 max(0, d . axis)^2 over the sphere (cell centres)."""
    theta = (np.arange(h) + 0.5) * np.pi / h
    phi = (np.arange(2 * h) + 0.5) * np.pi / h
    st = np.sin(theta)[:, None]
    d = np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)[:, None] + 0 * phi], -1)
    lobe = np.clip(d @ np.asarray(axis, float), 0, None) ** 2
    return np.repeat((1 + 4 * lobe)[..., None], 3, -1).astype(np.float32)


@pytest.mark.parametrize(
    "axis,rotate,lit,dark",
    [
        ((1, 0, 0), 0.0, "+x", "-x"),
        ((0, 0, 1), 0.0, "top", "bottom"),
        ((1, 0, 0), 90.0, "+y", "-y"),
        ((0, 1, 0), 90.0, "-x", "+x"),
    ],
)
def test_the_lit_side_is_where_the_map_says(axis, rotate, lit, dark):
    """A grey cube under a map bright around ``axis`` (turned by ``rotate`` about z, from +x towards +y): the face
    looking at the light is brighter than the opposite one by far more than the noise."""
    s = np.full((6, 6, 6, 3), 10.0, np.float32)
    vol = Volume.from_coefficients(voxel_mm=(0.1,) * 3, sigma_s=s, sigma_a=np.full_like(s, 1.0))
    rnd = Renderer(vol, lighting=Lighting(_lobe_map(axis), rotate, "lobe"))
    res = {f: rnd.render(Texels.for_volume(vol, [f]), spp=256, seed=2) for f in (lit, dark)}
    gap = res[lit].mean_rgb - res[dark].mean_rgb
    se = np.hypot(res[lit].mean_rgb_stderr, res[dark].mean_rgb_stderr)
    assert np.all(gap > 6 * se) and np.all(gap > 0.1), (gap, se)


def test_render_cli_with_a_map(tmp_path, capsys):
    """Radiance 1 everywhere renders exactly as uniform light; --lighting-rotate is reported."""
    s = np.full((3, 4, 4, 3), 5.0, np.float32)
    path = tmp_path / "v.npz"
    Volume.from_coefficients(voxel_mm=(0.1,) * 3, sigma_s=s, sigma_a=np.full_like(s, 0.5)).save(path)
    ones = write_map(tmp_path / "ones.npy", np.ones((4, 8, 3), np.float32))
    outs = []
    for extra in ([], ["--lighting", str(ones), "--lighting-rotate", "45"]):
        assert main(["render", str(path), "--spp", "4", "--json"] + extra) == 0
        outs.append(json.loads(capsys.readouterr().out))
    assert outs[0]["mean_rgb"] == outs[1]["mean_rgb"]
    assert outs[0]["lighting"] == "uniform" and outs[1]["lighting"] == "ones.npy"
    assert outs[1]["lighting_rotate_deg"] == 45


def test_slab_and_evaluate_under_a_map(tmp_path, capsys):
    """`slab --lighting MAP` optimises and reports under the map (and resumes only under the same one);
    `evaluate --lighting` renders every result under the lighting it is given."""
    chart = charts.save(charts.colour_chart(24, 16), tmp_path / "chart.png")
    env = write_map(tmp_path / "sky.npy", _lobe_map((0.6, 0, 0.8), h=16) * 0.5)
    out = tmp_path / "run"
    args = [
        "slab",
        str(chart),
        "--size-mm",
        "2x1.333x0.5",
        "--out",
        str(out),
        "--iterations",
        "2",
        "--spp",
        "1",
        "--forward-spp",
        "2",
        "--eval-spp",
        "4",
        "--inks",
        "cyan,magenta,yellow,white",
    ]
    assert main(args + ["--lighting", str(env), "--lighting-rotate", "20"]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["lighting"] == "sky.npy" and rep["lighting_rotate_deg"] == 20.0
    capsys.readouterr()
    assert main(args + ["--resume", "--iterations", "3"]) == 2  # uniform now: a different run
    assert "different settings" in capsys.readouterr().err
    for spec in ("uniform", str(env)):
        assert main(["evaluate", str(out), "--spp", "4", "--no-baselines", "--json", "--lighting", spec]) == 0
        ev = json.loads(capsys.readouterr().out)
        assert ev["lighting"] == ("uniform" if spec == "uniform" else "sky.npy")
        assert np.isfinite(ev["continuous"]["delta_e76_mean"])
