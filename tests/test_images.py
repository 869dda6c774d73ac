"""Every image read goes through inkopt.images.open_image: a decompression bomb (a small file that declares a huge
image) is refused in one line naming the file, its pixel count and the limit, before a pixel is decoded, whether
it is a slab picture, a mesh texture (given or named by an MTL), a translucency mask or a printer package's layer."""

import io
import struct
import warnings
import zipfile
import zlib

import numpy as np
import pytest
from PIL import Image

from inkopt.cli import main
from inkopt.images import MAX_IMAGE_PIXELS, ImageError, ImageTooLargeError, open_image
from inkopt.printing.formats.inspection import PackageError, read_image
from inkopt.scenes.mesh.source import load_texture
from inkopt.scenes.slab import describe_picture, load_picture
from inkopt.scenes.translucency import load_mask


def bomb_png(w: int, h: int) -> bytes:
    """A PNG whose header declares ``w`` x ``h`` RGB pixels, with one short row of data: tiny on disk, and a
    reader that checks the size first never gets to the missing rows."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b"")
    )


def test_the_limit_lies_below_pillows_own():
    """Pillow warns above its MAX_IMAGE_PIXELS: an image inkopt accepts never makes it warn."""
    assert MAX_IMAGE_PIXELS < Image.MAX_IMAGE_PIXELS


@pytest.mark.parametrize(
    ("w", "h", "says"),
    [
        (20000, 20000, "has 400,000,000 pixels"),  # Pillow's own error range (above twice its limit)
        (10000, 10000, "has 10000 x 10000 px, 100,000,000 pixels"),  # Pillow's warning range
        (8193, 8192, "has 8193 x 8192 px, 67,117,056 pixels"),  # just above this limit
    ],
)
def test_bombs_are_refused_before_decoding(tmp_path, w, h, says):
    path = tmp_path / "bomb.png"
    path.write_bytes(bomb_png(w, h))
    for source in (path, path.read_bytes()):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # Pillow's DecompressionBombWarning would fail here
            with pytest.raises(ImageTooLargeError) as exc:
                with open_image(source, f"picture {path}"):
                    pass
        msg = str(exc.value)
        assert msg.startswith(f"picture {path} {says}") and "more than the limit of 67,108,864" in msg
        assert "\n" not in msg


def test_missing_junk_and_truncated_files(tmp_path):
    with pytest.raises(ImageError, match=r"^mask .*nothere.png does not exist$"):
        with open_image(tmp_path / "nothere.png", f"mask {tmp_path / 'nothere.png'}"):
            pass
    (tmp_path / "junk.png").write_text("not an image")
    with pytest.raises(ImageError, match=r"^cannot read j: not an image file Pillow reads$"):
        with open_image(tmp_path / "junk.png", "j"):
            pass
    buf = io.BytesIO()
    Image.fromarray(np.random.default_rng(0).integers(0, 255, (64, 64, 3), np.uint8)).save(buf, "PNG")
    with pytest.raises(ImageError, match="^cannot read t: "):
        with open_image(buf.getvalue()[:300], "t"):  # header whole, pixel data cut short
            pass
    with open_image(buf.getvalue()[:300], "t", decode=False) as im:  # the header alone reads
        assert im.size == (64, 64)


def test_a_good_image_reads(tmp_path):
    Image.new("RGB", (5, 3), (10, 20, 30)).save(tmp_path / "ok.png")
    with open_image(tmp_path / "ok.png", "ok") as im:
        assert np.asarray(im)[0, 0].tolist() == [10, 20, 30]


@pytest.fixture
def bomb(tmp_path):
    path = tmp_path / "bomb.png"
    path.write_bytes(bomb_png(20000, 20000))
    return path


@pytest.mark.parametrize(
    ("read", "what"),
    [
        (load_picture, "picture"),
        (describe_picture, "picture"),
        (load_texture, "texture"),
        (load_mask, "translucency mask"),
    ],
)
def test_every_scene_input_is_checked(bomb, read, what):
    with pytest.raises(ValueError, match=rf"^{what} {bomb} has 400,000,000 pixels, more than the limit"):
        read(bomb)


def test_package_layers_are_checked(bomb):
    with pytest.raises(PackageError, match=r"^layer_0.png has 400,000,000 pixels, more than the limit"):
        read_image(bomb.read_bytes(), "layer_0.png", (14, 10))


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("inkopt: error: "), err
    return err[0]


def test_cli_slab_picture_and_mask(bomb, tmp_path, capsys):
    Image.new("RGB", (60, 40), (200, 100, 50)).save(tmp_path / "ok.png")
    base = ["--size-mm", "6x4x1", "--iterations", "1", "--inks", "vero-cmykwt"]
    assert main(["slab", str(bomb), *base, "--out", str(tmp_path / "a")]) == 2
    assert "picture" in _one_error_line(capsys) and not (tmp_path / "a").exists()
    argv = ["slab", str(tmp_path / "ok.png"), *base, "--translucency", str(bomb), "--out", str(tmp_path / "b")]
    assert main(argv) == 2
    assert f"translucency mask {bomb} has 400,000,000 pixels" in _one_error_line(capsys)


def test_cli_inspect_gcvf_layer(bomb, tmp_path, capsys):
    from inkopt.printing.formats import FORMATS
    from inkopt.printing.formats.job import LabelVoxels, PrintJob
    from inkopt.printing.profiles import printer_profile

    lab = np.zeros((3, 10, 14), np.uint8)
    voxel = np.array([25.4 / 600, 25.4 / 300, 0.027])
    FORMATS["gcvf"].write(PrintJob(LabelVoxels(lab, voxel, ["white"]), printer_profile("j750")), tmp_path / "j.gcvf")
    with zipfile.ZipFile(tmp_path / "j.gcvf") as zi, zipfile.ZipFile(tmp_path / "bad.gcvf", "w") as zo:
        for name in zi.namelist():
            zo.writestr(name, bomb.read_bytes() if name == "layer_1.png" else zi.read(name))
    assert main(["inspect", str(tmp_path / "bad.gcvf")]) == 2
    assert "layer_1.png has 400,000,000 pixels, more than the limit of 67,108,864" in _one_error_line(capsys)
