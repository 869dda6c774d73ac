"""Tests of inkopt.evaluation.colour_table and .baselines: simplex lattice, colour table (accuracy, cache),
surface and extrusion baselines, and the constraints they keep."""

import time
from math import comb

import numpy as np
import pytest

from inkopt.color import delta_e76, linear_to_lab
from inkopt.errors import ParameterError
from inkopt.evaluation.baselines import BaselineLayers, extrusion_baseline, surface_baseline, white_mixture
from inkopt.evaluation.colour_table import (
    ColourTable,
    colour_table,
    default_step,
    render_patches,
    simplex_lattice,
    simplex_least_squares,
    table_key,
    table_mixtures,
)
from inkopt.model import InkTable, Texels, Volume
from inkopt.rundir import SceneRecord

V300 = 25.4 / 300
INKS3 = InkTable.from_names(["cyan", "magenta", "white"])


@pytest.fixture(scope="module")
def cyan_white():
    """A 2-ink table (cyan, white), step 1/8, 1 mm patches: 9 entries."""
    inks = InkTable.from_names(["cyan", "white"])
    return inks, colour_table(inks, patch_mm=1.0, step=8, max_stderr=0.4)


def test_simplex_lattice_counts_and_rows():
    for n, step in [(1, 3), (2, 8), (3, 4), (5, 8)]:
        lat = simplex_lattice(n, step)
        assert lat.shape == (comb(step + n - 1, n - 1), n)
        np.testing.assert_allclose(lat.sum(1), 1.0, atol=1e-6)
        np.testing.assert_allclose(lat * step, np.rint(lat * step), atol=1e-5)  # on the 1/step grid
        assert len(np.unique(lat, axis=0)) == len(lat) and lat.min() >= 0
    assert default_step(5) == 8 and len(simplex_lattice(5, 8)) == 495
    assert default_step(8) <= 4


def test_table_mixtures_add_the_tint_warp():
    mixes = table_mixtures(2, 8)
    k = np.arange(9)
    expect = np.unique(np.concatenate([k / 8, k**2 / (k**2 + (8 - k) ** 2)]))  # 9 + 6 new (k = 0, 4, 8 shared)
    np.testing.assert_allclose(mixes[:, 0], expect, atol=1e-6)
    np.testing.assert_allclose(mixes.sum(1), 1.0, atol=1e-6)
    assert len(table_mixtures(5, 8)) == 970


def test_simplex_least_squares_matches_brute_force():
    rng = np.random.default_rng(0)
    b = rng.normal(size=(50, 4, 3)) * 10
    w = simplex_least_squares(b, 2000)
    assert np.all(w >= -1e-12) and np.allclose(w.sum(1), 1)
    f = np.sum(np.einsum("uk,ukc->uc", w, b) ** 2, 1)
    # brute force over a fine simplex grid (step 1/40): the solver must not be worse (up to the grid resolution)
    grid = simplex_lattice(4, 40).astype(np.float64)
    fb = np.sum(np.einsum("gk,ukc->ugc", grid, b) ** 2, 2).min(1)
    assert np.all(f <= fb + 1e-6 * (1 + fb))


def test_table_maps_rendered_colour_back(cyan_white):
    inks, table = cyan_white
    assert table.lab.shape == (15, 3) and table.stderr.max() < 0.4 * 1.5  # pilot-sized second pass: some slack
    assert np.all(np.diff(table.lab[:, 0]) < 0)  # more cyan -> darker (rows in ascending cyan share)
    # table mixtures rendered with other seeds map back to themselves (neighbours are >> noise apart in Lab)
    mixes = table.mixtures[[1, 4, 7]]  # cyan 0.02, 0.25, 0.5: far from their neighbours in colour
    rgb, se = render_patches(mixes, inks, inks.g, 1.5, patch_mm=1.0, max_stderr=1.0, seed=99)
    np.testing.assert_array_equal(table.lookup(rgb, refine=False), mixes)
    # mixtures between table entries: with the nearest entry, the look-up's rendered colour is no farther from
    # the target than the nearer of the two enclosing entries; the refined blend must come within a third of
    # the Lab gap between them (measured: 0.07-0.17 of it); both plus 4 standard errors of MC noise
    off = np.array([[0.30, 0.70], [0.06, 0.94], [0.8, 0.2]], np.float32)
    rgb_off, se_off = render_patches(off, inks, inks.g, 1.5, patch_mm=1.0, max_stderr=0.4, seed=7)
    lab_off = linear_to_lab(rgb_off)
    hi = np.searchsorted(table.mixtures[:, 0], off[:, 0])
    gap = delta_e76(table.lab[hi - 1], table.lab[hi])
    nearer = np.minimum(delta_e76(lab_off, table.lab[hi - 1]), delta_e76(lab_off, table.lab[hi]))
    for refine, bound in ((False, nearer), (True, gap / 3)):
        got = table.lookup(rgb_off, refine=refine)
        rgb_got, se_got = render_patches(got, inks, inks.g, 1.5, patch_mm=1.0, max_stderr=0.4, seed=8)
        de = delta_e76(lab_off, linear_to_lab(rgb_got))
        assert np.all(de <= bound + 4 * np.hypot(se_off, se_got)), (refine, de, bound)


def test_cache_reused(cyan_white, tmp_path):
    inks, table = cyan_white
    t0 = time.perf_counter()
    again = colour_table(inks, patch_mm=1.0, step=8, max_stderr=0.4)
    assert time.perf_counter() - t0 < 0.5 and again.cached and again.key == table.key
    np.testing.assert_array_equal(again.lab, table.lab)
    np.testing.assert_array_equal(again.mixtures, table.mixtures)
    other = InkTable.from_names(["cyan", "white"], g=0.5)  # another g is another table
    assert table_key(other, other.g, 1.5, 1.0, 8, 0.4) != table.key
    # the ink table of a volume read from disk (float32 coefficients) finds the same table
    Volume.from_mixture([V300] * 3, mixture=np.ones((1, 1, 1, 2), np.float32) / 2, inks=inks).save(tmp_path / "v.npz")
    assert colour_table(Volume.load(tmp_path / "v.npz").inks, patch_mm=1.0, step=8, max_stderr=0.4).cached


# ----------------------------------------------------------------------------------------------- baselines
def patch_scene(shape=(6, 16, 24), faces=("top",)):
    """A slab with a target of 4 colour patches (quadrants) on each textured face."""
    vol = Volume.from_mixture(voxel_mm=[V300] * 3, mixture=np.full(shape + (3,), 1 / 3, np.float32), inks=INKS3)
    tex = Texels.box_faces(shape, faces)
    quad = (tex.voxel[:, 1] >= shape[1] // 2) * 2 + (tex.voxel[:, 2] >= shape[2] // 2)
    colours = np.array([[0.05, 0.3, 0.6], [0.6, 0.1, 0.3], [0.8, 0.8, 0.8], [0.2, 0.5, 0.8]])
    target = colours[quad].astype(np.float32)
    if len(faces) > 1:
        target[tex.face == 4] = colours[::-1][quad[tex.face == 4]]
    return vol, tex, target, np.zeros(shape + (3,), np.float32)


def test_surface_baseline_top_layer_only(table3):
    vol, tex, target, fixed = patch_scene()
    mix = surface_baseline(vol, tex, target, fixed, table3)
    white = white_mixture(INKS3)
    assert mix.shape == vol.shape + (3,) and mix.dtype == np.float32
    np.testing.assert_allclose(mix.sum(-1), 1.0, atol=1e-5)
    np.testing.assert_array_equal(mix[:-1], np.broadcast_to(white, mix[:-1].shape))  # below the top: white
    expect = table3.lookup(target)
    np.testing.assert_allclose(mix[-1].reshape(-1, 3), expect, atol=1e-6)  # texel order = C order of (y, x)
    assert not np.allclose(mix[-1], white)  # the colour is there


def test_extrusion_fills_columns_and_halves(table3):
    vol, tex, target, fixed = patch_scene()
    mix = extrusion_baseline(vol, tex, target, fixed, table3)
    top = table3.lookup(target).reshape(16, 24, 3)
    np.testing.assert_allclose(mix, np.broadcast_to(top, mix.shape), atol=1e-6)  # every layer = its top texel
    vol, tex, target, fixed = patch_scene(faces=("top", "bottom"))
    mix = extrusion_baseline(vol, tex, target, fixed, table3)
    mapped = table3.lookup(target)
    bottom, top = mapped[tex.face == 4].reshape(16, 24, 3), mapped[tex.face == 5].reshape(16, 24, 3)
    np.testing.assert_allclose(mix[3:], np.broadcast_to(top, mix[3:].shape), atol=1e-6)
    np.testing.assert_allclose(mix[:3], np.broadcast_to(bottom, mix[:3].shape), atol=1e-6)


def test_fixed_share_and_inside_kept(table3):
    vol, *_ = patch_scene()
    inside = np.ones(vol.shape, bool)
    inside[:, :, :2] = False
    vol = Volume.from_mixture(voxel_mm=vol.voxel_mm, mixture=vol.mixture, inks=INKS3, inside=inside)
    tex = Texels.exposed_faces(inside, ["top"])
    fixed = np.zeros(vol.shape + (3,), np.float32)
    fixed[:3, ..., 1] = 0.5  # half magenta fixed in the lower half
    target = np.tile([[0.1, 0.4, 0.7]], (len(tex), 1)).astype(np.float32)
    mix = extrusion_baseline(vol, tex, target, fixed, table3)
    assert np.all(mix[~inside] == 0)
    base = table3.lookup(target[:1])[0]
    lower = mix[:3][inside[:3]]
    np.testing.assert_allclose(lower, np.broadcast_to(0.5 * base + [0, 0.5, 0], lower.shape), atol=1e-6)
    np.testing.assert_allclose(mix[3:][inside[3:]], np.broadcast_to(base, (int(inside[3:].sum()), 3)), atol=1e-6)


def test_free_mask_only_scene_keeps_its_white_core(table3):
    """A large shelled mesh stores only free_mask in scene.npz (no dense fixed_share): the baselines built from
    that record must still print the non-free core 100 % white (they once lost it and extruded colour into it)."""
    vol, tex, target, _ = patch_scene()
    free = np.zeros(vol.shape, bool)
    free[-2:] = True  # a two-layer shell under the textured top
    rec = SceneRecord.from_arrays(SceneRecord("mesh", tex, target, free_mask=free).arrays())
    assert "fixed_share" not in rec.arrays() and rec.fixed is None
    mix = extrusion_baseline(vol, tex, target, rec.fixed_share(INKS3, vol.shape), table3)
    white = white_mixture(INKS3)
    np.testing.assert_array_equal(mix[~free], np.broadcast_to(white, mix[~free].shape))
    np.testing.assert_allclose(mix[-1].reshape(-1, 3), table3.lookup(target), atol=1e-6)  # the shell is coloured


def test_errors(table3):
    vol, tex, target, fixed = patch_scene()
    other = ColourTable(("a", "b", "c"), table3.mixtures, table3.rgb, table3.lab, table3.stderr, 1.0, 2, "k")
    with pytest.raises(ValueError, match="differ"):
        surface_baseline(vol, tex, target, fixed, other)
    with pytest.raises(ValueError, match="target_rgb"):
        surface_baseline(vol, tex, target[:5], fixed, table3)
    with pytest.raises(ParameterError, match="patch_mm must be a positive thickness"):
        colour_table(INKS3, patch_mm=0.0)


def test_the_default_ink_sets_table_ships_with_the_package(tmp_path, monkeypatch):
    """The default ink set's table is in the package (``colour_table.PACKAGED``) under the key the current code
    gives it, so a first `--init extrusion` or `inkopt evaluate` need not spend minutes building it. When this
    fails, the ink presets or the table's parameters changed: rebuild it (``colour_table(InkTable.parse(
    "vero-cmykw"))`` with an empty ``INKOPT_CACHE_DIR``) and copy the cache's file into the package's
    data/colour_tables/."""
    from inkopt.evaluation import colour_table as ct

    monkeypatch.setenv("INKOPT_CACHE_DIR", str(tmp_path))  # an empty cache: only the package has it
    monkeypatch.setattr(ct, "render_patches", lambda *a, **k: pytest.fail("the table was built, not read"))
    inks = InkTable.parse("vero-cmykw")
    table = ct.colour_table(inks)
    assert table.cached and table.ink_names == tuple(inks.names) and len(table.mixtures) > 500
    # it is the table a build makes: its patches' colours agree with fresh renders within their standard errors
    monkeypatch.undo()
    rows = np.arange(0, len(table.mixtures), len(table.mixtures) // 6)
    rgb, se = ct.render_patches(
        table.mixtures[rows], inks, inks.g, 1.5, ct.DEFAULT_PATCH_MM, ct.DEFAULT_MAX_STDERR, seed=12
    )
    assert np.all(delta_e76(linear_to_lab(rgb), table.lab[rows]) <= 4 * np.hypot(se, table.stderr[rows]))
    assert sorted(p.name for p in ct.PACKAGED.iterdir()) == [f"colour_table_{table.key}.npz"]  # nothing stale


def test_extrusion_of_centred_texels_takes_a_nearest_texel(table3):
    """Mesh texels (at voxel centres): the distance transform gives every inside voxel a texel at the smallest
    Euclidean distance in mm (any of equidistant ones), as a brute-force search over all texels finds it, on a
    ball in an anisotropic grid."""
    n = 12
    vmm = np.array([0.05, 0.07, 0.03])  # x, y, z
    c = (np.indices((n, n, n)).transpose(1, 2, 3, 0)[..., ::-1] + 0.5 - n / 2) * vmm  # xyz mm from the centre
    inside = np.linalg.norm(c / vmm.max(), axis=-1) < 0.45 * n * vmm.min() / vmm.max()
    normals = (c / np.maximum(np.linalg.norm(c, axis=-1, keepdims=True), 1e-9)).astype(np.float32)
    vol = Volume.from_mixture(
        voxel_mm=vmm, mixture=np.zeros((n, n, n, 3), np.float32), inks=INKS3, inside=inside, normals=normals
    )
    tex = Texels.from_normals(inside, normals)
    assert tex.centred and len(tex) > 50
    target = np.random.default_rng(0).random((len(tex), 3)).astype(np.float32)
    src = BaselineLayers("extrusion", vol, tex, target, None, table3)
    assert src.near is not None  # the distance-transform path
    pos_t = tex.position_mm(vmm)
    for z in range(n):
        flat = np.flatnonzero(inside[z].ravel())
        if not len(flat):
            continue
        yx = np.stack(np.unravel_index(flat, (n, n)), 1)
        pos = (np.column_stack([yx[:, ::-1], np.full(len(flat), z)]) + 0.5) * vmm
        dist = np.linalg.norm(pos[:, None] - pos_t[None], axis=2)
        got = dist[np.arange(len(flat)), src.nearest_texels(z, flat)]
        np.testing.assert_allclose(got, dist.min(1), rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(src[z][inside[z]], src.mix_t[src.nearest_texels(z, flat)])


@pytest.mark.parametrize("seed", range(6))
def test_nearest_centred_is_scipys_feature_transform_ties_included(seed):
    """The plane-at-a-time feature transform (``_core.feature_plane`` under ``_nearest_centred``) picks exactly the
    texel scipy's whole-grid ``distance_transform_edt(return_indices=True)`` picks, equidistant ones included
    (cubic voxels tie often), on random grids of sparse and dense features, cubic and anisotropic."""
    from scipy import ndimage

    from inkopt.evaluation.baselines import _nearest_centred

    rng = np.random.default_rng(seed)
    shape = tuple(int(v) for v in rng.integers(3, 14, 3))
    vmm = np.full(3, 0.0847) if seed % 2 else rng.uniform(0.03, 0.1, 3)
    voxel = np.argwhere(rng.random(shape) < (0.02, 0.1, 0.4)[seed % 3])
    if not len(voxel):
        voxel = np.array([[0, 0, 0]])
    tex = Texels(voxel, np.zeros(len(voxel)), np.tile([0.0, 0.0, 1.0], (len(voxel), 1)), centred=True)
    fill = rng.random(shape) < 0.7
    near, offsets = _nearest_centred(tex, fill, vmm)
    feature = np.ones(shape, bool)
    feature[tuple(voxel.T)] = False
    idx = ndimage.distance_transform_edt(feature, sampling=vmm[::-1], return_distances=False, return_indices=True)
    want = np.ravel_multi_index(tuple(i[fill] for i in idx), shape)
    got = np.ravel_multi_index(tuple(voxel[near].T), shape)
    np.testing.assert_array_equal(got, want)
    assert offsets[-1] == fill.sum()


@pytest.mark.parametrize("centred", [True, False])
def test_extrusion_read_only_at_some_voxels_is_bit_identical_there(table3, centred):
    """``only`` (a run's free voxels): the extrusion baseline's layers at those voxels equal the whole baseline's
    bit for bit, with fixed shares; its other voxels are 0, and the distance-transform path keeps a texel index
    for those voxels alone. Some asked voxels lie outside (they stay 0, as in the whole baseline)."""
    n = 10
    rng = np.random.default_rng(3)
    vmm = np.array([0.05, 0.07, 0.03])
    c = (np.indices((n, n, n)).transpose(1, 2, 3, 0)[..., ::-1] + 0.5 - n / 2) * vmm
    inside = np.linalg.norm(c / vmm.max(), axis=-1) < 0.45 * n * vmm.min() / vmm.max()
    normals = (c / np.maximum(np.linalg.norm(c, axis=-1, keepdims=True), 1e-9)).astype(np.float32)
    vol = Volume.from_mixture(
        voxel_mm=vmm, mixture=np.zeros((n, n, n, 3), np.float32), inks=INKS3, inside=inside, normals=normals
    )
    tex = Texels.from_normals(inside, normals)
    if not centred:  # face-centre texels: the k-d tree path
        tex = Texels(tex.voxel, tex.face, tex.normal, centred=False)
    target = rng.random((len(tex), 3)).astype(np.float32)
    fixed = np.zeros((n, n, n, 3), np.float32)
    fixed[inside & (rng.random(inside.shape) < 0.3), 0] = 0.25
    asked = np.flatnonzero((rng.random(inside.shape) < 0.4).ravel())
    whole = BaselineLayers("extrusion", vol, tex, target, fixed, table3)
    part = BaselineLayers("extrusion", vol, tex, target, fixed, table3, only=asked)
    if centred:
        assert part.near is not None and len(part.near) == int(inside.ravel()[asked].sum()) < len(whole.near)
    a, b = whole.array().reshape(-1, 3), part.array().reshape(-1, 3)
    np.testing.assert_array_equal(b[asked], a[asked])
    rest = np.ones(len(b), bool)
    rest[asked] = False
    assert not b[rest & ~(fixed.reshape(-1, 3).any(1))].any()
