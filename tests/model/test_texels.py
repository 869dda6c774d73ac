"""Texels.exposed_faces, found a few z layers at a time, against the whole-grid definition."""

import numpy as np
import pytest

from inkopt.model import Texels
from inkopt.model import texels as texels_module


def _exposed_whole_grid(inside, fids):
    """The definition: a face whose neighbour (np.roll of the padded mask) is outside or off the grid."""
    pad = np.pad(inside, 1, constant_values=False)
    vox, fid = [], []
    for f in fids:
        axis, step = 2 - f // 2, 1 if f % 2 else -1
        nb = np.roll(pad, -step, axis=axis)[1:-1, 1:-1, 1:-1]
        v = np.argwhere(inside & ~nb)
        vox.append(v)
        fid.append(np.full(len(v), f, np.uint8))
    return np.concatenate(vox), np.concatenate(fid)


@pytest.mark.parametrize("slab", [1, 3, 32])
@pytest.mark.parametrize("faces", [None, ["top"], ["-x", "+y"]])
def test_exposed_faces_in_slabs_equal_the_whole_grid(monkeypatch, slab, faces):
    rng = np.random.default_rng(3)
    inside = rng.random((7, 5, 6)) < 0.6
    inside[0, 0, 0] = inside[-1, -1, -1] = True  # corners: off-grid neighbours
    monkeypatch.setattr(texels_module, "EXPOSED_SLAB", slab)
    tex = Texels.exposed_faces(inside, faces)
    fids = range(6) if faces is None else sorted({texels_module.face_id(f) for f in faces})
    vox, fid = _exposed_whole_grid(inside, fids)
    np.testing.assert_array_equal(tex.voxel, vox)
    np.testing.assert_array_equal(tex.face, fid)
