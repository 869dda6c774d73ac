"""Where a scene's target colour comes from: missing materials and textures, meshes without UVs or colours, and
every image mode Pillow reads (16-bit grey, float grey, palette, CMYK, CIELAB, alpha) as the right colours."""

import numpy as np
import pytest
import trimesh
from helpers import RED, srgb_to_linear, write_cube_obj
from PIL import Image

from inkopt.cli import main
from inkopt.scenes.mesh import load_mesh
from inkopt.scenes.mesh.source import describe_colour_source
from inkopt.scenes.picture import picture_rgba
from inkopt.scenes.slab import load_picture


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(mtllib=None), r"names no material library \(no mtllib line\) but m.mtl is beside it"),
        (dict(map_kd="nothere.png"), "names texture nothere.png, which does not exist"),
        (dict(mtllib="other.mtl"), "names material library other.mtl, which does not exist"),
        (dict(uv=False), r"has a texture but no texture coordinates"),
        (dict(mtllib=None, write_mtl=False), "so the target would be the constant #FFFFFF"),
        (dict(map_kd=None), "so the target would be the constant #FFFFFF"),
    ],
)
def test_obj_colour_problems_are_refused(tmp_path, kw, match):
    obj = write_cube_obj(tmp_path / "c", **kw)
    with pytest.raises(ValueError, match=match) as e:
        load_mesh(obj, height_mm=2.0)
    assert "\n" not in str(e.value)


JUNK = "root:x:0:0:root:/root:/bin/bash\n"  # what /etc/passwd holds: neither a material library nor an image


@pytest.mark.parametrize(
    "kw, files, match",
    [
        (dict(usemtl="Other"), {}, r"uses material Other \(usemtl\), which .*m.mtl does not define \(it defines mat\)"),
        (dict(mtllib="junk.txt"), {"junk.txt": JUNK}, r"names material library .*junk.txt, which defines no material"),
        (
            dict(map_kd="junk.txt"),
            {"junk.txt": JUNK},
            r"cannot read texture .*junk.txt \(map_Kd of material mat in m.mtl\)",
        ),
        (dict(usemtl=None), {}, r"gives its faces no material \(m.mtl defines mat\)"),
        (
            dict(head=["mtllib x.mtl"]),
            {"x.mtl": "newmtl x\n"},
            r"names 2 material libraries \(x.mtl, m.mtl\), but only",
        ),
        (dict(head=["# written without mtllib"]), {}, r"mentions 'mtllib' on line 1, before its mtllib statement"),
        (dict(sep="\t"), {}, r"12 of its 12 faces have no material the mesh reader could resolve"),  # reads 'usemtl
        (dict(map_kd="-s 1 1 1 tex.png"), {}, r"could not read texture .*tex.png of material mat \(map_Kd options"),
    ],
)
def test_obj_materials_trimesh_would_replace_are_refused(tmp_path, kw, files, match):
    """Each of these gets trimesh's grey 2 x 2 placeholder texture (or no texture) without a word: an error naming
    the file, the material and the fix; accepted with a texture or a constant colour given."""
    obj = write_cube_obj(tmp_path / "c", **kw)
    for name, text in files.items():
        (tmp_path / "c" / name).write_text(text)
    with pytest.raises(ValueError, match=match) as e:
        load_mesh(obj, height_mm=2.0)
    assert "\n" not in str(e.value) and "`texture` FILE" in e.value.template
    m = load_mesh(obj, height_mm=2.0, texture=tmp_path / "c" / "tex.png")
    assert describe_colour_source(m) == f"texture {tmp_path / 'c' / 'tex.png'} (8 x 8 px)"
    assert describe_colour_source(load_mesh(obj, height_mm=2.0, constant_color=True)) == "constant colour #FFFFFF"


def test_textured_and_untextured_materials_keep_their_colours(tmp_path):
    """An OBJ whose faces use a textured material and an untextured one (Kd only): trimesh packs both into one
    atlas; each face keeps its material's colour exactly (red texture, blue Kd) and the atlas's transparent
    padding is no alpha channel of the file's."""
    obj = write_cube_obj(tmp_path / "c")
    lines = obj.read_text().splitlines()
    first_face = next(i for i, ln in enumerate(lines) if ln.startswith("f "))
    lines.insert(first_face + 6, "usemtl plain")
    obj.write_text("\n".join(lines) + "\n")
    (tmp_path / "c" / "m.mtl").write_text("newmtl mat\nKd 1 1 1\nmap_Kd tex.png\nnewmtl plain\nKd 0 0 1\n")
    m = load_mesh(obj, height_mm=2.0)
    assert m.texture_alpha is None and describe_colour_source(m).startswith("texture tex.png (")
    got = m.colors_at(np.arange(len(m.faces)), np.full((len(m.faces), 3), 1 / 3))
    red, blue = srgb_to_linear(np.array(RED) / 255), np.array([0.0, 0.0, 1.0])
    is_red = np.abs(got - red).max(1) < 1e-3
    assert is_red.sum() == 6 and np.abs(got[~is_red] - blue).max() < 1e-3


def test_texture_line_names_the_texture_used(tmp_path):
    """The log line gives the file and the size of the texture the target is made from, not trimesh's stand-in."""
    from helpers import SPOT

    for name in ("spot.obj", "spot.mtl", "spot_texture.png"):
        (tmp_path / name).write_bytes((SPOT.parent / name).read_bytes())
    assert describe_colour_source(load_mesh(tmp_path / "spot.obj", height_mm=4.0)) == (
        "texture spot_texture.png (1024 x 1024 px)"
    )
    obj = tmp_path / "wrongname.obj"
    obj.write_text((tmp_path / "spot.obj").read_text().replace("mtllib spot.mtl", "mtllib wrongname.mtl"))
    (tmp_path / "wrongname.mtl").write_text("newmtl SomethingElse\nKd 1 1 1\nmap_Kd spot_texture.png\n")
    with pytest.raises(ValueError, match="uses material Default_OBJ .usemtl., which .*wrongname.mtl does not define"):
        load_mesh(obj, height_mm=4.0)


def test_obj_texture_bomb_is_refused_by_name(tmp_path):
    from test_images import bomb_png

    obj = write_cube_obj(tmp_path / "c")
    (tmp_path / "c" / "tex.png").write_bytes(bomb_png(20000, 20000))
    with pytest.raises(ValueError, match=r"texture .*tex.png \(map_Kd of material mat in m.mtl\) has 400,000,000 pix"):
        load_mesh(obj, height_mm=2.0)


def test_obj_fixes_named_in_the_errors(tmp_path):
    ok = load_mesh(write_cube_obj(tmp_path / "ok"), height_mm=2.0)
    assert describe_colour_source(ok) == "texture tex.png (8 x 8 px)"
    obj = write_cube_obj(tmp_path / "nolib", mtllib=None)
    m = load_mesh(obj, height_mm=2.0, texture=tmp_path / "ok" / "tex.png")  # --texture FILE
    assert describe_colour_source(m).startswith("texture ") and m.texture_alpha is None
    np.testing.assert_allclose(m.colors_at([0], [[1, 0, 0]]), [srgb_to_linear(np.array(RED) / 255)], atol=1e-5)
    c = load_mesh(obj, height_mm=2.0, constant_color=True)  # trimesh's grey placeholder is not used
    assert describe_colour_source(c) == "constant colour #FFFFFF" and c.texture_alpha is None
    with pytest.raises(ValueError, match="no texture coordinates"):
        load_mesh(write_cube_obj(tmp_path / "nouv", uv=False), height_mm=2.0, texture=tmp_path / "ok" / "tex.png")


def test_uncoloured_ply_needs_the_flag(tmp_path):
    path = tmp_path / "ball.ply"
    trimesh.creation.icosphere(subdivisions=2, radius=0.5).export(path)
    with pytest.raises(ValueError, match="no texture, vertex colours or face colours"):
        load_mesh(path, scale=1.0)
    assert load_mesh(path, scale=1.0, constant_color=True).color_source == "constant"


def test_cli_refuses_obj_without_mtllib_in_one_line(tmp_path, capsys):
    obj = write_cube_obj(tmp_path / "c", mtllib=None)
    out = tmp_path / "run"
    assert main(["optimize", str(obj), "--height-mm", "2", "--out", str(out), "--iterations", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("inkopt: error: ") and "mtllib m.mtl" in err[0]
    assert not out.exists()


# ------------------------------------------------------------------------------------------------ image modes
def _modes():
    """(image, expected sRGB (r, g, b, alpha) in 0..1 of pixel (0, 0)) for the modes Pillow reads."""
    g16 = Image.fromarray(np.full((4, 6), 40000, np.uint16))
    assert g16.mode == "I;16"
    i32 = Image.fromarray(np.full((4, 6), 40000, np.int32))
    f32 = Image.fromarray(np.full((4, 6), 0.25, np.float32))
    pal = Image.new("P", (6, 4), 1)
    pal.putpalette([0, 0, 0, 10, 200, 40] + [0] * 762)
    la = Image.new("LA", (6, 4), (100, 128))
    cmyk = Image.new("CMYK", (6, 4), (255, 0, 0, 0))  # full cyan, no profile: Pillow's inversion
    one = Image.new("1", (6, 4), 1)
    lab = Image.new("LAB", (6, 4), (255, 128, 128))  # L* = 100, a* = b* = 0: white
    g = 40000 / 65535
    return [
        (g16, (g, g, g, 1)),
        (i32, (g, g, g, 1)),
        (f32, (0.25, 0.25, 0.25, 1)),
        (pal, (10 / 255, 200 / 255, 40 / 255, 1)),
        (la, (100 / 255, 100 / 255, 100 / 255, 128 / 255)),
        (cmyk, (0, 1, 1, 1)),
        (one, (1, 1, 1, 1)),
        (lab, (1, 1, 1, 1)),
    ]


@pytest.mark.parametrize("im, want", _modes(), ids=lambda v: getattr(v, "mode", ""))
def test_picture_modes(im, want):
    got = picture_rgba(im)
    assert got.shape == (4, 6, 4) and got.dtype == np.float32
    np.testing.assert_allclose(got[0, 0], want, atol=1.5 / 255)


def test_sixteen_bit_grey_png_is_grey_not_white(tmp_path):
    path = tmp_path / "g16.png"
    Image.fromarray(np.full((10, 15), 40000, np.uint16)).save(path)
    lin = load_picture(path)
    np.testing.assert_allclose(lin[0, 0], [srgb_to_linear(40000 / 65535)] * 3, rtol=1e-4)


def test_out_of_range_grey_is_refused():
    with pytest.raises(ValueError, match="outside 0..1"):
        picture_rgba(Image.fromarray(np.full((2, 2), 3.0, np.float32)), "p.tif")


def test_sixteen_bit_mesh_texture(tmp_path):
    tex = Image.fromarray(np.full((8, 8), 40000, np.uint16))
    m = load_mesh(write_cube_obj(tmp_path / "c", texture=tex), height_mm=2.0)
    want = srgb_to_linear(round(40000 / 65535 * 255) / 255)
    np.testing.assert_allclose(m.colors_at([0], [[1, 0, 0]]), [[want] * 3], atol=1e-5)


def test_mesh_spec_refuses_missing_material_files_before_the_mesh_is_read(tmp_path):
    """select-inks checks its target's spec before any run: an OBJ's missing texture is refused there."""
    from inkopt.scenes.spec import MeshSpec

    obj = write_cube_obj(tmp_path / "c", map_kd="nothere.png")
    with pytest.raises(ValueError, match="names texture nothere.png, which does not exist"):
        MeshSpec(obj, height_mm=2.0).validate()
    MeshSpec(obj, height_mm=2.0, constant_color=True).validate()  # the flag accepts it on purpose
