"""A run's start read from a mixture volume file (``--init FILE``) in blocks of grid voxels
(``optim.param.file_free_mixture``, ``model.mixturefile.MixtureSource.blocks``): bit for bit the free part of the
whole file's mixture as ``Volume.load`` reads it, for any block size and any way the file was written, and bad files
refused in one line."""

import io
import zipfile

import numpy as np
import pytest

from inkopt.io import save_npz
from inkopt.model import FixedShares, InkTable, Volume, VolumeError
from inkopt.model.mixturefile import MixtureSource
from inkopt.optim import Parameterization, initial_free_mixture
from inkopt.optim.param import file_free_mixture, free_part

INKS = InkTable.from_names(["cyan", "magenta", "yellow", "white"])
SHAPE = (5, 7, 9)  # (z, y, x): 315 voxels
VOX = (25.4 / 300,) * 3


def problem():
    """An object with an inside mask, a fixed white bottom layer (no variables there) and 80 % cyan fixed in a
    column (20 % free), a random mixture on its inside voxels; its ``Parameterization``."""
    rng = np.random.default_rng(4)
    inside = rng.random(SHAPE) < 0.8
    inside[2, 3, :] = True  # a whole row of free voxels (the block boundaries below fall inside it)
    fixed = np.zeros(SHAPE + (4,), np.float32)
    fixed[0, ..., 3] = 1.0
    fixed[1:, :2, :2, 0] = 0.8
    mix = np.zeros(SHAPE + (4,), np.float32)
    mix[inside] = rng.dirichlet(np.ones(4), size=int(inside.sum())).astype(np.float32)
    vol = Volume.from_mixture(VOX, mix, INKS, inside=inside, origin_mm=(1.0, 2.0, 3.0))
    param = Parameterization("softmax", FixedShares.from_dense(fixed))
    return vol, param


def whole_file_free_part(path, param) -> np.ndarray:
    """The reference: the whole mixture loaded (``Volume.load``), its free voxels' rows mapped by ``free_part``."""
    rows = Volume.load(path).mixture.reshape(-1, len(INKS))[param.free_index]
    return free_part(rows, param.fixed_f, param.share_f).astype(np.float32)


def writers(vol, tmp_path):
    """The same mixture in the files users hold: ``Volume.save`` (compressed), the streamed writer
    (``save_with_mixture``, a slab of layers at a time), numpy's uncompressed ``np.savez`` with the mixture as
    big-endian float64, and in Fortran order (a transposed array)."""
    arrays = vol.to_arrays()
    out = {"save": tmp_path / "save.npz", "slabs": tmp_path / "slabs.npz"}
    vol.save(out["save"])
    vol.save_with_mixture(out["slabs"], (vol.mixture[z : z + 2] for z in range(0, SHAPE[0], 2)), vol.inks)
    out["savez_f8be"] = tmp_path / "f8be.npz"
    np.savez(out["savez_f8be"], **{**arrays, "mixture": vol.mixture.astype(">f8")})
    out["fortran"] = tmp_path / "fortran.npz"
    np.savez_compressed(out["fortran"], **{**arrays, "mixture": np.asfortranarray(vol.mixture)})
    return out


@pytest.mark.parametrize("voxels", [1, 2, 7, 9, 11, 40, 63, 77, 155, 315, 1000])
def test_blocks_give_the_whole_files_free_part_bit_for_bit(tmp_path, voxels):
    vol, param = problem()
    plane, nx = SHAPE[1] * SHAPE[2], SHAPE[2]
    row = 2 * plane + 3 * nx  # flat index of the first voxel of the all-free row (2, 3, :)
    free = np.zeros(np.prod(SHAPE), bool)
    free[param.free_index] = True
    assert free[row : row + nx].all()
    if voxels in (1, 2, 11, 40, 77, 155):  # these block sizes put a boundary strictly inside that row
        assert any(row < b < row + nx for b in range(0, free.size, voxels))
    for name, path in writers(vol, tmp_path).items():
        want = whole_file_free_part(path, param)
        got = file_free_mixture(path, INKS, param, voxels)
        assert got.dtype == np.float32 and got.shape == (param.n_free, len(INKS))
        np.testing.assert_array_equal(got, want, err_msg=name)
    # the run's own entry point reads it the same way (its default block holds the whole small grid)
    path = tmp_path / "save.npz"
    np.testing.assert_array_equal(initial_free_mixture(INKS, param, str(path), 0), whole_file_free_part(path, param))


def test_blocks_are_the_loaded_mixture_and_layers_still_read_after_them(tmp_path):
    vol, _ = problem()
    path = writers(vol, tmp_path)["save"]
    with MixtureSource(path) as src:
        np.testing.assert_array_equal(src[3], vol.mixture[3])
        parts = list(src.blocks(50))
        assert [v0 for v0, _ in parts] == list(range(0, 315, 50)) and len(parts[-1][1]) == 15
        np.testing.assert_array_equal(np.concatenate([r for _, r in parts]), vol.mixture.reshape(-1, 4))
        np.testing.assert_array_equal(src[1], vol.mixture[1])  # the layer reader starts again
        with pytest.raises(ValueError, match="at least one voxel"):
            next(src.blocks(0))


def test_bad_start_files_are_refused_in_one_line(tmp_path):
    vol, param = problem()
    cases = {}
    other = Volume.from_mixture(VOX, np.full((5, 7, 8, 4), 0.25, np.float32), INKS)  # another grid
    other.save(tmp_path / "shape.npz")
    cases["shape.npz"] = r"volume shape \(5, 7, 8\) differs from \(5, 7, 9\)"
    three = InkTable.from_names(["cyan", "magenta", "white"])
    Volume.from_mixture(VOX, np.full(SHAPE + (3,), 1 / 3, np.float32), three).save(tmp_path / "inks.npz")
    cases["inks.npz"] = r"needs a mixture volume with inks \['cyan', 'magenta', 'yellow', 'white'\]"
    Volume.from_labels(VOX, np.zeros(SHAPE, np.uint8), INKS).save(tmp_path / "labels.npz")
    cases["labels.npz"] = "holds a labels volume; init .* needs a mixture volume"
    s, a = vol.coefficients()
    save_npz(tmp_path / "dense.npz", Volume.from_coefficients(VOX, s, a).to_arrays())
    cases["dense.npz"] = "holds a dense volume; init .* needs a mixture volume"
    bad = vol.mixture.copy()
    bad[4, 6, 8, 1] = -0.5  # the last voxel: found in the last block
    np.savez(tmp_path / "negative.npz", **{**vol.to_arrays(), "mixture": bad})
    cases["negative.npz"] = "mixture must be finite and non-negative"
    buf = io.BytesIO()  # a mixture member cut short: its header promises the whole grid
    np.lib.format.write_array(buf, vol.mixture)
    with zipfile.ZipFile(tmp_path / "short.npz", "w") as zf:
        for k, v in vol.to_arrays().items():
            if k != "mixture":
                with zf.open(k + ".npy", "w") as fh:
                    np.lib.format.write_array(fh, np.asanyarray(v))
        zf.writestr("mixture.npy", buf.getvalue()[: -4 * 10])
    cases["short.npz"] = "the mixture ends early"
    (tmp_path / "text.npz").write_text("not a zip")
    cases["text.npz"] = "is not a readable .npz volume file"
    cases["missing.npz"] = "volume file .*missing.npz does not exist"
    for name, match in cases.items():
        with pytest.raises(ValueError, match=match) as e:
            initial_free_mixture(INKS, param, str(tmp_path / name), 0)
        assert "\n" not in str(e.value), name
    with pytest.raises(VolumeError, match="finite and non-negative"):
        file_free_mixture(tmp_path / "negative.npz", INKS, param, 7)


@pytest.mark.parametrize("kind", ["softmax", "sigmoid"])
def test_variables_written_over_their_mixture_are_bit_identical(kind):
    """``variables_for(p, reuse=True)`` writes x over a float32 p of its own (a baseline's start: one (F, N) array,
    not two), bit for bit what a new array gets, over several blocks; other mixtures (float64, a read-only view) are
    left alone."""
    param = Parameterization(kind, FixedShares.none((3, 4, 5), 4))
    rng = np.random.default_rng(1)
    p = rng.dirichlet(np.ones(4), size=(1 << 20) + 77).astype(np.float32)
    want = param.variables_for(p)
    mine = p.copy()
    got = param.variables_for(mine, reuse=True)
    assert got is mine and np.array_equal(got, want)
    p64 = p.astype(np.float64)
    assert param.variables_for(p64, reuse=True) is not p64 and np.array_equal(p64, p.astype(np.float64))
    view = np.broadcast_to(p[0], p.shape)
    assert np.array_equal(param.variables_for(view, reuse=True), param.variables_for(view))
