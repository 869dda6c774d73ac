"""Pictures and textures with an embedded ICC profile are read in their own colour space: their colours are
converted to sRGB (LittleCMS) and agree with colour-science's conversion of the same numbers; an sRGB profile
changes nothing; an unreadable profile is one line naming the file."""

import colour
import numpy as np
import pytest
from helpers import fuzz, srgb_to_linear, write_cube_obj
from hypothesis import given
from hypothesis import strategies as st
from iccprofiles import rgb_profile as make_profile
from PIL import Image

from inkopt.scenes.mesh import load_mesh
from inkopt.scenes.mesh.source import describe_colour_source
from inkopt.scenes.picture import picture_rgba, rgb_profile
from inkopt.scenes.slab import describe_picture, load_picture

# one 8-bit level: LittleCMS works in 8 bits a channel, colour-science in floating point
LEVEL = 1.0 / 255
SPACES = {"Display P3": None, "Adobe RGB (1998)": 563 / 256}  # transfer: sRGB's curve, Adobe RGB's gamma
RGB = np.array([[200, 50, 30], [40, 160, 90], [60, 90, 210], [128, 128, 128], [250, 240, 20]], np.uint8)


def _image(space, rgb=RGB, mode="RGB"):
    im = Image.fromarray(rgb[None], "RGB").convert(mode)
    im.info["icc_profile"] = make_profile(space, curve=SPACES.get(space))
    return im


def _colour_science(space, rgb):
    return colour.RGB_to_RGB(
        rgb / 255.0,
        colour.RGB_COLOURSPACES[space],
        colour.RGB_COLOURSPACES["sRGB"],
        chromatic_adaptation_transform="Bradford",
        apply_cctf_decoding=True,
        apply_cctf_encoding=True,
    )


@pytest.mark.parametrize("space", SPACES)
def test_wide_gamut_pictures_are_converted_like_colour_science(space):
    got = picture_rgba(_image(space))[0]
    want = _colour_science(space, RGB.astype(float))
    inside = np.all((want >= 0) & (want <= 1), axis=1)  # colours outside sRGB are clipped: compare the rest
    assert inside.sum() >= 3
    np.testing.assert_allclose(got[inside, :3], want[inside], atol=1.5 * LEVEL)
    assert np.abs(got[:, :3] - RGB / 255.0).max() > 10 * LEVEL  # read as sRGB they would be other colours
    np.testing.assert_array_equal(got[:, 3], 1.0)


def test_alpha_survives_the_conversion():
    rgba = np.concatenate([RGB, np.array([[255], [0], [128], [255], [7]], np.uint8)], 1)
    im = Image.fromarray(rgba[None], "RGBA")
    im.info["icc_profile"] = make_profile("Display P3")
    got = picture_rgba(im)[0]
    np.testing.assert_allclose(got[:, 3], rgba[:, 3] / 255.0)


def test_an_srgb_profile_changes_nothing():
    im = _image("sRGB")
    assert rgb_profile(im) is None
    np.testing.assert_array_equal(picture_rgba(im)[0, :, :3], RGB / np.float32(255))


def test_an_unreadable_profile_is_one_line_naming_the_file():
    im = Image.fromarray(RGB[None], "RGB")
    im.info["icc_profile"] = b"\x00\x00\x01\x00" + b"junk" * 60
    with pytest.raises(ValueError, match=r"^tex.png: its embedded ICC profile cannot be read") as e:
        picture_rgba(im, "tex.png")
    assert "\n" not in str(e.value)


def test_slab_picture_is_read_through_its_profile(tmp_path):
    path = tmp_path / "p3.png"
    Image.fromarray(np.repeat(RGB[None], 2, 0), "RGB").save(path, icc_profile=make_profile("Display P3"))
    lin = load_picture(path)[0]
    want = srgb_to_linear(np.clip(_colour_science("Display P3", RGB.astype(float)), 0, 1))
    inside = np.all((_colour_science("Display P3", RGB.astype(float)) >= 0), axis=1)
    np.testing.assert_allclose(lin[inside], want[inside], atol=2 * LEVEL)
    assert "converted to sRGB from ICC profile Display P3" in describe_picture(path)


@pytest.mark.parametrize("override", [False, True])
def test_mesh_texture_is_read_through_its_profile(tmp_path, override):
    tex = Image.new("RGB", (8, 8), tuple(int(v) for v in RGB[0]))
    obj = write_cube_obj(tmp_path / "c")
    target = tmp_path / "c" / ("p3.png" if override else "tex.png")
    tex.save(target, icc_profile=make_profile("Display P3"))
    m = load_mesh(obj, height_mm=2.0, texture=target if override else None)
    want = srgb_to_linear(np.round(np.clip(_colour_science("Display P3", RGB[0].astype(float)), 0, 1) * 255) / 255)
    np.testing.assert_allclose(m.colors_at([0], [[1, 0, 0]])[0], want, atol=srgb_to_linear(2 * LEVEL) + 1e-3)
    assert m.texture_alpha is None
    assert "converted to sRGB from ICC profile Display P3" in describe_colour_source(m)


@fuzz(60)
@given(st.data())
def test_damaged_profiles_give_one_clean_error_or_a_conversion(data):
    """Any byte of a valid profile replaced, or the profile cut short: one line naming the file, or colours."""
    icc = bytearray(make_profile("Display P3"))
    for _ in range(data.draw(st.integers(1, 8))):
        icc[data.draw(st.integers(0, len(icc) - 1))] = data.draw(st.integers(0, 255))
    icc = bytes(icc[: data.draw(st.integers(0, len(icc)))])
    im = Image.fromarray(RGB[None], "RGB")
    im.info["icc_profile"] = icc
    try:
        got = picture_rgba(im, "tex.png")
    except ValueError as exc:
        assert str(exc).startswith("tex.png: ") and "\n" not in str(exc)
    else:
        assert got.shape == (1, 5, 4) and np.all((got >= 0) & (got <= 1))
