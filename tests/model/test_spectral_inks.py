"""Spectral ink tables: the ink file format (version 2: RGB and spectral in one format, older RGB files upgraded),
``load_ink_table`` and the presets' spectral form (``SpectralInkTable.from_rgb``); the reader fuzzed (one clean
one-line ValueError naming the file, or a right table)."""

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from inkopt.model import InkTable
from inkopt.model.inks import INK_FILE_FORMAT, INK_LIBRARY, read_ink_file, write_ink_file
from inkopt.model.spectral import (
    LIBRARY_SPECTRA,
    WAVELENGTHS_10NM,
    WAVELENGTHS_20NM,
    SpectralInkTable,
    band_edges,
    load_ink_table,
    rgb_basis,
    write_spectral_ink_file,
)

VERO = InkTable.parse("vero-cmykw")


def test_default_grids():
    assert len(WAVELENGTHS_20NM) == 16 and WAVELENGTHS_20NM[0] == 400 and WAVELENGTHS_20NM[-1] == 700
    assert len(WAVELENGTHS_10NM) == 31
    lo, hi = band_edges(WAVELENGTHS_20NM)
    assert lo[0] == 390 and hi[-1] == 710 and np.all(hi - lo == 20)


def test_basis_is_a_partition_of_unity_and_non_negative():
    for grid in (WAVELENGTHS_20NM, WAVELENGTHS_10NM, [550.0]):
        b = rgb_basis(grid)
        assert b.shape == (3, len(grid)) and b.min() > 0
        np.testing.assert_allclose(b.sum(0), 1.0, atol=1e-4)
    # each primary dominates its own part of the spectrum (red 600-640 nm, green 520-560, blue 440-460); towards
    # 400 and 700 nm, where the observer sees little, the basis tends back to 1/3 each
    b = rgb_basis(WAVELENGTHS_20NM)
    assert b[0, 10:13].min() > 0.85 and b[1, 6:9].min() > 0.9 and b[2, 2:4].min() > 0.9


def test_from_rgb_keeps_flat_inks_flat_and_rgb_order():
    flat = InkTable(("grey",), [[2.0, 2.0, 2.0]], [[0.5, 0.5, 0.5]])
    t = SpectralInkTable.from_rgb(flat)
    np.testing.assert_allclose(t.sigma_s, 2.0, rtol=1e-4)
    np.testing.assert_allclose(t.sigma_a, 0.5, rtol=1e-4)
    spec = SpectralInkTable.from_rgb(VERO)
    cyan, yellow = spec.index("cyan"), spec.index("yellow")
    # cyan absorbs red (600-640 nm) far more than green (520-560), yellow blue (440-460) far more than green
    assert spec.sigma_a[cyan, 10:13].mean() > 4 * spec.sigma_a[cyan, 6:9].mean()
    assert spec.sigma_a[yellow, 2:4].mean() > 10 * spec.sigma_a[yellow, 6:9].mean()
    assert spec.names == VERO.names and spec.g == VERO.g


def test_presets_and_spectral_suffixes(tmp_path):
    assert isinstance(load_ink_table("vero-cmykw"), InkTable)
    t = load_ink_table("vero-cmykw@spectral")
    assert isinstance(t, SpectralInkTable) and t.bands == 16 and t.names == VERO.names and t.g == VERO.g
    np.testing.assert_array_equal(t.wavelengths_nm, WAVELENGTHS_20NM)
    ten = load_ink_table("cyan,white@spectral10")
    assert ten.bands == 31 and ten.names == ("cyan", "white")
    # the rows are the stored library's, whatever the set
    np.testing.assert_array_equal(load_ink_table("white,cyan@spectral").sigma_a[1], t.sigma_a[t.index("cyan")])
    for band_nm, path in LIBRARY_SPECTRA.items():
        assert set(load_ink_table(str(path)).names) == set(INK_LIBRARY), band_nm
    with pytest.raises(ValueError, match="unknown ink"):
        load_ink_table("vero-cmykw@spectra")
    mine = tmp_path / "mine.json"
    write_ink_file(mine, InkTable(VERO.names, VERO.sigma_s * 1.1, VERO.sigma_a, VERO.g))
    with pytest.raises(ValueError, match="ink 'cyan' is not the ink library's 'cyan'.*spectral_form"):
        load_ink_table(f"{mine}@spectral")


def test_spectral_file_round_trip_and_rgb_refusal(tmp_path):
    t = load_ink_table("vero-cmykw@spectral")
    path = write_spectral_ink_file(tmp_path / "s.json", t, {"made_by": "test"})
    data = read_ink_file(path)
    assert data["format_version"] == INK_FILE_FORMAT == 2 and data["provenance"] == {"made_by": "test"}
    back = load_ink_table(str(path))
    assert isinstance(back, SpectralInkTable) and back.names == t.names and back.g == t.g
    np.testing.assert_array_equal(back.sigma_s, t.sigma_s)
    np.testing.assert_array_equal(back.sigma_a, t.sigma_a)
    np.testing.assert_array_equal(back.wavelengths_nm, t.wavelengths_nm)
    with pytest.raises(ValueError, match=r"s.json holds a spectral ink table .*load_ink_table") as exc:
        InkTable.parse(str(path))
    assert "\n" not in str(exc.value)


def test_rgb_files_of_every_version_load(tmp_path):
    inks = [{"name": "cyan", "mu_t": [9, 4.5, 7.5], "albedo": [0.05, 0.7, 0.98]}]
    for version in (None, 1, 2):
        data = {"g": 0.4, "inks": inks} | ({} if version is None else {"format_version": version})
        (tmp_path / f"v{version}.json").write_text(json.dumps(data))
        t = load_ink_table(str(tmp_path / f"v{version}.json"))
        assert isinstance(t, InkTable) and t.names == ("cyan",)
        np.testing.assert_allclose(t.mu_t, [[9, 4.5, 7.5]])
    write_ink_file(tmp_path / "w.json", VERO)
    assert read_ink_file(tmp_path / "w.json")["format_version"] == 2
    np.testing.assert_allclose(InkTable.parse(str(tmp_path / "w.json")).sigma_a, VERO.sigma_a)
    (tmp_path / "v3.json").write_text(json.dumps({"format_version": 3, "inks": inks}))
    with pytest.raises(ValueError, match="format version 3"):
        load_ink_table(str(tmp_path / "v3.json"))


def test_toml_spectral_file(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(
        "format_version = 2\ng = 0.3\nwavelengths_nm = [450, 550, 650]\n"
        '[[inks]]\nname = "Cyan"\nsigma_s = [1, 2, 3]\nsigma_a = [0.1, 0.2, 5]\n'
    )
    t = load_ink_table(str(path))
    assert t.names == ("cyan",) and t.g == 0.3 and t.bands == 3
    np.testing.assert_array_equal(t.sigma_a, [[0.1, 0.2, 5]])


@pytest.mark.parametrize(
    ("change", "needle"),
    [
        ({"wavelengths_nm": [500, 400, 600]}, "strictly increasing"),
        ({"wavelengths_nm": "400"}, "'wavelengths_nm' must be a list of numbers"),
        ({"inks": [{"name": "cyan", "sigma_s": [1, 2], "sigma_a": [1, 2, 3]}]}, "must hold 3 numbers"),
        ({"inks": [{"name": "cyan", "sigma_s": [1, -2, 3], "sigma_a": [1, 2, 3]}]}, "non-negative"),
        ({"inks": [{"name": "cyan", "sigma_s": [1, 2, 3], "sigma_a": [1, True, 3]}]}, "list of numbers"),
        ({"inks": [{"name": "a/b", "sigma_s": [1, 2, 3], "sigma_a": [1, 2, 3]}]}, "holds '/'"),
        ({"inks": [{"name": "cyan", "sigma_s": [1, 2, 3]}]}, "missing field 'sigma_a'"),
        ({"g": 1.5}, "g must lie"),
    ],
)
def test_bad_spectral_files_are_one_line(tmp_path, change, needle):
    base = {"format_version": 2, "g": 0.4, "wavelengths_nm": [450, 550, 650]}
    base["inks"] = [{"name": "cyan", "sigma_s": [1, 2, 3], "sigma_a": [1, 2, 3]}]
    (tmp_path / "bad.json").write_text(json.dumps(base | change))
    with pytest.raises(ValueError, match=needle) as exc:
        load_ink_table(str(tmp_path / "bad.json"))
    assert "\n" not in str(exc.value) and "bad.json" in str(exc.value)


# ------------------------------------------------------------------------------------------- fuzzing
VALID = {
    "format_version": 2,
    "g": 0.4,
    "wavelengths_nm": [450.0, 550.0, 650.0],
    "inks": [
        {"name": "cyan", "sigma_s": [1.0, 2.0, 3.0], "sigma_a": [5.0, 0.5, 0.1]},
        {"name": "white", "sigma_s": [9.0, 9.0, 9.0], "sigma_a": [0.01, 0.01, 0.01]},
    ],
    "provenance": {"made_by": "test"},
}
JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=True) | st.text(max_size=5),
    lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=5), kids, max_size=4),
    max_leaves=8,
)


@st.composite
def mutated(draw):
    """VALID with 1-3 entries, reached by a random walk from the top, replaced by random JSON or dropped."""
    value = json.loads(json.dumps(VALID))
    for _ in range(draw(st.integers(1, 3))):
        node, parent, key = value, None, None
        while isinstance(node, (dict, list)) and node and draw(st.integers(0, 4)) < 4:
            key = draw(st.sampled_from(sorted(node) if isinstance(node, dict) else range(len(node))))
            parent, node = node, node[key]
        if parent is None:
            value = draw(JSON)
        elif draw(st.booleans()):
            del parent[key]
        else:
            parent[key] = draw(JSON)
    return value


@settings(max_examples=300, deadline=None, derandomize=True, database=None, suppress_health_check=list(HealthCheck))
@given(value=mutated(), cut=st.none() | st.integers(0, 400))
def test_fuzzed_spectral_files(tmp_path_factory, value, cut):
    """Mutated or truncated spectral files: a right table (the file's numbers, checked) or one clean ValueError
    naming the file."""
    path = tmp_path_factory.mktemp("fuzz") / "inks.json"
    text = json.dumps(value)
    path.write_text(text if cut is None else text[:cut])
    try:
        t = load_ink_table(str(path))
    except ValueError as exc:
        msg = str(exc)
        assert msg and "\n" not in msg and "inks.json" in msg, msg
        return
    assert isinstance(value, dict) and cut is None or cut >= len(text)
    if isinstance(t, SpectralInkTable):
        np.testing.assert_array_equal(t.wavelengths_nm, value["wavelengths_nm"])
        np.testing.assert_array_equal(t.sigma_s, [i["sigma_s"] for i in value["inks"]])
        np.testing.assert_array_equal(t.sigma_a, [i["sigma_a"] for i in value["inks"]])
        assert np.all(np.diff(t.wavelengths_nm) > 0) and np.all(t.sigma_s >= 0) and -1 < t.g < 1
    else:
        assert "wavelengths_nm" not in value
