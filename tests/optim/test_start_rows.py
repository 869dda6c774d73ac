"""A coarse-to-fine job's start held in proportion to the surface: the coarse result and its baseline held by their
bands (``model.banded.BandMixture``) move onto the fine grid as the dense ones do, bit for bit, and the start is
written as the fine run's free voxels' rows only (``optim.startrows``), which a run reads as it reads the same rows
from a whole-grid volume file; files that do not fit or are malformed are refused in one line."""

import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from inkopt.model import InkTable, Volume, white_fixed_shares
from inkopt.model.banded import band_mixture
from inkopt.optim import initial_free_mixture
from inkopt.optim.param import file_free_mixture
from inkopt.optim.startrows import is_start_rows, save_start_rows
from inkopt.optim.transfer import (
    Baseline,
    coarse_result,
    destination,
    transferred_free_mixture,
    write_start_volume,
    write_transferred_rows,
    write_transferred_volume,
)

INKS = InkTable.from_names(["cyan", "magenta", "white"])
WHITE = np.array([0.0, 0.0, 1.0], np.float32)


def ball(shape, vox, seed: int, shell: float = 2.5):
    """A mixture volume of a ball filling ``shape`` (z, y, x) voxels of ``vox`` mm: random mixtures within
    ``shell`` voxels of its surface, white (its core) below."""
    zyx = np.indices(shape).astype(np.float64) + 0.5
    centre = np.array(shape, np.float64)[:, None, None, None] / 2
    r = np.sqrt(((zyx - centre) ** 2).sum(0))
    radius = min(shape) / 2 - 0.3
    inside = r < radius
    mix = np.zeros((*shape, 3), np.float32)
    mix[inside] = WHITE
    band = inside & (r > radius - shell)
    mix[band] = np.random.default_rng(seed).dirichlet(np.ones(3), int(band.sum())).astype(np.float32)
    return Volume.from_mixture((vox,) * 3, mix, INKS, inside=inside, origin_mm=(0.0, 0.0, 0.0))


def fine_ball():
    """The destination: the same ball on a grid twice as fine, reaching half a coarse voxel further out (fine
    voxels that no coarse inside voxel surrounds: the nearest-voxel fallback), its outer 4 voxels free, every other
    voxel fixed white (a mesh run's band over its core)."""
    vol = ball((24, 22, 20), 0.5, 7)
    zyx = np.indices(vol.shape).astype(np.float64) + 0.5
    r = np.sqrt(((zyx - np.array(vol.shape)[:, None, None, None] / 2) ** 2).sum(0))
    inside = r < min(vol.shape) / 2 + 0.4
    vol = Volume.from_mixture(vol.voxel_mm, np.where(inside[..., None], vol.mixture, 0), INKS, inside=inside)
    return vol, white_fixed_shares(inside & (r >= min(vol.shape) / 2 - 4), INKS)  # white elsewhere, as meshes


def test_mixtures_held_by_their_bands_move_as_the_dense_ones_bit_for_bit(tmp_path):
    coarse_c, coarse_b = ball((12, 11, 10), 1.0, 1), ball((12, 11, 10), 1.0, 2)
    fine, fixed = fine_ball()
    param = destination(fine, fixed)
    layers = np.random.default_rng(3).dirichlet(np.ones(3), (*fine.shape,)).astype(np.float32)
    dense = transferred_free_mixture(coarse_c, fine, fixed, chunk=97, baseline=Baseline(coarse_b, layers))
    band_c = band_mixture(coarse_c, coarse_c.mixture)
    band_b = band_mixture(coarse_b, coarse_b.mixture, WHITE)
    assert 0 < len(band_c.rows) < coarse_c.inside.count  # the core is not held
    got = transferred_free_mixture(band_c, fine, fixed, chunk=97, baseline=Baseline(band_b, layers))
    np.testing.assert_array_equal(got, dense)
    # the coarse result read from its file by its band
    coarse_c.save(tmp_path / "coarse.npz")
    from_file = coarse_result(tmp_path / "coarse.npz")
    assert len(from_file.rows) == len(band_c.rows)
    plain = transferred_free_mixture(coarse_c, fine, fixed, chunk=50)
    np.testing.assert_array_equal(transferred_free_mixture(from_file, fine, fixed, chunk=50), plain)
    assert param.n_free == len(got)


@pytest.mark.parametrize("chunk", [1, 13, 4096])
def test_the_start_rows_are_the_whole_grid_files_rows_and_start_a_run_alike(tmp_path, chunk):
    coarse, (fine, fixed) = ball((12, 11, 10), 1.0, 1), fine_ball()
    param = destination(fine, fixed)
    whole = write_transferred_volume(coarse, fine, fixed, tmp_path / "whole.npz", compressed=False)
    rows = write_transferred_rows(coarse, fine, param, tmp_path / "rows.npz", chunk=chunk)
    assert is_start_rows(rows) and not is_start_rows(whole)
    with np.load(rows) as f:
        np.testing.assert_array_equal(f["free_index"], param.free_index)
        np.testing.assert_array_equal(f["free_rows"], Volume.load(whole).mixture.reshape(-1, 3)[param.free_index])
    with zipfile.ZipFile(rows) as zf:
        assert zf.getinfo("free_rows.npy").compress_type == zipfile.ZIP_STORED
    for voxels in (1, 7, 1 << 20):
        np.testing.assert_array_equal(
            file_free_mixture(rows, INKS, param, voxels), file_free_mixture(whole, INKS, param, voxels)
        )
    np.testing.assert_array_equal(  # the start as a whole grid again, to render or print it
        Volume.load(write_start_volume(rows, fine, fixed, tmp_path / "again.npz", slab_voxels=999)).mixture,
        Volume.load(whole).mixture,
    )
    assert rows.stat().st_size < whole.stat().st_size  # 8 + 4N B per free voxel, not 4N per grid voxel (both stored)


def valid(tmp_path, param, name="start.npz"):
    rows = np.random.default_rng(0).dirichlet(np.ones(3), param.n_free).astype(np.float32)
    blocks = (rows[i : i + 5] for i in range(0, len(rows), 5))
    return save_start_rows(tmp_path / name, param.shape, INKS, param.free_index, blocks)


def test_start_rows_that_do_not_fit_or_are_malformed_are_refused_in_one_line(tmp_path):
    fine, fixed = fine_ball()
    param = destination(fine, fixed)
    good = valid(tmp_path, param)
    with np.load(good) as f:
        arrays = dict(f)
    cases = {}

    def case(name, match, **changes):
        np.savez(tmp_path / name, **{**arrays, **changes})
        cases[name] = match

    case("inks.npz", "needs a start with inks", ink_names=np.array(["yellow", "magenta", "white"]))
    case("grid.npz", "a start for a grid of", grid_shape=np.array([1, 2, 3]))
    case("fewer.npz", "free voxels, this run has", free_index=arrays["free_index"][:-1])
    other = arrays["free_index"].copy()
    other[-1] += 1
    case("other.npz", "other free voxels than this run", free_index=other)
    bad = arrays["free_rows"].copy()
    bad[-1, 0] = np.nan
    case("nan.npz", "finite and non-negative", free_rows=bad)
    case("f8.npz", "holds float64", free_rows=arrays["free_rows"].astype(np.float64))
    case("i4.npz", "free_index is int32", free_index=arrays["free_index"].astype(np.int32))
    case("newer.npz", "format version 2", format_version=np.int64(2))
    case("names.npz", "ink names or grid shape", grid_shape=np.array(["a", "b", "c"]))
    np.savez(tmp_path / "missing.npz", **{k: v for k, v in arrays.items() if k != "grid_shape"})
    cases["missing.npz"] = "a start file without grid_shape"
    with zipfile.ZipFile(tmp_path / "short.npz", "w") as zf:
        with zipfile.ZipFile(good) as src:
            for info in src.infolist():
                body = src.read(info.filename)
                zf.writestr(info.filename, body[:-12] if info.filename == "free_rows.npy" else body)
    cases["short.npz"] = "ends early"
    for name, match in cases.items():
        with pytest.raises(ValueError, match=match) as e:
            initial_free_mixture(INKS, param, str(tmp_path / name), 0)
        assert "\n" not in str(e.value) and name in str(e.value), name


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.integers(0, 10**9), st.integers(0, 255)), min_size=1, max_size=8))
def test_corrupt_start_rows_give_one_line_errors_or_the_right_start(tmp_path, flips):
    fine, fixed = fine_ball()
    param = destination(fine, fixed)
    good = valid(tmp_path, param, "good.npz")
    want = file_free_mixture(good, INKS, param)
    data = bytearray(good.read_bytes())
    for at, value in flips:
        data[at % len(data)] = value
    path = tmp_path / "corrupt.npz"
    path.write_bytes(bytes(data))
    try:
        got = initial_free_mixture(INKS, param, str(path), 0)
    except ValueError as exc:
        assert "\n" not in str(exc)
    else:
        np.testing.assert_array_equal(got, want)


def test_the_coarse_result_and_its_baseline_are_held_by_their_bands(tmp_path):
    """What a coarse-to-fine job holds of the coarse grid: its result read from volume.npz (``coarse_result``) and
    its baseline made a layer at a time (``coarse.baseline_by_band``) each peak below half the whole grid's mixture
    (they hold their band's rows, 8 + 4N B per band voxel, and the mask's bytes; the whole mixture is 4N B per grid
    voxel), and hold the same values."""
    import tracemalloc

    from inkopt.coarse import baseline_by_band

    # its band 6 % of the grid (Spot 100 mm at 150 DPI: 3 %): held, 2 x (8 + 4N) B per band voxel while the band's
    # pieces are joined and the mask's byte per grid voxel, against the whole mixture's 4N B per grid voxel
    vol = ball((48, 48, 48), 0.25, 5, shell=1.0)
    whole = vol.mixture.nbytes
    vol.save(tmp_path / "coarse.npz")
    layers = type("Layers", (), {"shape": vol.mixture.shape, "__getitem__": lambda self, z: vol.mixture[z].copy()})()
    tracemalloc.start()
    try:
        held = coarse_result(tmp_path / "coarse.npz")
        peak_result = tracemalloc.get_traced_memory()[1]
        tracemalloc.reset_peak()
        made = baseline_by_band(vol.with_medium(vol.medium, band=None), layers)
        peak_baseline = tracemalloc.get_traced_memory()[1] - held.rows.nbytes
    finally:
        tracemalloc.stop()
    assert peak_result < whole / 2 and peak_baseline < whole / 2, (peak_result, peak_baseline, whole)
    for got in (held, made):
        np.testing.assert_array_equal(
            got.at(np.arange(vol.inside.size)[vol.inside_mask().ravel()]), vol.mixture[vol.inside_mask()]
        )


def test_start_rows_declaring_huge_or_trailing_members_are_refused_in_one_line(tmp_path):
    """Headers are checked before anything is allocated, and a member with more than it declares is refused."""
    import io

    fine, fixed = fine_ball()
    param = destination(fine, fixed)
    good = valid(tmp_path, param)

    def rewrite(name: str, member: str, body: bytes) -> str:
        with zipfile.ZipFile(good) as src, zipfile.ZipFile(tmp_path / name, "w") as zf:
            for info in src.infolist():
                zf.writestr(info.filename, body if info.filename == member else src.read(info.filename))
        return str(tmp_path / name)

    huge = io.BytesIO()  # a header claiming 10^12 int64 entries, then nothing
    np.lib.format.write_array_header_2_0(huge, {"descr": "<i8", "fortran_order": False, "shape": (10**12,)})
    with zipfile.ZipFile(good) as src:
        rows = src.read("free_rows.npy")
    cases = {
        rewrite("huge.npz", "grid_shape.npy", huge.getvalue()): "declares",
        rewrite("trailing.npz", "free_rows.npy", rows + b"\0" * 8): "more than its header declares",
        rewrite("v9.npz", "grid_shape.npy", b"\x93NUMPY\x09\x00" + huge.getvalue()[8:]): "format version",
    }
    for path, match in cases.items():
        with pytest.raises(ValueError, match=match) as e:
            initial_free_mixture(INKS, param, path, 0)
        assert "\n" not in str(e.value) and path in str(e.value)
