"""Tests of inkopt.printing.formats.png_slices: PNG slice stacks read back with Pillow, manifest, material limits,
atomic writes; the job's checks (inkopt.printing.formats.job) and the ink colours (formats.slices)."""

import json

import numpy as np
import pytest
from PIL import Image

from inkopt.errors import ParameterError
from inkopt.model import Quantization
from inkopt.printing.formats.job import LabelVoxels, PrintJob, Provenance
from inkopt.printing.formats.png_slices import PngSlices, read_png_slices, write_png_slices
from inkopt.printing.formats.slices import DEFAULT_PALETTE, ink_colours
from inkopt.printing.profiles import PRINTER_PROFILES, printer_profile
from inkopt.printing.quantize import MixtureLayers, quantize

VP = np.array([25.4 / 600, 25.4 / 300, 0.027])
INKS = ["cyan", "magenta", "yellow", "black", "white"]


def job(labels, inks=INKS, printer=None, **kw) -> PrintJob:
    """A label job of ``labels`` on the J750's grid; ``printer`` a profile key."""
    return PrintJob(LabelVoxels(labels, VP, inks), None if printer is None else printer_profile(printer), **kw)


def random_labels(shape=(7, 11, 13), n=5, seed=0, empty=0.2):
    rng = np.random.default_rng(seed)
    lab = rng.integers(0, n, shape).astype(np.uint8)
    lab[rng.random(shape) < empty] = 255
    return lab


def leftovers(parent, name):
    return [p.name for p in parent.iterdir() if p.name.startswith(f".{name}.")]


def test_slice_stack_read_with_pillow(tmp_path):
    lab = random_labels()
    out = tmp_path / "job"
    man = write_png_slices(job(lab), out)
    Z, Y, X = lab.shape
    files = sorted(p.name for p in out.glob("*.png"))
    assert files == [f"slice_{k:05d}.png" for k in range(Z)]
    colour = {tuple(DEFAULT_PALETTE[name]) + (255,): i for i, name in enumerate(INKS)}
    colour[(0, 0, 0, 0)] = 255  # default background
    counts = {}
    for k in range(Z):
        with Image.open(out / files[k]) as im:
            assert im.mode == "RGBA" and im.size == (X, Y)
            assert im.info["dpi"] == pytest.approx((600, 300), abs=0.1)
            rgba = np.asarray(im)
        keys = [tuple(int(v) for v in px) for px in rgba.reshape(-1, 4)]
        assert set(keys) <= set(colour), "only palette colours and the background"
        decoded = np.array([colour[c] for c in keys], np.uint8).reshape(Y, X)
        np.testing.assert_array_equal(decoded, lab[k, ::-1, :])  # row 0 = largest y, column 0 = smallest x
        for c in keys:
            counts[c] = counts.get(c, 0) + 1
    for c, i in colour.items():
        assert counts.get(c, 0) == int(np.sum(lab == i))
    disk = json.loads((out / "manifest.json").read_text())
    assert disk == json.loads(json.dumps(man))
    assert disk["dpi"] == {"x": pytest.approx(600), "y": pytest.approx(300)}
    assert disk["layer_thickness_um"] == pytest.approx(27.0)
    assert disk["layer_count"] == Z and disk["image_size"] == {"width": X, "height": Y}
    assert [m["ink"] for m in disk["materials"]] == INKS
    assert [m["voxel_count"] for m in disk["materials"]] == [int(np.sum(lab == i)) for i in range(5)]
    assert disk["empty_voxel_count"] == int(np.sum(lab == 255))
    assert disk["materials"][0]["color"] == [0, 255, 255, 255] and disk["materials"][0]["hex"] == "#00FFFF"
    assert "largest y" in disk["orientation"]["rows"]
    back, _ = read_png_slices(out)
    np.testing.assert_array_equal(back, lab)
    assert leftovers(tmp_path, "job") == []


def test_quantize_then_export_roundtrip(tmp_path):
    mix = np.random.default_rng(1).dirichlet(np.ones(5), size=(6, 10, 12)).astype(np.float32)
    inside = np.ones(mix.shape[:3], bool)
    inside[:, :2] = False
    lab, vp = quantize(MixtureLayers(mix, (25.4 / 300,) * 3, inside), Quantization(ink_order="index"))
    man = write_png_slices(PrintJob(LabelVoxels(lab, vp, INKS), printer_profile("j750")), tmp_path / "s")
    assert man["layer_count"] == lab.shape[0] and man["materials_used"] == 5
    np.testing.assert_array_equal(read_png_slices(tmp_path / "s")[0], lab)


def test_refuses_too_many_materials(tmp_path):
    inks = INKS + ["transparent", "orange"]
    lab = random_labels(n=7, empty=0.0)
    assert PRINTER_PROFILES["j750"].max_materials == 6
    for kw, who in (
        ({"printer": "j750"}, "Stratasys J750 holds 6"),
        ({"max_materials": 6}, "the printer holds 6"),
        ({"printer": "J55"}, "J55 Prime holds 5"),
    ):
        with pytest.raises(ParameterError, match="uses 7 inks") as err:
            write_png_slices(job(lab, inks, **kw), tmp_path / "job")
        assert "\n" not in str(err.value) and who in str(err.value)
        assert "(cyan, magenta, yellow, black, white, transparent, orange)" in str(err.value)
        assert err.value.parameters == ("printer",) and str(err.value).endswith("material slots (printer)")
        assert not (tmp_path / "job").exists() and leftovers(tmp_path, "job") == []
    write_png_slices(job(lab, inks, " J850"), tmp_path / "ok")  # 7 fit a J850
    # only inks actually used count: 7 inks in the table but 3 used fit a 6-material printer
    write_png_slices(job(np.minimum(lab, 2), inks, "j750"), tmp_path / "few")
    with pytest.raises(ValueError, match="unknown printer"):
        printer_profile("j9000")
    with pytest.raises(ValueError, match="J850 holds 7"):  # the printer's limit, unless max_materials overrides it
        write_png_slices(job(np.arange(8, dtype=np.uint8).reshape(1, 2, 4), inks + ["cyan2"], "j850"), tmp_path / "y")
    write_png_slices(job(lab, inks, "j750", max_materials=7), tmp_path / "z")
    with pytest.raises(ParameterError, match="max_materials must be at least 1"):
        job(lab, inks, max_materials=0)


def test_manifest_names_printer_materials(tmp_path):
    inks = ["cyan", "magenta", "yellow", "black", "white", "orange"]
    man = write_png_slices(job(random_labels(n=6), inks, "j750"), tmp_path / "s")
    assert [m["material"] for m in man["materials"]] == [
        "VeroCY-V",
        "VeroMGT-V",
        "VeroYL-V",
        "VeroBlack",
        "VUltraWhite",
        None,
    ]
    assert man["printer"] == {"key": "j750", "name": "Stratasys J750"} and man["max_materials"] == 6
    assert json.loads((tmp_path / "s" / "manifest.json").read_text())["materials"][5]["material"] is None
    man = write_png_slices(job(random_labels(n=6), inks), tmp_path / "g")  # no printer: no material names
    assert man["printer"] is None and {m["material"] for m in man["materials"]} == {None}
    for key, prof in PRINTER_PROFILES.items():
        assert prof.max_materials is None or prof.max_materials >= 5, key


def test_atomic_on_error(tmp_path, monkeypatch):
    lab = random_labels()
    out = tmp_path / "job"
    write_png_slices(job(lab), out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    calls = {"n": 0}
    real_save = Image.Image.save

    def failing_save(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 3:
            raise OSError("disk full")
        return real_save(self, *args, **kwargs)

    monkeypatch.setattr(Image.Image, "save", failing_save)
    with pytest.raises(OSError, match="disk full"):
        write_png_slices(job(random_labels(seed=1)), out)
    with pytest.raises(OSError, match="disk full"):
        calls["n"] = 0
        write_png_slices(job(lab), tmp_path / "new")
    monkeypatch.undo()
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before, "the old folder survives intact"
    assert not (tmp_path / "new").exists()
    assert leftovers(tmp_path, "job") == [] and leftovers(tmp_path, "new") == []
    # a successful rewrite replaces the old folder completely
    write_png_slices(job(lab[:3]), out)
    assert len(list(out.glob("*.png"))) == 3 and leftovers(tmp_path, "job") == []


def test_refuses_foreign_folder(tmp_path):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "thesis.tex").write_text("precious")
    with pytest.raises(ValueError, match="not an inkopt slice folder"):
        write_png_slices(job(random_labels()), tmp_path / "mine")
    assert (tmp_path / "mine" / "thesis.tex").read_text() == "precious"


def test_palette_and_bad_input(tmp_path):
    cols = ink_colours(["cyan", "Glow", "white"], palette={"white": "#F0F0F0"})
    assert cols[0] == (0, 255, 255, 255) and cols[2] == (240, 240, 240, 255)
    assert cols[1][3] == 255 and cols[1] not in (cols[0], cols[2])
    with pytest.raises(ValueError, match="already used"):
        ink_colours(["cyan", "magenta"], palette={"magenta": (0, 255, 255)})
    with pytest.raises(ValueError, match="opaque"):
        ink_colours(["cyan"], palette={"cyan": (0, 255, 255, 128)})
    with pytest.raises(ValueError, match="already used"):
        ink_colours(["black"], background=(0, 0, 0, 255))
    with pytest.raises(ValueError, match="labels use ink 5"):
        write_png_slices(job(np.full((2, 2, 2), 5, np.uint8)), tmp_path / "a")
    with pytest.raises(ValueError, match="uint8"):
        job(np.zeros((2, 2, 2), np.int32))
    with pytest.raises(ValueError, match=r"^voxel_mm must be 3 positive sizes"):
        LabelVoxels(np.zeros((2, 2, 2), np.uint8), (1, 0, 1), INKS)
    with pytest.raises(ValueError, match="inks must be 1..254 unique names"):
        LabelVoxels(np.zeros((2, 2, 2), np.uint8), VP, ["cyan", "cyan"])
    with pytest.raises(ParameterError, match=r"^materials names unknown ink 'teal'; the inks are \['cyan'"):
        job(np.zeros((2, 2, 2), np.uint8), materials={"teal": "X"})
    with pytest.raises(ParameterError, match="materials names an empty name"):
        job(np.zeros((2, 2, 2), np.uint8), materials={"cyan": " "})
    assert not any(tmp_path.iterdir())


def test_background_option(tmp_path):
    lab = np.full((3, 2, 2), 255, np.uint8)
    lab[1, 0, 0] = 0
    man = PngSlices(background=(10, 20, 30, 255)).write(job(lab, ["white"]), tmp_path / "s")
    assert man["files"]["first"] == "slice_00000.png" and man["background"] == [10, 20, 30, 255]
    with Image.open(tmp_path / "s" / "slice_00001.png") as im:
        assert im.getpixel((0, 1)) == (255, 255, 255, 255) and im.getpixel((1, 1)) == (10, 20, 30, 255)
    assert man["materials_used"] == 1 and man["empty_voxel_count"] == 11


def test_manifest_records_the_sources_and_material_overrides(tmp_path):
    lab = random_labels()
    prov = Provenance("quantized.npz", "sha256:02", volume_digest="sha256:01")
    man = write_png_slices(
        job(lab, printer="j750", materials={"White": "VeroPureWht"}, provenance=prov), tmp_path / "s"
    )
    assert (man["volume_digest"], man["quantized_digest"]) == ("sha256:01", "sha256:02")
    assert list(man)[-2:] == ["volume_digest", "quantized_digest"]
    assert [m["material"] for m in man["materials"]][3:] == ["VeroBlack", "VeroPureWht"]
    assert "volume_digest" not in write_png_slices(job(lab), tmp_path / "t")
