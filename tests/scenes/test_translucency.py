"""Tests of translucency constraints (inkopt.scenes.translucency, model.Translucency): slab masks, mesh alpha and
texture-space masks, depth, the white core, scene.npz round trip, one-line errors, the CLI, and that the
constraint survives quantization."""

import numpy as np
import pytest
import trimesh
from PIL import Image

from inkopt import charts, cli
from inkopt.io import load_npz
from inkopt.model import InkTable, Volume
from inkopt.rundir import RunDir, SceneRecord
from inkopt.scenes.mesh import build_mesh_scene
from inkopt.scenes.slab import build_slab
from inkopt.scenes.spec import MeshSpec
from inkopt.scenes.translucency import load_mask

INKS = InkTable.parse("vero-cmykwt")
T = INKS.index("transparent")
W = INKS.index("white")


def _pic(h=20, w=30):
    return np.full((h, w, 3), 0.5, np.float32)


def _mask(h=20, w=30, s=0.8):
    """Share s in the left half of the picture (columns < w/2), 0 elsewhere."""
    m = np.zeros((h, w), np.float32)
    m[:, : w // 2] = s
    return m


def test_slab_constraint_region_depth_and_record():
    vox = 25.4 / 300
    sc = build_slab(
        _pic(), None, (30 * vox, 20 * vox, 10 * vox), INKS, translucency=_mask(), translucency_depth_mm=4 * vox
    )
    nz, ny, nx = sc.volume.shape
    assert (nz, ny, nx) == (10, 20, 30)
    fixed = np.asarray(sc.fixed_share)  # dense form of the compact FixedShares
    assert fixed.shape == (10, 20, 30, len(INKS))
    np.testing.assert_allclose(fixed[6:, :, :15, T], 0.8)  # the region, 4 layers from the top
    assert np.all(fixed[:6, ..., T] == 0) and np.all(fixed[:, :, 15:, T] == 0)
    assert np.all(np.delete(fixed, T, -1) == 0)  # the optimiser picks the rest
    # scene.npz round trip rebuilds the same fixed shares (evaluation and baselines read them so)
    rec = SceneRecord.from_arrays(sc.record().arrays())
    np.testing.assert_array_equal(rec.fixed_share(INKS, (nz, ny, nx)), fixed)
    assert rec.translucency.depth_mm == pytest.approx(4 * vox) and rec.translucency.ink == "transparent"
    np.testing.assert_allclose(rec.translucency.texel_share(sc.texels).reshape(ny, nx)[:, :15], 0.8)


def test_slab_whole_depth_and_picture_orientation():
    """Row 0 of the mask is the largest y (like the picture); default depth: the whole slab."""
    vox = 25.4 / 300
    m = np.zeros((20, 30), np.float32)
    m[:10] = 0.5  # top half of the picture = large y
    sc = build_slab(_pic(), None, (30 * vox, 20 * vox, 3 * vox), INKS, translucency=m)
    g = sc.translucency.grid()
    assert np.all(g[:, 10:] == 0.5) and np.all(g[:, :10] == 0)


def test_no_transparent_ink_is_one_line_error():
    with pytest.raises(ValueError, match="transparent ink.*vero-cmykwt"):
        build_slab(_pic(), None, (2.54, 1.693, 0.5), InkTable.parse("vero-cmykw"), translucency=_mask())


@pytest.mark.parametrize(
    "mask, needle",
    [
        (_mask(10, 15), "must be the same size"),
        (_mask() + 0.5, "shares must lie in 0..1"),
        (-_mask(), "shares must lie in 0..1"),
        (np.zeros((20, 30, 3)), "grey"),
    ],
)
def test_bad_mask_arrays(mask, needle):
    with pytest.raises(ValueError, match=needle):
        build_slab(_pic(), None, (2.54, 1.693, 0.5), INKS, translucency=mask)


def test_mask_files(tmp_path):
    Image.fromarray((_mask() * 255).round().astype(np.uint8)).save(tmp_path / "m8.png")
    np.testing.assert_allclose(load_mask(tmp_path / "m8.png"), _mask(), atol=0.5 / 255)
    Image.fromarray((_mask() * 65535).round().astype(np.uint16)).save(tmp_path / "m16.png")
    np.testing.assert_allclose(load_mask(tmp_path / "m16.png"), _mask(), atol=1e-4)
    (tmp_path / "junk.png").write_bytes(b"not an image")
    with pytest.raises(ValueError, match="cannot read translucency mask"):
        load_mask(tmp_path / "junk.png")
    with pytest.raises(ValueError, match="does not exist"):
        load_mask(tmp_path / "none.png")
    np.save(tmp_path / "bad.npy", np.full((2, 2), np.nan))
    with pytest.raises(ValueError, match="0..1"):
        load_mask(tmp_path / "bad.npy")


# ------------------------------------------------------------------------------------------------ meshes
def _alpha_cube(tmp_path, side=1.0):
    """A 1 mm cube with an RGBA texture: alpha 0.2 everywhere (share 0.8) except the +z face's cell (alpha 1)."""
    box = trimesh.creation.box(extents=[side] * 3)
    box = box.subdivide()  # several triangles per face
    uv = np.zeros((len(box.vertices), 2))
    top = box.vertices[:, 2] > side / 2 - 1e-9
    uv[top] = [0.75, 0.5]
    uv[~top] = [0.25, 0.5]
    img = np.zeros((8, 8, 4), np.uint8)
    img[..., :3] = 200
    img[:, :4, 3] = 51  # u < 0.5: alpha 0.2
    img[:, 4:, 3] = 255  # u >= 0.5: opaque
    mat = trimesh.visual.material.SimpleMaterial(image=Image.fromarray(img, "RGBA"))
    tm = trimesh.Trimesh(
        box.vertices, box.faces, visual=trimesh.visual.TextureVisuals(uv=uv, material=mat), process=False
    )
    path = tmp_path / "cube.glb"
    path.write_bytes(tm.export(file_type="glb"))
    return path


def test_mesh_alpha_depth_and_core(tmp_path):
    path = _alpha_cube(tmp_path)
    vox = 25.4 / 300
    spec = MeshSpec(path, scale=1.0, up="z", shell_mm=2 * vox, translucency="alpha", translucency_depth_mm=4 * vox)
    sc = build_mesh_scene(spec, INKS)
    g = sc.translucency.grid()
    inside = sc.vox.inside.dense()
    assert np.all(g[~inside] == 0)
    tex = sc.vox.texels
    ts = sc.translucency.texel_share(tex)
    up = tex.normal[:, 2] > 0.9
    assert np.all(ts[up] == 0)  # the opaque top face is unconstrained
    side = np.abs(tex.normal[:, 2]) < 0.1
    assert np.median(ts[side]) == pytest.approx(0.8, abs=0.01)
    # the region reaches 4 voxels deep: the centre of the cube (~6 voxels deep) is not constrained
    nz, ny, nx = inside.shape
    assert g[nz // 2, ny // 2, nx // 2] == 0
    fixed = np.asarray(sc.fixed_share)  # dense form of the compact FixedShares
    reached_core = (g > 0) & ~sc.free & inside
    assert reached_core.any()  # depth 4 > shell 2: the region reaches the core
    np.testing.assert_allclose(fixed[reached_core][:, T], g[reached_core])
    np.testing.assert_allclose(fixed[reached_core][:, W], 1 - g[reached_core])  # core: the rest stays white
    free_reg = (g > 0) & sc.free
    assert np.all(np.delete(fixed[free_reg], T, -1) == 0)
    core = ~sc.free & (g == 0)
    assert np.all(fixed[core][:, W] == 1)
    assert np.all(fixed.sum(-1) <= 1 + 1e-6)
    rec = SceneRecord.from_arrays(sc.record().arrays())
    rec.fixed = None  # as a large object stores it: free mask + sparse translucency
    np.testing.assert_array_equal(rec.fixed_share(INKS, inside.shape), fixed)


def test_mesh_texture_mask_and_errors(tmp_path):
    path = _alpha_cube(tmp_path)
    m = np.zeros((8, 8), np.uint8)
    m[:, 4:] = 153  # the top face's texels: a share of 153 / 255 = 0.6
    Image.fromarray(m).save(tmp_path / "mask.png")
    sc = build_mesh_scene(MeshSpec(path, scale=1.0, up="z", translucency=tmp_path / "mask.png"), INKS)
    ts = sc.translucency.texel_share(sc.vox.texels)
    up = sc.vox.texels.normal[:, 2] > 0.9
    assert np.all(ts[up] == pytest.approx(0.6)) and np.median(ts[~up]) == 0
    with pytest.raises(ValueError, match="transparent ink"):
        build_mesh_scene(MeshSpec(path, scale=1.0, translucency="alpha"), InkTable.parse("vero-cmykw"))
    sph = tmp_path / "ball.ply"
    trimesh.creation.icosphere(subdivisions=2, radius=0.5).export(sph)
    with pytest.raises(ValueError, match="no texture, vertex colours or face colours"):
        build_mesh_scene(MeshSpec(sph, scale=1.0, translucency="alpha"), INKS)
    with pytest.raises(ValueError, match="no uv coordinates"):
        build_mesh_scene(MeshSpec(sph, scale=1.0, translucency="alpha", constant_color=True), INKS)


# ------------------------------------------------------------------------------------------------ CLI
def test_slab_cli_constraint_and_errors(tmp_path, capsys):
    pytest.importorskip("inkopt._core")
    chart = charts.save(charts.colour_chart(24, 16), tmp_path / "chart.png")
    Image.fromarray((_mask(16, 24) * 255).round().astype(np.uint8)).save(tmp_path / "mask.png")
    base = [
        "slab",
        str(chart),
        "--size-mm",
        "2.032x1.355x0.5",
        "--iterations",
        "1",
        "--spp",
        "1",
        "--forward-spp",
        "1",
        "--eval-spp",
        "2",
        "--threads",
        "2",
    ]
    for extra, needle in [
        (["--translucency", str(tmp_path / "mask.png")], "needs a transparent ink"),
        (["--translucency", str(tmp_path / "none.png"), "--inks", "vero-cmykwt"], "does not exist"),
        (["--translucency", str(chart), "--inks", "vero-cmykwt", "--translucency-depth-mm", "-1"], "positive depth"),
    ]:
        out = tmp_path / "bad"
        assert cli.main(base + ["--out", str(out)] + extra) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("inkopt: error:") and needle in err and "\n" not in err
        assert not out.exists()
    Image.fromarray(np.zeros((10, 10), np.uint8)).save(tmp_path / "small.png")
    assert (
        cli.main(
            base
            + ["--out", str(tmp_path / "bad"), "--inks", "vero-cmykwt", "--translucency", str(tmp_path / "small.png")]
        )
        == 2
    )
    assert "same size" in capsys.readouterr().err
    out = tmp_path / "run"
    assert (
        cli.main(base + ["--out", str(out), "--inks", "vero-cmykwt", "--translucency", str(tmp_path / "mask.png")]) == 0
    )
    rd = RunDir(out)
    vol = rd.load_volume()
    rec = rd.load_scene()
    g = rec.translucency.grid()
    reg = g > 0
    assert reg.sum() == vol.shape[0] * vol.shape[1] * vol.shape[2] // 2
    fixed = rec.fixed_share(vol.inks, vol.shape)
    rest = vol.mixture - fixed  # the optimiser's part: 20 % of the region's voxels, any inks
    assert np.all(rest > -1e-6) and np.all(vol.mixture[reg][:, T] >= 0.8 - 1e-6)
    np.testing.assert_allclose(rest[reg].sum(-1), 0.2, atol=1e-5)
    assert rd.read_report()["translucency"]["mean_share"] == pytest.approx(0.8, abs=0.01)
    assert "translucency_index" in load_npz(out / "scene.npz", "scene")


# ------------------------------------------------------------------------------------------------ quantization
def test_constraint_holds_through_quantization():
    """Printer labels of a constrained region hold the required share of transparent ink, within the halftone's
    tolerance: blue-noise dithering is error-free up to its quantization per layer, so the region's label fraction
    differs from the mean mixture share by a few printer voxels' worth; we allow 4 binomial standard errors of the
    region's printer-voxel count (a random draw's spread, which blue noise beats by far)."""
    from inkopt.printing.quantize import quantize_volume

    vox = 25.4 / 300
    rng = np.random.default_rng(3)
    shape = (8, 24, 24)
    for s in (0.8, 0.35):
        m = np.zeros((24, 24), np.float32)
        m[4:20, 2:12] = s
        sc = build_slab(
            _pic(24, 24), None, (24 * vox, 24 * vox, 8 * vox), INKS, translucency=m, translucency_depth_mm=5 * vox
        )
        fixed = np.asarray(sc.fixed_share)  # dense form of the compact FixedShares
        free = rng.dirichlet(np.ones(len(INKS)), size=shape)
        mix = (fixed + (1 - fixed.sum(-1, keepdims=True)) * free).astype(np.float32)
        vol = Volume.from_mixture(voxel_mm=(vox,) * 3, mixture=mix, inks=INKS)
        q = quantize_volume(vol)
        lab = q.labels
        # the region in printer voxels: map printer voxel centres back to optimisation voxels
        Z, Y, X = lab.shape
        iz = np.minimum(((np.arange(Z) + 0.5) * q.voxel_mm[2] / vox).astype(int), shape[0] - 1)
        iy = np.minimum(((np.arange(Y) + 0.5) * q.voxel_mm[1] / vox).astype(int), shape[1] - 1)
        ix = np.minimum(((np.arange(X) + 0.5) * q.voxel_mm[0] / vox).astype(int), shape[2] - 1)
        reg = sc.translucency.grid()[np.ix_(iz, iy, ix)] > 0
        n = int(reg.sum())
        want = mix[..., T][np.ix_(iz, iy, ix)][reg].mean()  # the required share plus the free part's own
        got = float((lab[reg] == T).mean())
        tol = 4 * np.sqrt(want * (1 - want) / n)
        assert abs(got - want) < tol, (s, got, want, tol, n)
        assert got >= s - tol
