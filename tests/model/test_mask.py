"""The packed mask (``model.mask.PackedMask``): its planes, slabs and spans at any voxel against the dense mask, and
a volume holding its inside mask as one."""

import numpy as np
import pytest

from inkopt.model import InkTable, Volume
from inkopt.model.mask import PackedMask


@pytest.mark.parametrize("step", [8, 16, 1 << 24])  # slabs smaller than the mask, and one slab
def test_planes_slabs_and_spans_equal_the_dense_mask(monkeypatch, step):
    monkeypatch.setattr(PackedMask, "STEP", step)
    rng = np.random.default_rng(4)
    mask = rng.random((5, 3, 7)) < 0.5  # planes of 21 voxels: most start inside a byte
    pm = PackedMask(mask)
    flat = mask.reshape(-1)
    for a in range(0, flat.size + 1, 5):
        for b in range(a, flat.size + 3, 7):
            np.testing.assert_array_equal(pm.range(a, b), flat[a:b])
    for z in range(-5, 5):
        np.testing.assert_array_equal(pm[z], mask[z])
    for z0, z1 in ((0, 5), (1, 3), (4, 9), (3, 3), (-2, None)):
        np.testing.assert_array_equal(pm[z0:z1], mask[z0:z1])
    np.testing.assert_array_equal(np.asarray(pm), mask)
    np.testing.assert_array_equal(np.asarray(pm, np.uint8), mask.astype(np.uint8))
    assert pm.any() and pm.nbytes == 14 and not PackedMask(np.zeros((1, 2, 3), bool)).any()
    for bad in (5, -6):
        with pytest.raises(IndexError):
            pm[bad]
    with pytest.raises(IndexError):
        pm[::2]
    with pytest.raises(IndexError):
        pm[0, 1]
    with pytest.raises(ValueError):
        PackedMask(np.ones((2, 3), bool))


def test_a_volume_holds_its_inside_mask_as_bits():
    inks = InkTable.parse("vero-cmykw")
    inside = np.random.default_rng(5).random((4, 6, 9)) < 0.6
    vol = Volume.from_mixture((0.1, 0.1, 0.1), np.ones(inside.shape + (len(inks),), np.float32), inks, inside=inside)
    assert isinstance(vol.inside, PackedMask) and vol.inside.count == int(inside.sum())
    np.testing.assert_array_equal(vol.inside_mask(), inside)
    np.testing.assert_array_equal(vol.to_arrays()["inside"], inside)  # the file keeps the dense mask
    assert vol.with_mixture(vol.mixture).inside is vol.inside  # the same bits, not a copy
