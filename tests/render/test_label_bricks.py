"""A printed (labels) volume as the core stores it, by bricks, and read from a layered label file a layer at a time:
its renders, texels and labels are those of the same labels held whole, bit for bit; the core's label bricks refuse
wrong planes and reuse with one-line errors."""

import numpy as np
import pytest

from inkopt import _core
from inkopt.model import EMPTY, InkTable, Texels, Volume
from inkopt.model.labelfile import LabelLayers, LabelLayersWriter
from inkopt.model.media import NonEmpty
from inkopt.model.normals import SurfaceNormals
from inkopt.render import Renderer

INKS = InkTable.parse("vero-cmykw")
VMM = (0.042, 0.085, 0.027)


def printed_ball(shape=(40, 21, 30), seed=3):
    """A printed ellipsoid: random inks within 3 voxels of its surface, white (4) below, ``EMPTY`` outside, and
    outward normals on its surface voxels."""
    rng = np.random.default_rng(seed)
    c = (np.array(shape) - 1) / 2
    r = np.array(shape) / 2 - 1.5
    p = np.stack(np.indices(shape), -1).astype(float)
    e = np.sqrt((((p - c) / r) ** 2).sum(-1))
    labels = np.where(e < 1, np.uint8(4), np.uint8(EMPTY))
    near = (e < 1) & ((1 - e) * r.min() < 3)
    labels[near] = rng.integers(0, 5, near.sum())
    surface = (e < 1) & ((1 - e) * r.min() < 1.2)
    normals = np.zeros(shape + (3,), np.float32)
    normals[surface] = ((p - c) / r**2)[surface][:, ::-1]  # (x, y, z)
    normals[surface] /= np.linalg.norm(normals[surface], axis=1, keepdims=True)
    return labels, SurfaceNormals.from_dense(normals)


def layered(tmp_path, labels) -> LabelLayers:
    w = LabelLayersWriter(tmp_path / "labels.layers", labels.shape)
    for k, layer in enumerate(labels):
        w[k] = layer
    w.commit()
    return LabelLayers(tmp_path / "labels.layers", labels.shape)


def test_a_layered_label_volume_renders_and_textures_as_the_whole_one(tmp_path):
    labels, normals = printed_ball()
    whole = Volume.from_labels(VMM, labels, INKS, normals=normals)
    by_layers = Volume.from_labels(VMM, layered(tmp_path, labels), INKS, normals=normals)
    assert isinstance(by_layers.inside_planes(), NonEmpty)
    tex, tex_layers = Texels.for_volume(whole), Texels.for_volume(by_layers)
    assert len(tex) > 500
    for name in ("voxel", "face", "normal"):
        np.testing.assert_array_equal(getattr(tex, name), getattr(tex_layers, name))
    assert np.array_equal(Texels.for_volume(whole, ["top"]).voxel, Texels.for_volume(by_layers, ["top"]).voxel)
    a = Renderer(whole, threads=2).render(tex, spp=8, seed=4)
    b = Renderer(by_layers, threads=1).render(tex, spp=8, seed=4)
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.var_mean, b.var_mean)
    index = np.random.default_rng(0).integers(0, labels.size, 999)
    assert np.array_equal(by_layers.medium.labels_at(index), labels.reshape(-1)[index])
    assert np.array_equal(by_layers.inside_mask(), labels != EMPTY)  # the whole-array readers decode it
    assert all(np.array_equal(x, y) for x, y in zip(by_layers.coefficients(), whole.coefficients()))


def test_the_labels_own_mask_renders_as_the_mask_given():
    # The core's mask taken from its label bricks (no mask array) against the same mask given as bits.
    labels, normals = printed_ball(seed=8)
    own = Volume.from_labels(VMM, labels, INKS, normals=normals)
    given = Volume.from_labels(VMM, labels, INKS, normals=normals, inside=labels != EMPTY)
    tex = Texels.for_volume(own)
    a, b = Renderer(own).render(tex, spp=8, seed=2), Renderer(given).render(tex, spp=8, seed=2)
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.var_mean, b.var_mean)
    # the renders see the inks: a label volume of white alone renders differently
    white = Volume.from_labels(VMM, np.where(labels == EMPTY, labels, np.uint8(4)), INKS, normals=normals)
    assert not np.array_equal(Renderer(white).render(tex, spp=8, seed=2).rgb, a.rgb)


def test_label_bricks_refuse_wrong_planes_and_reuse():
    ink = np.ones((2, 3), np.float32)
    b = _core.LabelBricks((3, 4, 5))
    with pytest.raises(ValueError, match="planes of shape"):
        b.push(np.zeros((1, 5, 4), np.uint8))
    with pytest.raises(ValueError, match="exceed the 3 planes left"):
        b.push(np.zeros((4, 4, 5), np.uint8))
    b.push(np.zeros((2, 4, 5), np.uint8))
    assert b.planes_left == 1
    with pytest.raises(ValueError, match="1 of 3 planes"):
        _core.Scene((3, 4, 5), (0.1, 0.1, 0.1), _core.Medium.labels(b, ink, ink))
    b.push(np.full((1, 4, 5), 7, np.uint8))
    with pytest.raises(ValueError, match="label 7 has no ink"):
        _core.Scene((3, 4, 5), (0.1, 0.1, 0.1), _core.Medium.labels(b, ink, ink))
    with pytest.raises(ValueError, match="already taken"):
        _core.Scene((3, 4, 5), (0.1, 0.1, 0.1), _core.Medium.labels(b, ink, ink))
    with pytest.raises(ValueError, match="needs a label medium"):
        _core.Scene(
            (1, 1, 1), (0.1,) * 3, _core.Medium.dense(*[np.ones((1, 1, 1, 3), np.float32)] * 2), inside="labels"
        )
