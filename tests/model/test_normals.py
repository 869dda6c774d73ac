"""SurfaceNormals (model/normals.py): the sparse form of a volume's shading normals, its file keys, and the old
dense files."""

import numpy as np
import pytest

from inkopt.io import FormatError, save_npz
from inkopt.model import InkTable, SurfaceNormals, Texels, Volume, VolumeError
from inkopt.render import Renderer


def _field(shape=(4, 5, 6), seed=0):
    rng = np.random.default_rng(seed)
    dense = np.zeros(shape + (3,), np.float32)
    some = rng.random(shape) < 0.3
    v = rng.normal(size=(some.sum(), 3)).astype(np.float32)
    dense[some] = v / np.linalg.norm(v, axis=1, keepdims=True)
    return dense


def test_forms_agree():
    dense = _field()
    sn = SurfaceNormals.from_dense(dense)
    np.testing.assert_array_equal(sn.dense(), dense)
    vox = np.argwhere(np.any(dense != 0, -1))
    perm = np.random.default_rng(1).permutation(len(vox))
    again = SurfaceNormals.from_voxels(dense.shape[:3], vox[perm], dense[tuple(vox[perm].T)])
    np.testing.assert_array_equal(again.index, sn.index)
    np.testing.assert_array_equal(again.vectors, sn.vectors)
    every = np.argwhere(np.ones(dense.shape[:3], bool))
    np.testing.assert_array_equal(sn.at(every), dense.reshape(-1, 3))
    for z in range(dense.shape[0]):
        np.testing.assert_array_equal(sn.layer(z), dense[z])
    assert sn.nbytes == 20 * len(sn.index)
    with pytest.raises(ValueError, match="increase"):
        SurfaceNormals((2, 2, 2), [3, 3], np.zeros((2, 3)))
    with pytest.raises(ValueError, match="lie in the grid"):
        SurfaceNormals((2, 2, 2), [8], np.zeros((1, 3)))
    with pytest.raises(ValueError, match="vectors"):
        SurfaceNormals((2, 2, 2), [1], np.zeros((2, 3)))


def test_volume_files_and_renders(tmp_path):
    """A volume keeps its normals sparse, saves them as normal_index/normal_vectors, loads them back, and refuses
    a pre-release file with a dense 'normals' array in one line; renders are bit-identical with either form given to the
    core, and texels come out the same."""
    dense = _field((6, 6, 6))
    inside = np.ones((6, 6, 6), bool)
    inks = InkTable.parse("vero-cmykw")
    mix = np.full((6, 6, 6, len(inks)), 1 / len(inks), np.float32)
    vol = Volume.from_mixture(voxel_mm=[0.1] * 3, mixture=mix, inks=inks, inside=inside, normals=dense)
    assert isinstance(vol.normals, SurfaceNormals)
    vol.save(tmp_path / "v.npz")
    with np.load(tmp_path / "v.npz") as z:
        assert "normals" not in z and "normal_index" in z and "normal_vectors" in z
    back = Volume.load(tmp_path / "v.npz")
    np.testing.assert_array_equal(back.normals.dense(), dense)
    old = vol.to_arrays()
    del old["normal_index"], old["normal_vectors"], old["format_version"]
    old["normals"] = dense
    save_npz(tmp_path / "old.npz", old)
    with pytest.raises(FormatError, match="dense shading normals, a pre-release layout; write it again"):
        Volume.load(tmp_path / "old.npz")
    tex = Texels.for_volume(vol)
    assert tex.centred and len(tex) == len(Texels.from_normals(inside, dense))
    a = Renderer(back).render(tex, 8, 3).rgb
    from inkopt import _core

    s, sa = vol.coefficients()
    sc = _core.Scene(
        vol.shape, (0.1, 0.1, 0.1), _core.Medium.dense(s, sa), inside=inside.astype(np.uint8), normals=dense
    )
    b = Renderer(back)
    b._scene = sc
    np.testing.assert_array_equal(a, b.render(tex, 8, 3).rgb)
    with pytest.raises(VolumeError, match="grid of shape"):
        Volume.from_mixture([0.1] * 3, mixture=mix, inks=inks, normals=SurfaceNormals((2, 2, 2), [], np.zeros((0, 3))))
