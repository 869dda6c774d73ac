"""``inkopt render`` with a spectral ink table: a volume's bands rendered and shown under each light asked.

A flat-spectrum table renders as the RGB renderer renders the same grey inks (within the standard error) and looks
the same under every light; a slab of smooth spectra is shown under D65 and A as adding-doubling's reflectance per
band under those lights says (within the standard error); a spectral run's volume renders its own table when a
light is asked; gradients take a band adjoint; without anything spectral the render is the RGB one bit for bit; a
bad light or an RGB --inks is one line naming the flag."""

import json

import numpy as np
import pytest
from spectral_helpers import INKS, smooth_table

from inkopt.cli import main
from inkopt.lighting import write_map
from inkopt.model import InkTable, Texels, Volume
from inkopt.model.spectral import SpectralInkTable, write_spectral_ink_file
from inkopt.render import Renderer
from inkopt.rundir import RunDir
from inkopt.spectral.lights import named_light
from inkopt.spectral.render import SpectralRenderer
from inkopt.spectral.viewing import display_under

VOX = 0.0847
WL = np.linspace(400.0, 700.0, 16)


def mixture_volume(inks: InkTable, shape=(5, 6, 7), seed=0) -> Volume:
    rng = np.random.default_rng(seed)
    m = rng.dirichlet(np.ones(len(inks)), size=shape).astype(np.float32)
    return Volume.from_mixture(voxel_mm=(VOX,) * 3, mixture=m, inks=inks)


def grey_tables() -> tuple[InkTable, SpectralInkTable]:
    """The Vero inks made grey: each ink's σs, σa the mean of its RGB ones, the same in R, G, B and in 16 bands."""
    s, a = INKS.sigma_s.mean(axis=1, keepdims=True), INKS.sigma_a.mean(axis=1, keepdims=True)
    rgb = InkTable(INKS.names, np.repeat(s, 3, axis=1), np.repeat(a, 3, axis=1), INKS.g)
    return rgb, SpectralInkTable(INKS.names, WL, np.repeat(s, WL.size, axis=1), np.repeat(a, WL.size, axis=1), INKS.g)


def render_json(capsys, *args) -> dict:
    capsys.readouterr()
    assert main(["render", *map(str, args), "--json", "--threads", "2"]) == 0
    return json.loads(capsys.readouterr().out)


def test_flat_spectra_render_as_rgb_under_every_light(tmp_path, capsys):
    """Grey inks: every band estimates what each RGB channel does, and a flat reflectance adapted to D65 is the same
    linear sRGB under D65, A and F11. The spectral render's mean (seed 0) against the RGB render's (seed 1000,
    independent noise): within 4.5 combined standard errors per channel."""
    rgb, flat = grey_tables()
    mixture_volume(rgb).save(tmp_path / "v.npz")
    inks = write_spectral_ink_file(tmp_path / "flat.json", flat)
    spec = render_json(capsys, tmp_path / "v.npz", "--inks", inks, "--illuminants", "D65,A,F11", "--spp", "32")
    ref = render_json(capsys, tmp_path / "v.npz", "--spp", "32", "--seed", "1000")
    assert spec["colour"] == "spectral" and spec["illuminants"] == ["D65", "A", "F11"] and "colour" not in ref
    for light, shown in spec["by_light"].items():
        diff = np.subtract(shown["mean_rgb"], ref["mean_rgb"])
        se = np.hypot(shown["mean_rgb_stderr"], ref["mean_rgb_stderr"])
        assert np.all(np.abs(diff) < 4.5 * se), (light, diff, se)
        # the shown standard error is the bands' carried through: a flat colour averages 16 bands' noise
        assert np.all(np.array(shown["mean_rgb_stderr"]) < np.array(ref["mean_rgb_stderr"]))
    # a flat reflectance adapted to D65 is the same grey under every light (the lights differ only by noise above)
    grey = np.full((1, WL.size), 0.3)
    for light in ("D65", "A", "F11"):
        np.testing.assert_allclose(display_under(named_light(light).colour_map(WL), grey), 0.3, rtol=1e-9)


def test_lights_shown_as_adding_doubling_says(tmp_path):
    """A 1 mm layer of cyan and white of smooth spectra (not flat), lit from the upper hemisphere: its colour under
    D65 and under A (linear sRGB adapted to D65), and the change between them, within four standard errors plus the
    quadrature's own error (|AD16 - AD32|) of what adding-doubling's reflectance per band gives; the change is more
    than ten of its standard errors (the lights are told apart)."""
    pytest.importorskip("iadpython")
    from inkopt.calibration.stack import channel_reflectance, upper_hemisphere

    table = smooth_table()
    share = np.array([0.6, 0.0, 0.0, 0.0, 0.4])
    m = np.broadcast_to(share.astype(np.float32), (20, 1, 1, 5)).copy()
    vol = Volume.from_mixture((0.1, 0.1, 0.05), m, INKS, g=float(INKS.g), ior=1.5, boundary="periodic-xy")
    vol.save(tmp_path / "v.npz")
    write_map(tmp_path / "hemi.npy", upper_hemisphere().map)
    inks = write_spectral_ink_file(tmp_path / "smooth.json", table)
    out = tmp_path / "o.npz"
    args = ["render", tmp_path / "v.npz", "--inks", inks, "--illuminants", "D65,A", "--lighting", tmp_path / "hemi.npy"]
    assert main([*map(str, args), "--face", "top", "--spp", "200000", "--out", str(out), "--threads", "2"]) == 0
    s, a = share @ table.sigma_s, share @ table.sigma_a
    ad = {n: np.array([channel_reflectance([(s[b], a[b], 1.0)], table.g, 1.5, n) for b in range(6)]) for n in (16, 32)}
    with np.load(out) as o:
        assert list(o["illuminants"]) == ["D65", "A"] and o["bands"].shape == (1, 6)
        shown, var, band_var = o["rgb_by_light"][:, 0], o["rgb_var_mean_by_light"][:, 0], o["bands_var_mean"][0]
    cmaps = [named_light(light).colour_map(table.wavelengths_nm) for light in ("D65", "A")]
    want = np.array([display_under(c, ad[32]) for c in cmaps])
    quad = np.abs(np.array([display_under(c, ad[16]) for c in cmaps]) - want)
    assert np.all(np.abs(shown - want) < 4 * np.sqrt(var) + quad), (shown, want, var)
    change = display_under(cmaps[0], np.eye(6)) - display_under(cmaps[1], np.eye(6))  # (B, 3): D65 minus A per band
    change_se = np.sqrt(band_var @ change**2)
    got, expected = shown[0] - shown[1], want[0] - want[1]
    assert np.all(np.abs(got - expected) < 4 * change_se + quad[0] + quad[1]), (got, expected, change_se)
    assert np.max(np.abs(expected) / change_se) > 10


def test_a_spectral_runs_volume_renders_its_own_table(tmp_path, capsys):
    """A volume beside spectral_inks.json (a spectral run's) with a light asked: its bands are the spectral
    renderer's with that table, bit for bit; without a light, the stored RGB table and a note."""
    table = smooth_table()
    mixture_volume(INKS).save(tmp_path / "volume.npz")
    write_spectral_ink_file(tmp_path / RunDir.SPECTRAL_INKS, table)
    out = tmp_path / "o.npz"
    got = render_json(capsys, tmp_path / "volume.npz", "--illuminant", "A", "--spp", "4", "--seed", "3", "--out", out)
    vol = Volume.load(tmp_path / "volume.npz")
    want = SpectralRenderer(vol, table, threads=1).render(Texels.for_volume(vol), spp=4, seed=3)
    with np.load(out) as o:
        np.testing.assert_array_equal(o["bands"], want.rgb)
        np.testing.assert_array_equal(o["bands_var_mean"], want.var_mean)
        np.testing.assert_array_equal(o["rgb"], o["rgb_by_light"][0])
    assert got["illuminants"] == ["A"] and got["mean_bands"] == [float(x) for x in want.mean_rgb]
    plain = render_json(capsys, tmp_path / "volume.npz", "--spp", "1")
    assert "colour" not in plain


def test_a_band_adjoint_gives_the_band_gradient(tmp_path, capsys):
    table = smooth_table()
    vol = mixture_volume(INKS)
    vol.save(tmp_path / "v.npz")
    inks = write_spectral_ink_file(tmp_path / "s.json", table)
    tex = Texels.for_volume(vol)
    adj = np.random.default_rng(2).normal(size=(len(tex), table.bands)).astype(np.float32)
    np.save(tmp_path / "adj.npy", adj)
    out = tmp_path / "g.npz"
    render_json(capsys, tmp_path / "v.npz", "--inks", inks, "--adjoint", tmp_path / "adj.npy", "--out", out)
    gs, ga, _ = SpectralRenderer(vol, table, threads=1).gradient(tex, adj, spp=16, seed=0)
    with np.load(out) as g:
        np.testing.assert_array_equal(g["grad_sigma_s"], gs)
        np.testing.assert_array_equal(g["grad_sigma_a"], ga)
    np.save(tmp_path / "bad.npy", adj[:, :3])
    assert main(["render", str(tmp_path / "v.npz"), "--inks", str(inks), "--adjoint", str(tmp_path / "bad.npy")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"expected ({len(tex)}, 6) (texels x bands)" in err[0], err


def test_nothing_spectral_is_the_rgb_render_bit_for_bit(tmp_path):
    vol = mixture_volume(INKS)
    vol.save(tmp_path / "v.npz")
    want = Renderer(vol, threads=1).render(Texels.for_volume(vol), spp=4, seed=5)
    for extra in ([], ["--illuminant", "D65"]):
        out = tmp_path / f"o{len(extra)}.npz"
        assert main(["render", str(tmp_path / "v.npz"), "--spp", "4", "--seed", "5", "--out", str(out), *extra]) == 0
        with np.load(out) as o:
            np.testing.assert_array_equal(o["rgb"], want.rgb)
            np.testing.assert_array_equal(o["rgb_var_mean"], want.var_mean)
            assert "bands" not in o


@pytest.mark.parametrize(
    "flags,message",
    [
        (["--illuminant", "D93"], "--illuminant must be one of D50, D65, A, F11, LED-B3 or a .csv file, got 'D93'"),
        (["--illuminant", "A"], "--illuminants A: a light other than D65 needs a spectral ink table"),
        (["--illuminants", "D65,A,A"], "--illuminants names a light twice"),
        (["--inks", "vero-cmykw", "--illuminant", "A"], "--inks vero-cmykw is an RGB ink table"),
        (["--inks", "vero-cmykw+orange@spectral"], "--inks ['cyan', 'magenta', 'yellow', 'black', 'white', 'orange']"),
        (["--illuminant", "LAMP"], "lamp.csv: line 2: not two numbers"),
    ],
)
def test_bad_lights_and_inks_are_one_line(tmp_path, capsys, flags, message):
    mixture_volume(INKS).save(tmp_path / "v.npz")
    (tmp_path / "lamp.csv").write_text("nm,power\n400,x\n")
    flags = [str(tmp_path / "lamp.csv") if f == "LAMP" else f for f in flags]
    assert main(["render", str(tmp_path / "v.npz"), "--spp", "1", *flags]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("inkopt: error: ") and message in err[0], err
