"""Resampling a mixture between two grids of one object (model.resample): constants stay constant, linear ramps stay
linear, points the source does not hold take the nearest inside voxel, and the chunking changes nothing."""

import numpy as np
import pytest

from inkopt.model import InkTable, Volume, VolumeError
from inkopt.model.resample import MixtureResampler, voxel_centres_mm

INKS = InkTable.from_names(["cyan", "magenta", "white"])


def ball(shape, radius) -> np.ndarray:
    z, y, x = np.indices(shape) + 0.5
    c = np.asarray(shape) / 2
    return (z - c[0]) ** 2 + (y - c[1]) ** 2 + (x - c[2]) ** 2 < radius**2


def coarse_volume(mixture, inside=None, vox=0.2, origin=(0.3, -0.1, 0.05)) -> Volume:
    return Volume.from_mixture(voxel_mm=(vox,) * 3, mixture=mixture, inks=INKS, inside=inside, origin_mm=origin)


def test_a_constant_mixture_maps_to_itself_everywhere():
    """Inside the source, at its boundary, off its grid and far outside it: one row everywhere."""
    shape = (10, 12, 14)
    row = np.array([0.2, 0.3, 0.5], np.float32)
    src = coarse_volume(np.broadcast_to(row, shape + (3,)).copy(), ball(shape, 4.5))
    pts = np.random.default_rng(1).uniform(-1.0, 4.0, (5000, 3))  # the source spans ~0.3..3.1 mm in x
    for method in ("linear", "nearest"):
        got = MixtureResampler(src, method).at(pts)
        assert got.shape == (5000, 3) and got.dtype == np.float32
        np.testing.assert_allclose(got, np.broadcast_to(row, got.shape), atol=1e-6)


def test_a_linear_ramp_in_x_maps_to_the_ramp():
    """Trilinear interpolation reproduces a linear function exactly between the source's voxel centres; beyond the
    outermost centres (half a source voxel) it holds the outermost value, so it is off by at most the ramp's slope
    times that distance."""
    vox, shape = 0.2, (6, 5, 16)
    origin = np.array([0.3, -0.1, 0.05])
    xc = origin[0] + (np.arange(shape[2]) + 0.5) * vox  # source centres in x, mm
    slope = 0.25  # cyan share per mm
    cyan = 0.1 + slope * (xc - xc[0])
    m = np.zeros(shape + (3,), np.float32)
    m[..., 0], m[..., 2] = cyan, 1 - cyan
    src = coarse_volume(m, None, vox, origin)
    # a grid of half the voxel size over the same box (the fine grid of a coarse-to-fine run)
    fine_shape = (12, 10, 32)
    index = np.arange(np.prod(fine_shape))
    got = MixtureResampler(src).on_grid(index, fine_shape, (vox / 2,) * 3, origin)
    px = voxel_centres_mm(index, fine_shape, (vox / 2,) * 3, origin)[:, 0]
    want = 0.1 + slope * (np.clip(px, xc[0], xc[-1]) - xc[0])
    np.testing.assert_allclose(got[:, 0], want, atol=2e-6)  # float32 rounding of the source
    np.testing.assert_allclose(got.sum(1), 1.0, atol=1e-6)
    ramp = 0.1 + slope * (px - xc[0])
    assert np.abs(got[:, 0] - ramp).max() <= slope * vox / 4 + 2e-6  # the outer quarter voxels, held flat
    # the outermost fine centres lie a quarter source voxel beyond the outermost source centres
    assert np.isclose(np.abs(got[:, 0] - ramp).max(), slope * vox / 4, atol=1e-5)


def test_points_outside_the_source_take_the_nearest_inside_voxel():
    """A point none of whose 8 surrounding source centres is inside takes the row of the nearest inside voxel: the
    search among the boundary voxels finds as near a voxel as a search over every inside voxel."""
    rng = np.random.default_rng(3)
    shape = (9, 11, 10)
    inside = ball(shape, 3.8) | (rng.random(shape) < 0.03)  # a ball plus scattered single voxels (thin features)
    m = rng.dirichlet(np.ones(3), size=shape).astype(np.float32)
    src = coarse_volume(m, inside)
    pts = rng.uniform(-0.5, 2.8, (20000, 3))
    u = ((pts - src.origin_mm) / src.voxel_mm - 0.5)[:, ::-1]
    i0 = np.floor(u).astype(int)
    padded = np.pad(inside, 1)  # off-grid corners are not inside
    held = np.zeros(len(pts), bool)
    for off in np.ndindex(2, 2, 2):
        c = np.clip(i0 + np.asarray(off) + 1, 0, np.asarray(padded.shape) - 1)
        held |= padded[tuple(c.T)]
    lost = pts[~held]
    assert len(lost) > 500
    allc = voxel_centres_mm(np.flatnonzero(inside), shape, src.voxel_mm, src.origin_mm)
    dist = np.sqrt(((lost[:, None, :] - allc[None]) ** 2).sum(-1))
    best = dist.min(1)
    for method in ("linear", "nearest"):
        res = MixtureResampler(src, method)
        got = res._nearest_inside(lost)
        assert inside.reshape(-1)[got].all()
        mine = np.linalg.norm(lost - voxel_centres_mm(got, shape, src.voxel_mm, src.origin_mm), axis=1)
        np.testing.assert_allclose(mine, best, atol=1e-12)
        unique = np.sum(dist <= best[:, None] + 1e-9, axis=1) == 1  # no tie: the row is that voxel's
        rows = m.reshape(-1, 3)[np.flatnonzero(inside)[dist.argmin(1)]]
        np.testing.assert_allclose(res.at(lost)[unique], rows[unique], atol=1e-7)


def test_interpolation_ignores_outside_voxels():
    """A point between an inside voxel and an outside one takes the inside one's mixture: the empty voxels' rows
    (whatever they hold) do not dilute a surface colour."""
    shape = (1, 1, 2)
    m = np.zeros(shape + (3,), np.float32)
    m[0, 0, 0] = [1, 0, 0]
    m[0, 0, 1] = [0, 0, 1]  # outside
    inside = np.array([[[True, False]]])
    src = coarse_volume(m, inside, vox=1.0, origin=(0, 0, 0))
    got = MixtureResampler(src).at(np.array([[1.0, 0.5, 0.5], [1.4, 0.5, 0.5]]))
    np.testing.assert_allclose(got, [[1, 0, 0], [1, 0, 0]], atol=1e-7)
    both = coarse_volume(m, None, vox=1.0, origin=(0, 0, 0))  # the same with both voxels inside
    np.testing.assert_allclose(MixtureResampler(both).at(np.array([[1.0, 0.5, 0.5]])), [[0.5, 0, 0.5]], atol=1e-7)


def test_chunking_does_not_change_the_result():
    rng = np.random.default_rng(5)
    shape = (7, 8, 9)
    src = coarse_volume(rng.dirichlet(np.ones(3), size=shape).astype(np.float32), ball(shape, 3.5))
    fine_shape = (15, 17, 19)
    index = np.sort(rng.choice(np.prod(fine_shape), 2000, replace=False))
    for method in ("linear", "nearest"):
        res = MixtureResampler(src, method)
        whole = res.on_grid(index, fine_shape, (0.1,) * 3, (0.2, -0.2, 0.0))
        parts = res.on_grid(index, fine_shape, (0.1,) * 3, (0.2, -0.2, 0.0), chunk=37)
        np.testing.assert_array_equal(whole, parts)
        np.testing.assert_allclose(whole.sum(1), 1.0, atol=1e-6)


def test_bad_inputs_are_one_line_errors():
    shape = (2, 2, 2)
    src = coarse_volume(np.full(shape + (3,), 1 / 3, np.float32))
    with pytest.raises(ValueError, match="unknown resampling method"):
        MixtureResampler(src, "cubic")
    with pytest.raises(VolumeError, match="needs a mixture volume"):
        MixtureResampler(Volume.from_labels((0.1,) * 3, np.zeros(shape, np.uint8), INKS))
    with pytest.raises(VolumeError, match="no inside voxel"):
        MixtureResampler(coarse_volume(src.mixture, np.zeros(shape, bool)))
