"""The baselines' spectral colour table (evaluation.spectral_table): its patches are the RGB table's patches rendered
band by band (a 3-band table bit for bit), cached independently of the light; its look-up under one light is the
colour table's under that light, and under several it minimises the sum over the lights of the squared ΔE76."""

import numpy as np
import pytest
from spectral_helpers import INKS, smooth_table

from inkopt.color import linear_to_lab
from inkopt.evaluation import spectral_table as st
from inkopt.evaluation.colour_table import ColourTable, render_patches, table_mixtures
from inkopt.model.spectral import SpectralInkTable
from inkopt.spectral.lights import named_light


def test_three_bands_render_the_rgb_tables_patches_bit_for_bit():
    """A 3-band table of the RGB table's channels: each patch's pilot (no second pass at a huge error target) is the
    RGB table's patch render, bit for bit; the variances are those of the pooled texels' means."""
    table = SpectralInkTable(INKS.names, [450.0, 550.0, 650.0], INKS.sigma_s, INKS.sigma_a, INKS.g)
    mix = table_mixtures(len(INKS), 2)[::4]
    bands, var = st.render_band_patches(mix, table, (INKS.g, 1.5), 2.5, 1e9, seed=3, threads=2)
    rgb, _ = render_patches(mix, INKS, INKS.g, 1.5, 2.5, 1e9, seed=3, threads=2)
    np.testing.assert_array_equal(bands, rgb)
    assert var.shape == bands.shape and np.all(var > 0)


def test_patches_are_cached_and_serve_every_light(tmp_path, monkeypatch):
    monkeypatch.setenv("INKOPT_CACHE_DIR", str(tmp_path))
    table = smooth_table()
    built = st.spectral_patches(table, step=1, max_stderr=2.0, threads=2)
    assert not built.cached and built.bands.shape == (len(INKS), table.bands) and np.all(built.bands_var > 0)
    monkeypatch.setattr(st, "render_band_patches", lambda *a, **k: pytest.fail("built again, not read"))
    again = st.spectral_patches(table, step=1, max_stderr=2.0, threads=2)
    assert again.cached and again.key == built.key
    np.testing.assert_array_equal(again.bands, built.bands)
    other = SpectralInkTable(table.names, table.wavelengths_nm, table.sigma_s * 1.01, table.sigma_a, table.g)
    assert st.spectral_table_key(other, table.g, 1.5, 2.5, 1, 2.0) != built.key
    # one build, any lights: each light's CIELAB from the same band values, the error the largest over the lights
    cmaps = tuple(named_light(n).colour_map(table.wavelengths_nm) for n in ("D65", "A"))
    ct = again.under(cmaps)
    assert ct.labs.shape == (2, len(INKS), 3) and ct.light_names == ("D65", "A")
    np.testing.assert_array_equal(ct.lab, cmaps[0].lab(again.bands))
    assert np.all(ct.stderr >= cmaps[1].lab_stderr(again.bands, again.bands_var))


def linear_table(lights: int, seed: int = 0) -> tuple[st.SpectralColourTable, list[np.ndarray]]:
    """A made-up table whose colour under each light is linear in the mixture (lab = mixture @ A_l), so a blend of
    entries is a blend of their colours exactly."""
    rng = np.random.default_rng(seed)
    mix = table_mixtures(len(INKS), 4)
    maps = [rng.normal(0.0, 40.0, (len(INKS), 3)) + [60.0, 0.0, 0.0] for _ in range(lights)]
    labs = np.stack([mix.astype(np.float64) @ a for a in maps])
    ct = st.SpectralColourTable(
        tuple(INKS.names), mix, np.zeros((len(mix), 3)), labs[0], np.zeros(len(mix)), 2.5, 4, "k",
        labs=labs, light_names=tuple(f"L{k}" for k in range(lights)),
    )  # fmt: skip
    return ct, maps


def test_one_light_looks_up_as_the_colour_table():
    ct, _ = linear_table(1)
    plain = ColourTable(ct.ink_names, ct.mixtures, ct.rgb, ct.lab, ct.stderr, 2.5, 4, "k")
    target = np.random.default_rng(1).uniform(0.02, 0.9, (50, 3))
    np.testing.assert_array_equal(ct.lookup(target), plain.lookup(target))
    np.testing.assert_array_equal(ct.lookup(target, refine=False), plain.lookup(target, refine=False))
    np.testing.assert_array_equal(ct.reachable_lab(target), plain.reachable_lab(target))


def test_several_lights_minimise_the_sum_of_their_errors():
    """Under two lights whose colours disagree, the look-up's mixture has a summed squared ΔE76 over the lights no
    larger than either light's own look-up's (to the blend's convergence), and smaller than one of them."""
    ct, maps = linear_table(2)
    target = np.random.default_rng(2).uniform(0.02, 0.9, (200, 3))
    lab_t = linear_to_lab(target)

    def cost(mix):
        return sum(np.sum((mix.astype(np.float64) @ a - lab_t) ** 2, axis=1) for a in maps)

    both = cost(ct.lookup(target))
    for k in range(2):
        alone = cost(ct.under_light(k).lookup(target))
        assert np.all(both <= alone * (1 + 1e-3) + 1e-3), np.max(both - alone)
        assert np.mean(both) < 0.95 * np.mean(alone)


def test_the_default_spectral_inks_table_ships_with_the_package(tmp_path, monkeypatch):
    """The spectral table of vero-cmykw@spectral (g 0.4, ior 1.5, the defaults) is in the package
    (``spectral_table.PACKAGED``) under the key the current code gives it, so a first spectral evaluation need not
    spend minutes building it; its patches' colours under D65 and A agree with fresh renders of 4 of them within 4
    combined standard errors. When this fails, the spectral presets or the table's parameters changed: rebuild it
    (``spectral_patches(load_ink_table("vero-cmykw@spectral"), 0.4, 1.5)`` with an empty ``INKOPT_CACHE_DIR``) and
    copy the cache's file into the package's data/spectral_colour_tables/."""
    from inkopt.color import delta_e76
    from inkopt.model.spectral import load_ink_table

    monkeypatch.setenv("INKOPT_CACHE_DIR", str(tmp_path))  # an empty cache: only the package has it
    monkeypatch.setattr(st, "render_band_patches", lambda *a, **k: pytest.fail("the table was built, not read"))
    table = load_ink_table("vero-cmykw@spectral")
    patches = st.spectral_patches(table, 0.4, 1.5)
    assert patches.cached and len(patches.mixtures) == len(table_mixtures(len(table.names), 8))
    assert sorted(p.name for p in st.PACKAGED.iterdir()) == [f"spectral_colour_table_{patches.key}.npz"]
    monkeypatch.undo()
    rows = np.array([0, 300, 600, 900])
    bands, var = st.render_band_patches(patches.mixtures[rows], table, (0.4, 1.5), 2.5, 0.3, seed=12, threads=2)
    for light in ("D65", "A"):
        cmap = named_light(light).colour_map(table.wavelengths_nm)
        se = np.hypot(cmap.lab_stderr(bands, var), cmap.lab_stderr(patches.bands[rows], patches.bands_var[rows]))
        assert np.all(delta_e76(cmap.lab(bands), cmap.lab(patches.bands[rows])) <= 4 * se), light


def test_the_run_lights_of_the_look_up(tmp_path):
    """The baselines look up under the run's lights: an evaluation light of the name, a named light, or the band
    matrix predictions.npz keeps for a light file that is gone; the evaluation's lights when one is found nowhere."""
    from inkopt.evaluation.spectral import run_colours
    from inkopt.rundir import BandValues, Predictions, RunDir
    from inkopt.spectral.viewing import Viewing

    table = smooth_table()
    lamp = np.random.default_rng(0).uniform(0.1, 1.0, (3, table.bands))
    d = RunDir(tmp_path)
    bands = BandValues({"continuous": np.ones((4, table.bands), np.float32)}, table.wavelengths_nm, {"lamp.csv": lamp})
    d.save_predictions(Predictions({"continuous": np.ones((4, 3), np.float32)}, "optimisation", {}, "x", {}, bands))
    viewing = Viewing(table, (named_light("D65"),))
    got = run_colours(d, ["A", "lamp.csv", "D65"], viewing)
    assert [c.name for c in got] == ["A", "lamp.csv", "D65"]
    np.testing.assert_array_equal(got[0].matrix, named_light("A").colour_map(table.wavelengths_nm).matrix)
    np.testing.assert_array_equal(got[1].matrix, lamp)
    assert [c.name for c in run_colours(d, ["gone.csv"], viewing)] == ["D65"]
