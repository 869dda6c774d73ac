"""Scene specs (inkopt.scenes.spec): frozen and picklable, one-line errors for bad inputs before any file is read,
the JSON form round trip, and ``build`` giving the scene the scene modules build from the same inputs."""

import pickle
from dataclasses import FrozenInstanceError

import numpy as np
import pytest
import trimesh

from inkopt import charts
from inkopt.cli.common import flag_of
from inkopt.errors import ParameterError
from inkopt.model import InkTable
from inkopt.scenes import build_scene
from inkopt.scenes.slab import build_slab, load_picture
from inkopt.scenes.spec import MeshSpec, SlabSpec, spec_from_json

INKS = InkTable.parse("vero-cmykw")


@pytest.fixture(scope="module")
def chart(tmp_path_factory):
    return charts.save(charts.colour_chart(24, 16), tmp_path_factory.mktemp("chart") / "chart.png")


@pytest.fixture(scope="module")
def ball(tmp_path_factory):
    sph = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    col = np.where(sph.vertices[:, 2:3] > 0, [[0, 200, 230, 255]], [[230, 0, 160, 255]]).astype(np.uint8)
    path = tmp_path_factory.mktemp("ball") / "ball.ply"
    trimesh.Trimesh(sph.vertices, sph.faces, vertex_colors=col, process=False).export(path)
    return path


def test_frozen_picklable_and_json_round_trip(chart, ball):
    specs = [
        SlabSpec(chart, (2, 4 / 3, 0.5)),
        SlabSpec(chart, (2, 4 / 3, 0.5), chart, 150, chart, 0.2),
        MeshSpec(ball, height_mm=1, up="z"),
        MeshSpec(ball, scale=2, shell_mm=0.3, translucency="alpha"),
        MeshSpec(ball, height_mm=1, shell_mm=1, core="white=0.9,black=0.1"),
    ]
    for spec in specs:
        assert pickle.loads(pickle.dumps(spec)) == spec
        assert spec_from_json(spec.to_json()) == spec
        with pytest.raises(FrozenInstanceError):
            spec.dpi = 1.0
    assert specs[0].to_json()["kind"] == "image" and "translucency" not in specs[0].to_json()
    assert "scale" not in specs[2].to_json() and specs[3].to_json()["scale"] == 2.0
    assert "core" not in specs[2].to_json() and specs[4].to_json()["core"] == "white=0.9,black=0.1"


@pytest.mark.parametrize(
    "spec, message",
    [
        (lambda c, b: MeshSpec(b), "exactly one of height_mm H"),
        (lambda c, b: MeshSpec(b, height_mm=1, scale=1), "exactly one of height_mm H"),
        (lambda c, b: MeshSpec(b, height_mm=-1), "height_mm must be positive"),
        (lambda c, b: MeshSpec(b, height_mm=1, shell_mm=0), "shell_mm must be a positive thickness"),
        (lambda c, b: MeshSpec(b, height_mm=1, up="x"), "up must be one of"),
        (lambda c, b: MeshSpec(b, height_mm=1, dpi=0), "dpi must be positive"),
        (lambda c, b: MeshSpec(str(b) + ".missing", height_mm=1), "does not exist"),
        (lambda c, b: MeshSpec(b, height_mm=1, shell_mm=1, core="grey"), "core must be one of"),
        (lambda c, b: MeshSpec(b, height_mm=1, core="start"), "core start fills the voxels below shell_mm"),
        (lambda c, b: MeshSpec(b, height_mm=1, shell_mm=1, core="white=0.9,white=0.1"), "core must be one of"),
        (lambda c, b: MeshSpec(b, height_mm=1, shell_mm=1, core="white=1.1,black=-0.1"), "core must be one of"),
        (lambda c, b: MeshSpec(b, height_mm=1, shell_mm=1, core="white=0.8,black=0.1"), "core shares must sum to 1"),
        (lambda c, b: SlabSpec(c, (2, 1, -1)), "size_mm sizes must be three positive numbers"),
        (lambda c, b: SlabSpec(c, (6, 4, 1e-9)), r"size_mm 6x4x1e-09 mm: the depth 1e-09 mm is less than one voxel"),
        (lambda c, b: SlabSpec(c, (0.05, 4, 1), dpi=300), r"the width 0.05 mm is less than one voxel \(0.08467 mm at"),
        (
            lambda c, b: SlabSpec(c, (2, 1, 0.2), dpi=100),
            r"the depth 0.2 mm is less than one voxel \(0.254 mm at 100 DPI",
        ),
        (lambda c, b: SlabSpec(str(c) + ".missing", (2, 1, 1)), "picture"),
        (lambda c, b: SlabSpec(c, (2, 1, 1), translucency_depth_mm=0.2), "needs translucency"),
        (lambda c, b: SlabSpec(c, (2, 1, 1), translucency=c, translucency_depth_mm=-1), "positive depth"),
        (lambda c, b: SlabSpec(c, (2, 1, 1), translucency="alpha"), "translucency mask alpha does not exist"),
    ],
)
def test_one_line_errors(chart, ball, spec, message):
    """In Python the errors name the parameters; on the command line the same errors name their flags."""
    with pytest.raises(ValueError, match=message) as err:
        spec(chart, ball).validate()
    assert "\n" not in str(err.value)
    if isinstance(err.value, ParameterError) and err.value.parameters:
        flags = err.value.render(flag_of)
        assert all(flag_of(name) in flags for name in err.value.parameters) and "_" not in flags.split()[0]


def test_a_slab_side_of_one_voxel_is_enough(chart):
    """The grid holds round(side / voxel) voxels a side: one voxel is the thinnest slab (arrays too)."""
    from inkopt.units import voxel_mm

    SlabSpec(chart, (2, 4 / 3, voxel_mm(300))).validate()
    pic = load_picture(chart)
    assert build_slab(pic, None, (2, 4 / 3, voxel_mm(300)), INKS).volume.shape[0] == 1
    with pytest.raises(ValueError, match="less than one voxel"):
        build_slab(pic, None, (2, 4 / 3, 0.01), INKS)


def test_ink_set_checks(chart, ball):
    with pytest.raises(ValueError, match="transparent ink"):
        SlabSpec(chart, (2, 4 / 3, 0.5), translucency=chart).validate(INKS)
    with pytest.raises(ValueError, match="white"):
        MeshSpec(ball, height_mm=1).validate(InkTable.parse("cyan,magenta,yellow,black"))
    with pytest.raises(ValueError, match="core names ink 'transparent', not in the ink set"):
        MeshSpec(ball, height_mm=1, shell_mm=1, core="white=0.5,transparent=0.5").validate(InkTable.parse("vero-cmykw"))


def test_build_scene_reads_the_spec(chart, ball):
    """``build_scene`` builds a slab from the spec's picture files as ``build_slab`` does from the pictures, and a
    mesh spec into a mesh scene with its shell; a bad spec is refused before anything is read."""
    a = build_scene(SlabSpec(chart, (2, 4 / 3, 0.5), chart), INKS)
    pic = load_picture(chart)
    b = build_slab(pic, pic, (2, 4 / 3, 0.5), INKS)
    np.testing.assert_array_equal(a.target_rgb, b.target_rgb)
    assert a.volume.shape == b.volume.shape and a.faces == b.faces and "chart.png" in a.describe()
    m = build_scene(MeshSpec(ball, height_mm=1, up="z", shell_mm=0.2), INKS)
    assert m.kind == "mesh" and 0 < m.free.sum() < m.vox.inside.count
    with pytest.raises(ValueError, match="shell_mm"):
        build_scene(MeshSpec(str(ball) + ".missing", height_mm=1, shell_mm=-1), INKS)


def test_a_slab_too_large_for_the_machine_is_refused_before_anything_is_read(tmp_path):
    """A slab whose grid cannot fit: one line naming the grid, the memory and a --dpi that fits (which does)."""
    from inkopt.model.volume import VolumeError
    from inkopt.scenes.spec import SlabSpec

    spec = SlabSpec(tmp_path / "missing.png", (3000, 2000, 1000))  # the size is checked before the file
    with pytest.raises(VolumeError) as e:
        spec.validate()
    msg = str(e.value)
    msg = e.value.render(flag_of)  # as the command line prints it
    assert "\n" not in msg and "3000 x 2000 x 1000 mm at 300 DPI" in msg and "--size-mm" in msg
    dpi = int(msg.split("--dpi ")[1].split()[0])
    with pytest.raises(ValueError, match="does not exist"):  # at the suggested DPI only the missing picture is left
        SlabSpec(tmp_path / "missing.png", (3000, 2000, 1000), dpi=dpi).validate()
