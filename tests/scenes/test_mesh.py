"""Tests of inkopt.scenes.mesh: loading, voxelization (volume, SDF, normals, colours), baking, GLB and views."""

import numpy as np
import pytest
import trimesh
from helpers import SPOT
from PIL import Image

from inkopt.model import FACE_NORMALS
from inkopt.scenes.mesh import bake_vertex_colors, load_mesh, mesh_from_trimesh, render_views, voxelize, write_glb

# sRGB 128/255 decoded to linear by the IEC 61966-2-1 formula (reference value, not our code)
LIN = {0: 0.0, 128: 0.21586050011389926, 255: 1.0}
# one colour per face id (0 -x, 1 +x, 2 -y, 3 +y, 4 -z, 5 +z), channels from {0, 128, 255}
FACE_RGB = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 0], [128, 0, 255], [0, 128, 128]])


@pytest.fixture(scope="module")
def sphere():
    sph = trimesh.creation.icosphere(subdivisions=4, radius=2.0)
    return sph, voxelize(mesh_from_trimesh(sph, scale=1.0, up="z"))


def test_sphere_volume_and_depth(sphere):
    sph, vo = sphere
    assert vo.voxel_mm == pytest.approx([25.4 / 300] * 3)
    vol = vo.inside.count * np.prod(vo.voxel_mm)
    assert vol == pytest.approx(sph.volume, rel=0.01)  # 0.02 % in practice; 47 voxels across
    # analytic sphere SDF (the icosphere's faces lie within ~2 um of the sphere): the inside mask is its sign, the
    # near depths are exact for the inside voxels less than the band deep, and listed for no other voxel
    nz, ny, nx = vo.shape
    zz, yy, xx = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    pos = vo.origin_mm + (np.stack([xx, yy, zz], -1) + 0.5) * vo.voxel_mm
    true = (np.linalg.norm(pos - [0, 0, 2.0], axis=-1) - 2.0).reshape(-1)
    clear = np.abs(true) > 0.005
    assert np.all(vo.inside.at(np.flatnonzero(clear)) == (true[clear] < 0))
    dp = vo.depth
    assert dp.index.dtype == np.int64 and dp.mm.dtype == np.float32 and vo.inside.dense().dtype == bool
    assert len(np.unique(dp.index)) == len(dp.index) and vo.inside.at(dp.index).all()
    assert np.abs(dp.mm - (-true[dp.index])).max() < 0.005
    assert np.all((dp.mm > 0) & (dp.mm < vo.band_mm))
    listed = np.zeros(true.size, bool)
    listed[dp.index] = True
    deep_enough = vo.inside.dense().reshape(-1) & (-true < vo.band_mm - 0.01)
    assert np.all(listed[deep_enough])
    assert not listed[vo.inside.dense().reshape(-1) & (-true > vo.band_mm + 0.01)].any()
    # within: the voxels at most that deep; a depth beyond the band is refused
    sel = dp.within(0.2)
    assert np.array_equal(np.sort(sel), np.sort(dp.index[dp.mm <= np.float32(0.2)]))
    with pytest.raises(ValueError, match="band"):
        dp.within(vo.band_mm)


def test_sphere_texels_and_normals(sphere):
    _, vo = sphere
    tx = vo.texels
    # texels = inside voxels with a 6-neighbour outside, in C order of (z, y, x)
    ins = np.pad(vo.inside.dense(), 1)
    core = (
        ins[1:-1, 1:-1, 1:-1]
        & ins[:-2, 1:-1, 1:-1]
        & ins[2:, 1:-1, 1:-1]
        & ins[1:-1, :-2, 1:-1]
        & ins[1:-1, 2:, 1:-1]
        & ins[1:-1, 1:-1, :-2]
        & ins[1:-1, 1:-1, 2:]
    )
    np.testing.assert_array_equal(tx.voxel, np.argwhere(vo.inside.dense() & ~core))
    # Bound 0.5 deg: subdivision-4 icosphere edges span ~4 deg of arc, so flat face normals deviate up to
    # ~2.7 deg from radial and a one-voxel SDF gradient by several degrees; interpolated smooth normals at the
    # closest point deviate only to second order (~0.2 deg measured).
    radial = vo.texel_centres_mm() - [0, 0, 2.0]
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    ang = np.degrees(np.arccos(np.clip(np.sum(radial * tx.normal, 1), -1, 1)))
    assert ang.max() < 0.5
    # the chosen face is exposed and the most aligned of the exposed ones
    off = np.array([[0, 0, -1], [0, 0, 1], [0, -1, 0], [0, 1, 0], [-1, 0, 0], [1, 0, 0]])
    nb = tx.voxel + off[tx.face]
    assert not vo.inside.dense()[nb[:, 0], nb[:, 1], nb[:, 2]].any()
    assert np.mean(np.sum(FACE_NORMALS[tx.face] * tx.normal, 1) > 0.55) > 0.99
    # the normals volume carries the texel normals and nothing else
    np.testing.assert_array_equal(vo.normals.at(tx.voxel), tx.normal)
    assert len(vo.normals.index) == len(tx)
    # closest points lie on the flat faces, within their sagitta (~2 um) of the sphere
    assert np.linalg.norm(vo.closest_mm - [0, 0, 2.0], axis=1) == pytest.approx(2.0, abs=0.003)


def _textured_cube(side=2.0, margin=0.15):
    """A cube (24 vertices) whose faces sample distinct cells of a 3 x 2 cell texture (16 px cells)."""
    box = trimesh.creation.box(extents=[side] * 3)
    corners = np.array(box.vertices)
    verts, faces, uvs = [], [], []
    for fid in range(6):
        axis, sgn = fid // 2, 1 if fid % 2 else -1
        quad = corners[np.isclose(corners[:, axis] * sgn, side / 2)]
        u_ax, v_ax = [a for a in range(3) if a != axis]
        ang = np.arctan2(quad[:, v_ax], quad[:, u_ax])
        quad = quad[np.argsort(ang)]
        cu, cv = fid % 3, fid // 3  # the cell of this face
        uv = np.stack(
            [
                (cu + margin + (1 - 2 * margin) * (quad[:, u_ax] > 0)) / 3,
                (cv + margin + (1 - 2 * margin) * (quad[:, v_ax] > 0)) / 2,
            ],
            1,
        )
        base = len(verts) * 4
        tri = np.array([[0, 1, 2], [0, 2, 3]]) + base
        n = np.cross(quad[1] - quad[0], quad[2] - quad[0])
        if n[axis] * sgn < 0:
            tri = tri[:, ::-1]
        verts.append(quad)
        faces.append(tri)
        uvs.append(uv)
    img = np.zeros((32, 48, 3), np.uint8)
    for fid in range(6):
        cu, cv = fid % 3, fid // 3
        img[32 - 16 * (cv + 1) : 32 - 16 * cv, 16 * cu : 16 * (cu + 1)] = FACE_RGB[fid]  # v = 0 at the bottom
    mat = trimesh.visual.material.SimpleMaterial(image=Image.fromarray(img), diffuse=[255, 255, 255, 255])
    vis = trimesh.visual.TextureVisuals(uv=np.concatenate(uvs), material=mat)
    return trimesh.Trimesh(np.concatenate(verts), np.concatenate(faces), visual=vis, process=False)


def _check_cube(m, vo, file_face_of_ours):
    assert m.color_source == "texture"
    assert vo.inside.count == 20**3 and len(vo.texels) == 20**3 - 18**3  # faces on voxel boundaries
    ours = np.argmax(vo.texels.normal @ FACE_NORMALS.T, 1)
    assert np.all(np.max(vo.texels.normal @ FACE_NORMALS.T, 1) > 0.9999)  # sharp creases stay sharp
    np.testing.assert_array_equal(vo.texels.face, ours)
    want = np.vectorize(LIN.get)(FACE_RGB[file_face_of_ours[ours]])
    np.testing.assert_allclose(vo.targets, want, atol=1e-5)


def test_textured_cube_colours():
    m = mesh_from_trimesh(_textured_cube(), scale=1.0, up="z")
    _check_cube(m, voxelize(m, voxel_mm=0.1), np.arange(6))


def test_textured_cube_glb_y_up(tmp_path):
    """Through a GLB file (glTF flips v; trimesh undoes it) and the y-up mapping: file +y -> our +z."""
    path = tmp_path / "cube.glb"
    path.write_bytes(_textured_cube().export(file_type="glb"))
    m = load_mesh(path, height_mm=2.0)
    assert m.vertices[:, 2].min() == pytest.approx(0) and np.ptp(m.vertices[:, 2]) == pytest.approx(2.0)
    # (x, y, z)_ours = (x, -z, y)_file: our -y is the file's +z, our +z the file's +y, ...
    _check_cube(m, voxelize(m, voxel_mm=0.1), np.array([0, 1, 5, 4, 2, 3]))


def test_vertex_colour_ply(tmp_path):
    sph = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    sph.visual.vertex_colors = np.where(sph.vertices[:, :1] > 0, [255, 128, 0, 255], [0, 0, 255, 255])
    path = tmp_path / "s.ply"
    path.write_bytes(sph.export(file_type="ply"))
    m = load_mesh(path, scale=1.0, up="z")
    assert m.color_source == "vertex"
    vo = voxelize(m, voxel_mm=0.1)
    x = vo.closest_mm[:, 0]
    np.testing.assert_allclose(vo.targets[x > 0.3], [[1.0, LIN[128], 0.0]] * int(np.sum(x > 0.3)), atol=1e-5)
    np.testing.assert_allclose(vo.targets[x < -0.3], [[0.0, 0.0, 1.0]] * int(np.sum(x < -0.3)), atol=1e-5)


@pytest.mark.skipif(not SPOT.is_file(), reason="Spot data set not present")
def test_spot_loads_and_voxelizes():
    m = load_mesh(SPOT, height_mm=6.0)
    assert m.color_source == "texture" and m.texture.size == (1024, 1024)
    assert len(m.solid_vertices) < len(m.vertices)  # seams merged
    solid = m.solid_trimesh()
    assert solid.is_watertight and solid.volume > 0
    assert m.vertices[:, 2].min() == pytest.approx(0) and np.ptp(m.vertices[:, 2]) == pytest.approx(6.0)
    vo = voxelize(m)
    assert vo.inside.count * np.prod(vo.voxel_mm) == pytest.approx(solid.volume, rel=0.01)
    t = vo.targets
    assert t.shape == (len(vo.texels), 3) and t.dtype == np.float32 and np.all((t >= 0) & (t <= 1))
    lum = t @ [0.2126, 0.7152, 0.0722]
    assert np.mean(lum < 0.06) > 0.03 and np.mean(lum > 0.5) > 0.3  # dark patches (0.051) on a white cow
    assert np.any(t[:, 0] - t[:, 2] > 0.2)  # the orange muzzle


def test_argument_errors():
    sph = trimesh.creation.icosphere(subdivisions=2)
    with pytest.raises(ValueError, match="exactly one of height_mm H .* and scale S"):
        mesh_from_trimesh(sph)
    with pytest.raises(ValueError, match="exactly one of height_mm H .* and scale S"):
        mesh_from_trimesh(sph, height_mm=5, scale=1)
    with pytest.raises(ValueError, match="does not exist"):
        load_mesh("/nonexistent/mesh.obj", height_mm=5)
    with pytest.raises(ValueError, match="voxel_mm"):
        voxelize(mesh_from_trimesh(sph, scale=1), voxel_mm=-1)


@pytest.mark.parametrize("kind", ["quad", "half-sphere"])
def test_open_mesh_rejected(kind):
    if kind == "quad":
        tm = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]], process=False)
    else:
        sph = trimesh.creation.icosphere(subdivisions=3)
        tm = trimesh.Trimesh(sph.vertices, sph.faces[sph.triangles_center[:, 2] < 0], process=False)
    with pytest.raises(ValueError, match="does not enclose a solid"):
        mesh_from_trimesh(tm, scale=1.0)


@pytest.mark.parametrize("damage", ["inside-out", "inconsistent"])
def test_orientation_repaired(damage):
    """An inside-out mesh, or one with 20 % of its faces flipped, voxelizes exactly like the intact one."""
    sph = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    ref = voxelize(mesh_from_trimesh(sph, scale=1.0, up="z"), voxel_mm=0.1)
    faces = sph.faces.copy()
    sel = np.ones(len(faces), bool) if damage == "inside-out" else np.random.default_rng(1).random(len(faces)) < 0.2
    faces[sel] = faces[sel, ::-1]
    vo = voxelize(
        mesh_from_trimesh(trimesh.Trimesh(sph.vertices, faces, process=False), scale=1.0, up="z"), voxel_mm=0.1
    )
    np.testing.assert_array_equal(vo.inside.dense(), ref.inside.dense())
    np.testing.assert_allclose(vo.texels.normal, ref.texels.normal, atol=1e-6)
    assert np.all(np.sum(vo.texels.normal * (vo.closest_mm - [0, 0, 1]), 1) > 0)  # outward


def test_bake_glb_roundtrip_and_views(sphere, tmp_path):
    sph, vo = sphere
    mesh = mesh_from_trimesh(sph, scale=1.0, up="z")
    rgb = np.clip((vo.closest_mm - [0, 0, 2.0]) / 4 + 0.5, 0, 1).astype(np.float32)  # a smooth colour field
    baked = bake_vertex_colors(mesh, vo.closest_mm, rgb, texel_normal=vo.texels.normal)
    vc = np.asarray(baked.visual.vertex_colors)
    assert vc.shape == (len(mesh.solid_vertices), 4) and vc.dtype == np.uint8
    want = np.clip((mesh.solid_vertices - [0, 0, 2.0]) / 4 + 0.5, 0, 1)
    got = vc[:, :3] / 255.0
    got = np.where(got <= 0.04045, got / 12.92, ((got + 0.055) / 1.055) ** 2.4)
    assert np.abs(got - want).max() < 0.03  # texels ~0.08 mm apart on a field of slope 0.25 / mm
    path = tmp_path / "out" / "pred.glb"
    write_glb(baked, path)
    back = trimesh.load(path, force="mesh", process=False)
    assert back.visual.kind == "vertex"
    np.testing.assert_array_equal(np.asarray(back.visual.vertex_colors), vc)
    assert not any(p.name.endswith(".tmp") for p in path.parent.iterdir())
    png = tmp_path / "views.png"
    render_views(mesh, baked, np.full((len(mesh.solid_vertices), 3), 0.5, np.float32), png, views=3, size=96)
    im = Image.open(png)
    assert im.size == (3 * 96, 2 * 96) and im.mode == "RGB"
    arr = np.asarray(im)
    assert (arr == 255).all(-1).mean() > 0.2  # white background
    assert arr[:96].std() > arr[96:].std()  # the colour field (top row) varies more than the grey (bottom)
