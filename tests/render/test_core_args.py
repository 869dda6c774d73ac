"""The bindings' argument classes: ``_core.Medium`` (dense, sparse or label form) and ``_core.Texels`` check their
arrays once when they are built, a scene checks only that they fit its grid and object, and ``set_medium``
replaces a medium in place or anew with the same renders as a scene built for it."""

import numpy as np
import pytest

_core = pytest.importorskip("inkopt._core")

SHAPE = (4, 5, 6)
VMM = (0.1, 0.1, 0.1)
INK_S = np.array([[8.6, 3.1, 7.3], [2.4, 0.3, 9.0]], np.float32)
INK_A = np.array([[0.4, 1.4, 0.2], [0.1, 2.7, 1.0]], np.float32)


def coefficients(rng, shape=SHAPE):
    s = rng.uniform(0.5, 12.0, size=shape + (3,)).astype(np.float32)
    return s, rng.uniform(0.0, 2.0, size=shape + (3,)).astype(np.float32)


def top_texels(shape=SHAPE):
    nz, ny, nx = shape
    vox = np.stack(np.meshgrid([nz - 1], np.arange(ny), np.arange(nx), indexing="ij"), -1).reshape(-1, 3)
    n = len(vox)
    return _core.Texels(vox.astype(np.int32), np.full(n, 5, np.uint8), np.tile(np.float32([0, 0, 1]), (n, 1)))


def test_medium_forms_and_their_checks():
    rng = np.random.default_rng(0)
    s, a = coefficients(rng)
    assert _core.Medium.dense(s, a).form == "dense"
    index = np.array([0, 3, 7], np.int64)
    assert _core.Medium.sparse(index, s.reshape(-1, 3)[:3].copy(), a.reshape(-1, 3)[:3].copy()).form == "sparse"
    assert _core.Medium.labels(np.zeros(SHAPE, np.uint8), INK_S, INK_A).form == "labels"
    with pytest.raises(TypeError, match="cannot create"):
        _core.Medium()
    with pytest.raises(ValueError, match=r"sigma_a has shape \[4, 5, 7, 3\], expected \(4, 5, 6, 3\)"):
        _core.Medium.dense(s, np.zeros((4, 5, 7, 3), np.float32))
    with pytest.raises(ValueError, match=r"sigma_s has shape \[4, 5, 6, 2\]"):
        _core.Medium.dense(np.ascontiguousarray(s[..., :2]), a[..., :2])
    with pytest.raises(ValueError, match="sigma_s must be C-contiguous"):
        _core.Medium.dense(np.asfortranarray(s), a)
    with pytest.raises(ValueError, match=r"sigma_s has shape \[2, 3\], expected \(3, 3\)"):
        _core.Medium.sparse(index, np.zeros((2, 3), np.float32), np.zeros((3, 3), np.float32))
    with pytest.raises(ValueError, match=r"ink_sigma_a has shape \[3, 3\], expected \(2, 3\)"):
        _core.Medium.labels(np.zeros(SHAPE, np.uint8), INK_S, np.zeros((3, 3), np.float32))
    with pytest.raises(TypeError):  # dtypes are the extraction's: float64 is not float32
        _core.Medium.dense(s.astype(np.float64), a)


def test_a_scene_checks_the_grid_of_its_medium():
    s, a = coefficients(np.random.default_rng(1), (4, 5, 7))
    with pytest.raises(ValueError, match=r"sigma_s has shape \[4, 5, 7, 3\], expected \[4, 5, 6, 3\]"):
        _core.Scene(SHAPE, VMM, _core.Medium.dense(s, a))
    with pytest.raises(ValueError, match=r"labels has shape \[4, 5, 7\], expected \[4, 5, 6\]"):
        _core.Scene(SHAPE, VMM, _core.Medium.labels(np.zeros((4, 5, 7), np.uint8), INK_S, INK_A))
    with pytest.raises(ValueError, match="outside|grid"):  # a sparse index past the grid
        _core.Scene(SHAPE, VMM, _core.Medium.sparse(np.array([0, 500]), s.reshape(-1, 3)[:2], a.reshape(-1, 3)[:2]))


def test_texels_are_checked_once_and_against_the_object():
    tex = top_texels()
    assert len(tex) == 30
    vox, face, nrm = np.zeros((2, 3), np.int32), np.array([5, 5], np.uint8), np.float32([[0, 0, 1], [0, 0, 1]])
    with pytest.raises(ValueError, match="texel arrays must be voxel"):
        _core.Texels(vox, face[:1], nrm)
    with pytest.raises(ValueError, match="texel 1 has face id 6"):
        _core.Texels(vox, np.array([5, 6], np.uint8), nrm)
    with pytest.raises(ValueError, match="texel 0 normal .* facing out of face 4"):
        _core.Texels(vox, np.array([4, 5], np.uint8), nrm)
    inside = np.ones(SHAPE, np.uint8)
    inside[-1, 0, 1] = 0
    sc = _core.Scene(SHAPE, VMM, _core.Medium.dense(*coefficients(np.random.default_rng(2))), inside=inside)
    with pytest.raises(ValueError, match=r"texel 1 lies on voxel \(z,y,x\)=\[3, 0, 1\], which is not inside"):
        sc.render(tex, spp=1, seed=0)


@pytest.mark.parametrize("start", ["dense", "sparse", "labels"])
def test_set_medium_renders_as_a_new_scene(start):
    """Every form replaced by every form (in place where the form and voxels agree) renders and differentiates
    as a scene built for the new medium, bit for bit."""
    rng = np.random.default_rng(3)
    inside = (rng.random(SHAPE) < 0.8).astype(np.uint8)
    inside[-1] = 1  # the texels' voxels
    index = np.flatnonzero(inside)
    labels = rng.integers(0, 2, size=SHAPE).astype(np.uint8)
    media = {
        "dense": lambda: _core.Medium.dense(*coefficients(rng)),
        "sparse": lambda: _core.Medium.sparse(index, *(x.reshape(-1, 3)[index] for x in coefficients(rng))),
        "labels": lambda: _core.Medium.labels(labels, INK_S, INK_A),
    }
    tex = top_texels()
    adj = rng.normal(size=(len(tex), 3)).astype(np.float32)
    sc = _core.Scene(SHAPE, VMM, media[start](), inside=inside)
    for form, make in media.items():
        medium = make()
        sc.set_medium(medium)
        fresh = _core.Scene(SHAPE, VMM, medium, inside=inside)
        for scene in (sc, fresh):
            scene.zero_grad(float(np.abs(adj).max()), None)
        got, want = (x.backward(tex, adj, spp=3, seed=5) for x in (sc, fresh))
        np.testing.assert_array_equal(got[0], want[0], err_msg=f"{start} -> {form}")
        for g, w in zip(sc.take_grad(), fresh.take_grad()):
            np.testing.assert_array_equal(g, w)
        np.testing.assert_array_equal(sc.render(tex, spp=3, seed=6)[0], fresh.render(tex, spp=3, seed=6)[0])
