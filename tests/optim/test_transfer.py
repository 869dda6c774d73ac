"""Coarse to fine (optim.transfer): a coarse result moved onto a finer scene's free voxels, written as the fine run's
start, with the fine scene's fixed shares kept; and a start from a volume file maps its whole mixture to the free
part, so a run's own result restarts it where it ended."""

import zipfile

import numpy as np
import pytest
from helpers import SPOT, with_fixed_shares

from inkopt.model import FixedShares, InkTable, Volume
from inkopt.optim import Optimization, OptimizeConfig, Parameterization
from inkopt.optim.transfer import transferred_free_mixture, write_transferred_volume
from inkopt.scenes.slab import build_slab

INKS = InkTable.from_names(["cyan", "magenta", "white"])
VOX = 25.4 / 300


def slab(dpi: float, size=(16, 12, 6)):
    """A slab of ``size`` 300-DPI voxels (x, y, z) at ``dpi``, a flat cyan target on top."""
    img = np.full((12, 16, 3), 0.4, np.float32)
    return build_slab(img, None, tuple(n * VOX for n in size), INKS, dpi)


def constrained(shape) -> FixedShares:
    """White bottom layer (no variables there) and 80 % cyan fixed in one corner column (a translucency-style
    share with 20 % left free)."""
    fixed = np.zeros(shape + (3,), np.float32)
    fixed[0, ..., 2] = 1.0
    fixed[1:, :3, :3, 0] = 0.8
    return FixedShares.from_dense(fixed)


def start_of(scene, fixed, path) -> np.ndarray:
    run = Optimization(
        with_fixed_shares(scene, fixed), OptimizeConfig(init=str(path), iterations=1).for_scene(scene.kind)
    )
    return run.initial_volume().mixture


def test_a_run_restarts_from_its_own_result_with_fixed_shares(tmp_path):
    """The saved whole mixture (fixed + free share x p) is mapped back to p, not taken as p."""
    scene = slab(300)
    fixed = constrained(scene.volume.shape)
    param = Parameterization("softmax", fixed)
    x = np.random.default_rng(0).normal(size=(param.n_free, 3)).astype(np.float32)
    saved = param.mixture(x)
    scene.volume.with_mixture(saved).save(tmp_path / "volume.npz")
    np.testing.assert_allclose(start_of(scene, fixed, tmp_path / "volume.npz"), saved, atol=2e-6)


def test_a_coarse_slab_result_starts_the_fine_run(tmp_path):
    coarse, fine = slab(150), slab(300)
    assert coarse.volume.shape == (3, 6, 8) and fine.volume.shape == (6, 12, 16)
    rng = np.random.default_rng(1)
    src = coarse.volume.with_mixture(rng.dirichlet(np.ones(3), size=coarse.volume.shape).astype(np.float32))
    fixed = constrained(fine.volume.shape)
    path = write_transferred_volume(src, fine.volume, fixed, tmp_path / "start.npz", chunk=7, slab_voxels=200)
    got = Volume.load(path)
    assert got.shape == fine.volume.shape and got.mixture.dtype == np.float32
    # the same file without chunking, and stored without compression (a coarse-to-fine job's own start)
    write_transferred_volume(src, fine.volume, fixed, tmp_path / "whole.npz")
    np.testing.assert_array_equal(got.mixture, Volume.load(tmp_path / "whole.npz").mixture)
    stored = write_transferred_volume(src, fine.volume, fixed, tmp_path / "stored.npz", compressed=False)
    np.testing.assert_array_equal(Volume.load(stored).mixture, got.mixture)
    with zipfile.ZipFile(stored) as zf:
        assert zf.getinfo("mixture.npy").compress_type == zipfile.ZIP_STORED
    with zipfile.ZipFile(path) as zf:
        assert zf.getinfo("mixture.npy").compress_type == zipfile.ZIP_DEFLATED
    m = got.mixture
    np.testing.assert_allclose(m.sum(-1), 1.0, atol=1e-6)
    np.testing.assert_array_equal(m[0, ..., 2], 1.0)  # the fixed white layer
    assert np.all(m[1:, :3, :3, 0] >= 0.8 - 1e-6)  # the fixed cyan share, the rest from the source
    param = Parameterization("softmax", fixed)
    p = transferred_free_mixture(src, fine.volume, fixed, chunk=5)
    assert p.shape == (param.n_free, 3) and p.dtype == np.float32
    whole = param.fixed_f + param.share_f[:, None] * p
    np.testing.assert_allclose(m.reshape(-1, 3)[param.free_index], whole, atol=1e-6)
    # an unconstrained fine voxel in the coarse grid's interior is the trilinear mean of its 8 coarse neighbours:
    # fine voxel (2, 5, 7) has its centre at coarse index (0.75, 2.25, 3.25)
    wz, wyx = {0: 0.25, 1: 0.75}, {0: 0.75, 1: 0.25}
    near = sum(
        wz[dz] * wyx[dy] * wyx[dx] * src.mixture[0 + dz, 2 + dy, 3 + dx]
        for dz in (0, 1)
        for dy in (0, 1)
        for dx in (0, 1)
    )
    np.testing.assert_allclose(m[2, 5, 7], near, atol=1e-6)
    # the fine run starts from it
    np.testing.assert_allclose(start_of(fine, fixed, path), m, atol=2e-6)


def test_a_coarse_mesh_result_covers_every_fine_free_voxel(tmp_path):
    """Spot at 150 and 300 DPI (different origins and shells): a constant coarse mixture reaches every free voxel
    of the fine grid, including the surface voxels the coarse grid does not hold."""
    from inkopt.scenes.mesh import build_mesh_scene
    from inkopt.scenes.spec import MeshSpec

    if not SPOT.is_file():
        pytest.skip(f"{SPOT} is not there")
    inks = InkTable.parse("vero-cmykw")
    coarse = build_mesh_scene(MeshSpec(SPOT, height_mm=3.0, dpi=150), inks)
    fine = build_mesh_scene(MeshSpec(SPOT, height_mm=3.0, dpi=300), inks)
    row = np.array([0.1, 0.2, 0.3, 0.05, 0.35], np.float32)
    src = Volume.from_mixture(
        coarse.volume.voxel_mm,
        np.broadcast_to(row, coarse.volume.shape + (5,)).copy(),
        inks,
        inside=coarse.volume.inside,
        origin_mm=coarse.volume.origin_mm,
    )
    path = write_transferred_volume(src, fine.volume, fine.fixed_share, tmp_path / "start.npz", slab_voxels=5000)
    m = Volume.load(path).mixture
    np.testing.assert_allclose(m[fine.free], np.broadcast_to(row, (int(fine.free.sum()), 5)), atol=1e-6)
    np.testing.assert_array_equal(m[~fine.free], np.broadcast_to(np.eye(5)[4], (int((~fine.free).sum()), 5)))


def test_inks_must_match(tmp_path):
    coarse, fine = slab(150), slab(300)
    other = InkTable.from_names(["yellow", "magenta", "white"])
    src = Volume.from_mixture(coarse.volume.voxel_mm, coarse.volume.mixture, other)
    with pytest.raises(ValueError, match="inks"):
        write_transferred_volume(src, fine.volume, None, tmp_path / "start.npz")
    assert not (tmp_path / "start.npz").exists()


def test_coarse_start_runs_the_coarse_scene_and_writes_the_fine_start(tmp_path):
    from inkopt.optim.transfer import CoarseStart, coarse_start

    coarse, fine = slab(150), slab(300)
    cfg = OptimizeConfig(iterations=2)
    info = coarse_start(coarse, fine, cfg, tmp_path / "start.npz", threads=1, coarse_path=tmp_path / "coarse.npz")
    assert info.iterations == 2 and len(info.delta_e76) == 2 and info.seconds > 0
    assert CoarseStart.from_json(info.to_json()) == info
    start = Volume.load(info.path)
    assert start.shape == fine.volume.shape
    white = start.mixture[..., 2].mean(axis=(1, 2))
    assert white[-1] < 0.97 - 0.02 and white[-1] < white[0]  # the grey target: darker inks in the top layers
    np.testing.assert_allclose(start_of(fine, None, info.path), start.mixture, atol=2e-6)
    again = write_transferred_volume(tmp_path / "coarse.npz", fine.volume, None, tmp_path / "again.npz")
    np.testing.assert_array_equal(Volume.load(again).mixture, start.mixture)  # the saved coarse result


# ------------------------------------------------------------------------------------- the correction transfer
def centres(shape, step: float) -> np.ndarray:
    """(z, y, x, 3) voxel centres (x, y, z) in units of 300-DPI voxels of a grid whose voxels are ``step`` of
    them (the slabs here share their origin)."""
    zyx = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), -1)
    return (zyx[..., ::-1] + 0.5) * step


def linear(pos: np.ndarray, slope) -> np.ndarray:
    """A mixture field linear in space whose rows sum to 0: ``slope`` (3, 3) ink x axis, in shares per voxel."""
    s = np.asarray(slope, np.float64)
    return pos @ (s - s.mean(0, keepdims=True)).T


def test_the_correction_transfer_keeps_the_coarse_change_and_the_baselines_detail(tmp_path):
    """B_f = a smooth baseline L plus detail H finer than the coarse grid (+-0.04 in alternate fine voxels: the fine
    grid's Nyquist frequency), B_c = L on the coarse grid, C = B_c + a linear change D. Where the fine voxel's 8
    coarse neighbours are inside, trilinear interpolation reproduces linear fields exactly, so the fine start is
    L + H + D: its low-pass part (start - H) is the coarse result moved up, U(C) = L + D, its detail the baseline's."""
    from inkopt.optim.transfer import Baseline

    coarse, fine = slab(150), slab(300)
    row, l_slope = np.array([0.3, 0.3, 0.4]), np.array([[0.01, 0.0, -0.005], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    lc = row + linear(centres(coarse.volume.shape, 2.0), l_slope)
    lf = row + linear(centres(fine.volume.shape, 1.0), l_slope)
    parity = np.indices(fine.volume.shape).sum(0) % 2 * 2 - 1.0  # +1 / -1 in alternate voxels
    h = 0.04 * parity[..., None] * np.array([1.0, -1.0, 0.0])
    d_slope = np.array([[-0.006, 0.004, 0.003], [0.002, -0.003, 0.0], [0.0, 0.0, 0.0]])
    dc, df = linear(centres(coarse.volume.shape, 2.0), d_slope), linear(centres(fine.volume.shape, 1.0), d_slope)
    src = coarse.volume.with_mixture((lc + dc).astype(np.float32))
    base = Baseline(coarse.volume.with_mixture(lc.astype(np.float32)), (lf + h).astype(np.float32))
    got = Volume.load(write_transferred_volume(src, fine.volume, None, tmp_path / "c.npz", baseline=base)).mixture
    assert got.min() > 0.2 and np.allclose(got.sum(-1), 1.0, atol=1e-6)  # nothing clipped here
    inner = (slice(1, -1),) * 3  # fine voxels 1 .. 2n - 2: their 8 coarse neighbours are on the grid
    np.testing.assert_allclose(got[inner], (lf + h + df)[inner], atol=2e-6)
    plain = Volume.load(write_transferred_volume(src, fine.volume, None, tmp_path / "p.npz")).mixture
    np.testing.assert_allclose((got - h)[inner], plain[inner], atol=2e-6)  # low-pass: the coarse result's
    np.testing.assert_allclose((got - plain)[inner], h[inner], atol=2e-6)  # detail: the baseline's
    p = transferred_free_mixture(src, fine.volume, None, chunk=37, baseline=base)  # chunked, layers cut anywhere
    np.testing.assert_allclose(p.reshape(got.shape), got, atol=1e-6)


def test_the_correction_transfer_from_a_uniform_start_is_the_plain_one_and_keeps_fixed_shares(tmp_path):
    """From white (B the same row on both grids) the change C - B_c moved up plus B_f is U(C) (to float32 rounding:
    U(C) and U(B_c) are taken in one pass and each half renormalised; runs from white pass no baseline); the fine
    scene's fixed shares are kept as by the plain transfer, and a change that takes an ink below 0 is clipped."""
    from inkopt.optim.transfer import Baseline

    coarse, fine = slab(150), slab(300)
    white = np.array([0.015, 0.015, 0.97], np.float32)
    src = coarse.volume.with_mixture(
        np.random.default_rng(2).dirichlet(np.ones(3), size=coarse.volume.shape).astype(np.float32)
    )
    fixed = constrained(fine.volume.shape)
    uniform = Baseline(
        coarse.volume.with_mixture(np.broadcast_to(white, coarse.volume.shape + (3,)).copy()),
        np.broadcast_to(white, fine.volume.shape + (3,)),
    )
    plain = write_transferred_volume(src, fine.volume, fixed, tmp_path / "plain.npz")
    got = write_transferred_volume(src, fine.volume, fixed, tmp_path / "c.npz", chunk=11, baseline=uniform)
    np.testing.assert_allclose(Volume.load(got).mixture, Volume.load(plain).mixture, rtol=0, atol=3e-7)
    # a baseline richer in cyan on the coarse grid than on the fine one: the change takes cyan below 0 somewhere
    cyan = np.array([0.9, 0.05, 0.05], np.float32)
    poor = Baseline(
        coarse.volume.with_mixture(np.broadcast_to(cyan, coarse.volume.shape + (3,)).copy()),
        np.broadcast_to(white, fine.volume.shape + (3,)),
    )
    m = Volume.load(write_transferred_volume(src, fine.volume, fixed, tmp_path / "m.npz", baseline=poor)).mixture
    assert m.min() >= 0 and np.allclose(m.sum(-1), 1.0, atol=1e-6)
    np.testing.assert_array_equal(m[0, ..., 2], 1.0)  # the fixed white layer
    assert np.all(m[1:, :3, :3, 0] >= 0.8 - 1e-6)  # the fixed cyan share
    free = np.ones(fine.volume.shape, bool)
    free[0] = False
    free[1:, :3, :3] = False
    assert np.mean(m[free][:, 0] == 0) > 0.1  # clipped where the coarse cyan fell below the fine baseline's


def test_the_correction_transfer_needs_the_coarse_results_grid(tmp_path):
    from inkopt.optim.transfer import Baseline

    coarse, fine = slab(150), slab(300)
    src = coarse.volume.with_mixture(np.full(coarse.volume.shape + (3,), 1 / 3, np.float32))
    other = slab(100).volume.with_mixture(np.full(slab(100).volume.shape + (3,), 1 / 3, np.float32))
    with pytest.raises(ValueError, match="coarse baseline"):
        write_transferred_volume(src, fine.volume, None, tmp_path / "s.npz", baseline=Baseline(other, fine.volume))
    with pytest.raises(ValueError, match="fine baseline"):
        transferred_free_mixture(src, fine.volume, None, baseline=Baseline(src, np.zeros((2, 2, 2, 3), np.float32)))


def test_the_correction_transfer_holds_no_copy_of_both_coarse_grids():
    """U(C) and U(B_c) are resampled apart: beside its output and index the transfer holds less than one more source
    grid's mixture (side by side, C and B_c were copied into one (z, y, x, 2N) array: two grids' worth). The source
    grid is the finer one here, so that its mixture outweighs the destination's temporaries."""
    import tracemalloc

    from inkopt.optim.transfer import Baseline

    source, dest = slab(300, (48, 36, 24)), slab(100, (48, 36, 24))
    rng = np.random.default_rng(0)
    mix_c, mix_b = (rng.dirichlet(np.ones(3), source.volume.shape).astype(np.float32) for _ in range(2))
    src, bc = source.volume.with_mixture(mix_c), source.volume.with_mixture(mix_b)
    dest_b = rng.dirichlet(np.ones(3), dest.volume.shape).astype(np.float32)
    tracemalloc.start()
    try:
        p = transferred_free_mixture(src, dest.volume, None, chunk=256, baseline=Baseline(bc, dest_b))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    held = p.nbytes + 8 * len(p)  # the output and the free voxels' index
    assert peak < held + mix_c.nbytes, (peak, held, mix_c.nbytes)
