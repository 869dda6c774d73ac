"""A mixture volume file read by its band (``MixtureSource.band_volume``: the voxels whose mixture is not the core's,
a layer at a time) renders as the whole volume does, bit for bit, whether it has a core below a shell or every
voxel differs; its band holds exactly the voxels that differ."""

import numpy as np
import pytest

from inkopt.model import InkTable, Texels, Volume, VolumeError
from inkopt.model.mixturefile import MixtureSource
from inkopt.render import Renderer

INKS = InkTable.parse("vero-cmykw")
VMM = (25.4 / 300,) * 3


def ball(tmp_path, shell: bool | None):
    """A ball of random mixtures, over a white core below 2 voxels (``shell``), everywhere (False) or in one voxel
    (None), saved as a mixture volume file: (its path, the volume held whole, the voxels that are not white)."""
    rng = np.random.default_rng(4)
    shape = (14, 15, 16)
    c = (np.array(shape) - 1) / 2
    d = np.sqrt((((np.stack(np.indices(shape), -1) - c) / (np.array(shape) / 2 - 1)) ** 2).sum(-1))
    inside = d < 1
    mixture = np.zeros(shape + (5,), np.float32)
    mixture[..., 4] = inside
    own = inside & ((1 - d) * 6 < 2 if shell else inside)
    if shell is None:  # a band of one voxel
        own = np.zeros_like(inside)
        own[np.flatnonzero(inside[:, 7, 7]).max(), 7, 7] = True  # under the top face's texels
    mixture[own] = rng.dirichlet(np.ones(5), own.sum()).astype(np.float32)
    vol = Volume.from_mixture(VMM, mixture, INKS, inside=inside)
    vol.save(tmp_path / "volume.npz")
    return tmp_path / "volume.npz", vol, np.flatnonzero(own)


@pytest.mark.parametrize("shell", [True, False, None])
def test_a_volume_read_by_its_band_renders_as_the_whole(tmp_path, shell):
    path, whole, own = ball(tmp_path, shell)
    with MixtureSource(path) as src:
        vol, band_mixture = src.band_volume()
    if shell is not False:  # the core is the white below the shell, and the band exactly the voxels that are not
        assert np.array_equal(vol.band.core, [0, 0, 0, 0, 1]) and np.array_equal(vol.band.index, own)
    assert np.array_equal(band_mixture, whole.mixture.reshape(-1, 5)[vol.band.index])
    tex = Texels.for_volume(whole)
    r = Renderer(vol)
    r.set_mixture(vol.band.index, band_mixture)
    a, b = r.render(tex, spp=8, seed=3), Renderer(whole).render(tex, spp=8, seed=3)
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.var_mean, b.var_mean)


def test_a_volume_without_a_mask_is_not_read_by_a_band(tmp_path):
    # A mask would make the renderer walk it by the masked walk, whose numbers differ from the unmasked one's.
    mixture = np.random.default_rng(0).dirichlet(np.ones(5), (4, 5, 6)).astype(np.float32)
    Volume.from_mixture(VMM, mixture, INKS).save(tmp_path / "slab.npz")
    with MixtureSource(tmp_path / "slab.npz") as src, pytest.raises(VolumeError, match="no inside mask"):
        src.band_volume()
