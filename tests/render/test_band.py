"""The band medium (``Volume.band``: the voxels near the surface stored, one core mixture below) renders and
differentiates bit for bit as the sparse and dense forms holding the same mixtures, for any thread count; its
updates and checks; a mesh scene with a shell optimises with it exactly as without."""

import dataclasses

import numpy as np
import pytest
from helpers import SPOT

from inkopt.model import Band, FixedShares, InkTable, Texels, Volume, VolumeError
from inkopt.render import Renderer

VOX = 25.4 / 300
INKS = InkTable.parse("vero-cmykw")


def banded(seed: int = 5):
    """A (9, 10, 11) object (the box minus a notch) whose voxels within 2 of its faces and two deep ones hold
    random mixtures and the rest one core mixture: (volume with a band, the same mixture without a band)."""
    rng = np.random.default_rng(seed)
    shape = (9, 10, 11)
    inside = np.ones(shape, bool)
    inside[6:, 3:6, :3] = False
    z, y, x = np.indices(shape)
    deep = np.zeros(shape, bool)
    deep[4, 5, 5] = deep[5, 4, 6] = True
    near = (np.minimum.reduce([z, y, x, 8 - z, 9 - y, 10 - x]) < 2) | deep
    band = np.flatnonzero(near & inside)
    core = np.array([0.6, 0.1, 0.0, 0.1, 0.2], np.float32)
    mixture = np.broadcast_to(core, shape + (5,)).copy()
    mixture.reshape(-1, 5)[band] = rng.dirichlet(np.ones(5), size=len(band))
    plain = Volume.from_mixture(voxel_mm=(VOX,) * 3, mixture=mixture, inks=INKS, inside=inside)
    return dataclasses.replace(plain, band=Band(band, core)), plain


def passes_of(r: Renderer, vol: Volume, spp: int = 4):
    """A render's means and variances and the gradient (d/d sigma_s, d/d sigma_a) of a fixed adjoint."""
    tex = Texels.for_volume(vol)
    adj = np.random.default_rng(1).normal(size=(len(tex), 3)).astype(np.float32)
    res = r.render(tex, spp=spp, seed=3)
    return res.rgb, res.var_mean, *r.gradient(tex, adj, spp=spp, seed=4)[:2]


def passes(vol: Volume, threads: int):
    return passes_of(Renderer(vol, threads=threads), vol)


def assert_same(a, b):
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)


def test_band_renders_and_differentiates_as_the_sparse_and_dense_forms():
    vol, plain = banded()
    assert 0 < len(vol.band.index) < vol.inside.count - 100  # a core of its own
    want = passes(plain, 1)
    assert want[0].mean() > 0.05
    for threads in (1, 2, 3):
        assert_same(passes(vol, threads), want)
    dense = Volume.from_coefficients((VOX,) * 3, *plain.coefficients(), inside=plain.inside)
    assert_same(passes(vol, 2), passes(dense, 2))
    assert vol.render_bytes() < plain.render_bytes()


def test_set_mixture_writes_the_band_and_refuses_core_voxels():
    vol, plain = banded()
    rng = np.random.default_rng(2)
    index = np.sort(rng.choice(vol.band.index, 40, replace=False))
    rows = rng.dirichlet(np.ones(5), size=len(index)).astype(np.float32)
    changed = plain.mixture.copy()
    changed.reshape(-1, 5)[index] = rows
    core_voxel = np.setdiff1d(vol.inside.nonzero(), vol.band.index)[:3]
    reused = Renderer(vol)
    # core voxels given the core's mixture are taken as they are (the optimiser's fixed shares pass them)
    both = np.concatenate([index, core_voxel])
    order = np.argsort(both)
    reused.set_mixture(both[order], np.concatenate([rows, np.broadcast_to(vol.band.core, (3, 5))])[order])
    assert_same(passes_of(reused, vol), passes(plain.with_mixture(changed), 1))
    with pytest.raises(ValueError, match=f"voxel {core_voxel[0]} is in the core"):
        reused.set_mixture(core_voxel[:1], rows[:1])
    assert_same(passes_of(reused, vol), passes(plain.with_mixture(changed), 1))  # nothing written


def test_band_of_fixed_shares_and_its_checks():
    inside = np.zeros((4, 5, 6), bool)
    inside[1:3, 1:4, 1:5] = True
    free = np.zeros_like(inside)
    free[1, 1:4, 1:5] = True
    held = np.array([0, 0, 0, 0, 1], np.float32)
    rows_at = np.array([2 * 30 + 2 * 6 + 2, 3 * 30 + 0], np.int64)  # one inside, one outside the object
    fixed = FixedShares(free, held, rows_at, np.full((2, 5), 0.2, np.float32))
    band = Band.of_fixed(inside, fixed)
    np.testing.assert_array_equal(band.index, np.union1d(np.flatnonzero(free & inside), rows_at[:1]))
    np.testing.assert_array_equal(band.core, held)
    labels = np.where(inside, np.uint8(4), np.uint8(255))
    vol = Volume.from_labels((VOX,) * 3, labels, INKS, inside=inside, band=band)
    assert vol.with_mixture(np.zeros(inside.shape + (5,), np.float32)).band is None
    with pytest.raises(VolumeError, match="inside the object"):
        Volume.from_labels((VOX,) * 3, labels, INKS, inside=inside, band=Band(rows_at, held))
    with pytest.raises(VolumeError, match="5 finite non-negative ink shares"):
        Volume.from_labels((VOX,) * 3, labels, INKS, inside=inside, band=Band(band.index, held[:4]))
    with pytest.raises(VolumeError, match="strictly increasing"):
        Band(band.index[::-1], held)
    with pytest.raises(VolumeError, match="needs an inside mask"):
        Volume.from_labels((VOX,) * 3, labels, INKS, band=band)


@pytest.mark.skipif(not SPOT.is_file(), reason="Spot data set not present")
def test_mesh_scene_with_a_shell_optimises_as_without_the_band():
    from inkopt.optim import Optimization, OptimizeConfig
    from inkopt.scenes import build_scene
    from inkopt.scenes.spec import MeshSpec

    scene = build_scene(MeshSpec(str(SPOT), height_mm=4.0, shell_mm=0.3), INKS)
    band = scene.volume.band
    assert band is not None and 0 < len(band.index) < scene.volume.inside.count
    np.testing.assert_array_equal(band.index, np.flatnonzero(scene.free))
    cfg = OptimizeConfig(iterations=1, spp=1).for_scene(scene.kind)
    runs = [
        Optimization(s, cfg, threads=2)
        for s in (scene, dataclasses.replace(scene, volume=dataclasses.replace(scene.volume, band=None)))
    ]
    infos = [r.step() for r in runs]
    assert infos[0]["delta_e76"] == infos[1]["delta_e76"]
    np.testing.assert_array_equal(runs[0].x, runs[1].x)
