"""Wrong inputs that used to pass silently or with a confusing message: an object too large for the grid, a pickled
lighting map, a mesh with a small hole."""

import numpy as np
import pytest
import trimesh

from inkopt.cli import main
from inkopt.cli.common import flag_of
from inkopt.model import InkTable
from inkopt.scenes.mesh import build_mesh_scene, load_mesh
from inkopt.scenes.spec import MeshSpec

INKS = InkTable.parse("vero-cmykw")


def coloured_ball(path, drop_faces=0):
    sph = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    faces = sph.faces[drop_faces:]
    col = np.tile([200, 100, 50, 255], (len(sph.vertices), 1))
    trimesh.Trimesh(sph.vertices, faces, vertex_colors=col, process=False).export(path)
    return path


def test_a_400_mm_object_names_the_memory_and_the_dpi(tmp_path):
    ball = coloured_ball(tmp_path / "ball.ply")
    with pytest.raises(ValueError) as e:
        build_mesh_scene(MeshSpec(ball, height_mm=400.0, up="z"), INKS)
    msg = e.value.render(flag_of)  # as the command line prints it
    assert "height_mm" in str(e.value) and "--height-mm" in msg
    assert "\n" not in msg and "np.int64" not in msg
    assert "400 x 400 x 400 mm at 300 DPI" in msg and "GiB" in msg and "--dpi" in msg
    dpi = int(msg.split("--dpi ")[1].split()[0])
    assert 0 < dpi < 300
    # the suggested resolution fits the limit the message states
    from inkopt.model.volume import MAX_GRID_VOXELS
    from inkopt.scenes.mesh.scene import MIN_BYTES_PER_GRID_VOXEL, check_grid_size

    check_grid_size(load_mesh(ball, height_mm=400.0, up="z"), dpi)
    assert (400 / (25.4 / dpi)) ** 3 <= MAX_GRID_VOXELS * MIN_BYTES_PER_GRID_VOXEL


def test_pickled_lighting_map_is_refused_without_numpy_advice(tmp_path, capsys):
    path = tmp_path / "env.npy"
    np.save(path, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    vol = tmp_path / "v.npz"
    from inkopt.model import Volume

    Volume.from_mixture(voxel_mm=(0.0847,) * 3, mixture=np.full((2, 2, 2, 5), 0.2, np.float32), inks=INKS).save(vol)
    assert main(["render", str(vol), "--spp", "1", "--lighting", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pickled data" in err[0] and "allow_pickle" not in err[0]


def test_a_mesh_with_a_small_hole_is_noted(tmp_path):
    whole = load_mesh(coloured_ball(tmp_path / "whole.ply"), scale=1.0, up="z")
    assert whole.warnings == []
    holed = load_mesh(coloured_ball(tmp_path / "holed.ply", drop_faces=1), scale=1.0, up="z")
    assert len(holed.warnings) == 1 and "3 open edges" in holed.warnings[0]
    scene = build_mesh_scene(MeshSpec(tmp_path / "holed.ply", scale=1.0, up="z"), INKS)
    assert scene.warnings == holed.warnings
