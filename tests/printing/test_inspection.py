"""Tests of the formats' checkers (inkopt.printing.formats: inspect_package, the registry's format_of, and
formats.inspection): GCVF packages and slice folders written, read back (same labels, counts and box) and then
broken one part at a time: each break is found and named in one line."""

import io
import json
import zipfile

import numpy as np
import pytest
from PIL import Image

from inkopt.printing.formats import FORMATS, format_of, inspect_package
from inkopt.printing.formats.inspection import PackageError, PackageReport, preview
from inkopt.printing.formats.job import LabelVoxels, PrintJob, Provenance
from inkopt.printing.profiles import printer_profile

VP = np.array([25.4 / 600, 25.4 / 300, 0.027])
INKS = ["cyan", "magenta", "yellow", "black", "white", "orange"]


def job(labels, inks=INKS, **kw) -> PrintJob:
    """A J750 label job."""
    return PrintJob(LabelVoxels(labels, VP, inks), printer_profile("j750"), **kw)


def labels(shape=(6, 10, 14), seed=0):
    lab = np.random.default_rng(seed).integers(0, len(INKS), shape).astype(np.uint8)
    lab[:, :3] = 255  # label rows 0-2 empty: image rows Y-3..Y-1
    lab[:, :, 12:] = 255
    lab[0] = 255
    return lab


def box_of(lab):
    Z, Y, X = lab.shape
    z, y, x = np.nonzero(lab != 255)
    return [int(x.min()), Y - 1 - int(y.max()), int(z.min()), int(x.max()) + 1, Y - int(y.min()), int(z.max()) + 1]


def rewrite(src, dst, change):
    """Copy the zip ``src`` to ``dst`` with ``change(name, data)`` -> new data (None: leave the member out)."""
    with zipfile.ZipFile(src) as zi, zipfile.ZipFile(dst, "w") as zo:
        for name in zi.namelist():
            data = change(name, zi.read(name))
            if data is not None:
                zo.writestr(name, data)
        zo.comment = zi.comment


def png(arr) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(arr).save(buf, format="PNG")
    return buf.getvalue()


@pytest.fixture
def package(tmp_path):
    lab = labels()
    FORMATS["gcvf"].write(job(lab, provenance=Provenance("quantized.npz", "sha256:01")), tmp_path / "job.gcvf")
    return lab, tmp_path / "job.gcvf"


def test_gcvf_round_trip(package, tmp_path):
    lab, path = package
    rep, scan = inspect_package(path, labels=True, keep_layers=(2,))
    np.testing.assert_array_equal(scan.labels, lab)
    assert (rep.kind, rep.layers, rep.width, rep.height) == ("gcvf", 6, 14, 10)
    assert rep.dpi == (600, 300) and rep.layer_um == 27 and rep.bounding_box == box_of(lab)
    assert [m["voxel_count"] for m in rep.materials] == [int(np.sum(lab == i)) for i in range(len(INKS))]
    assert [m["name"] for m in rep.materials][:3] == ["VeroCY-V", "VeroMGT-V", "VeroYL-V"]
    assert rep.source == {"source": "quantized.npz", "digest": "sha256:01"}
    assert PackageReport.from_json(json.loads(json.dumps(rep.to_json()))) == rep
    preview(rep, scan, [m["color"] for m in rep.materials], tmp_path / "p.png")
    with Image.open(tmp_path / "p.png") as im:
        assert im.size == (2 * 14 + 4, 2 * 10)  # top view and layer 2, rows doubled (300 DPI in y)


def test_slices_round_trip(tmp_path):
    lab = labels()
    FORMATS["png-slices"].write(job(lab), tmp_path / "s")
    rep, scan = inspect_package(tmp_path / "s", labels=True)
    np.testing.assert_array_equal(scan.labels, lab)
    assert rep.kind == "png-slices" and rep.bounding_box == box_of(lab) and rep.source is None
    assert [m["voxel_count"] for m in rep.materials] == [int(np.sum(lab == i)) for i in range(len(INKS))]
    (tmp_path / "s" / "slice_00003.png").unlink()
    with pytest.raises(PackageError, match=r"^layer 3 is missing \(5 layer images, manifest.json declares 6\)$"):
        inspect_package(tmp_path / "s")


def edit_config(old, new):
    return lambda name, data: data.replace(old, new, 1) if name == "ConfigFile.xml" else data


def drop(member):
    return lambda name, data: None if name == member else data


BREAKS = [
    (drop("layer_2.png"), r"^layer 2 is missing \(5 layer images, ConfigFile.xml declares 6\)$"),
    (edit_config(b"<NumberOfSlices>6<", b"<NumberOfSlices>5<"), r"^layer image layer_5.png is beyond the 5 layers"),
    (edit_config(b"<SliceWidth>14<", b"<SliceWidth>15<"), r"^layer_0.png is 14 x 10 px; the package declares 15 x 10$"),
    (
        edit_config(b"<VoxelCount>", b"<VoxelCount>1"),
        r"^ConfigFile.xml gives VeroCY-V 1\d+ voxels; the slices hold \d+$",
    ),
    (
        edit_config(b"<RGBA>0 255 255 255<", b"<RGBA>0 250 255 255<"),
        r"^layer_1.png: pixel \(row \d+, column \d+\) has colour \[0, 255, 255, 255\], not in the palette$",
    ),
]


@pytest.mark.parametrize(("change", "message"), BREAKS)
def test_gcvf_disagreements(package, tmp_path, change, message):
    _, path = package
    rewrite(path, tmp_path / "bad.gcvf", change)
    with pytest.raises(PackageError, match=message) as exc:
        inspect_package(tmp_path / "bad.gcvf")
    assert "\n" not in str(exc.value)


def test_gcvf_foreign_colour_ktn_zbuffer_and_stl(package, tmp_path):
    lab, path = package
    with zipfile.ZipFile(path) as zf:
        layer = np.asarray(Image.open(io.BytesIO(zf.read("layer_3.png")))).copy()
        ktn = np.frombuffer(zf.read("MeshBbx.ktn"), "<f4").copy()
        zb = np.asarray(Image.open(io.BytesIO(zf.read("Zbuffer.png")))).copy()
        stl = bytearray(zf.read("Mesh.stl"))
    layer[4, 5] = (10, 20, 30, 255)
    rewrite(path, tmp_path / "a.gcvf", lambda n, d: png(layer) if n == "layer_3.png" else d)
    with pytest.raises(PackageError, match=r"^layer_3.png: pixel \(row 4, column 5\) has colour \[10, 20, 30, 255\]"):
        inspect_package(tmp_path / "a.gcvf")
    ktn[3] += 1  # the box one column too wide
    rewrite(path, tmp_path / "b.gcvf", lambda n, d: ktn.tobytes() if n == "MeshBbx.ktn" else d)
    with pytest.raises(PackageError, match=r"^MeshBbx.ktn holds \[.*\]; the printed voxels' box is \[.*\]$"):
        inspect_package(tmp_path / "b.gcvf")
    zb[0, 0] += 1
    rewrite(path, tmp_path / "c.gcvf", lambda n, d: png(zb) if n == "Zbuffer.png" else d)
    with pytest.raises(PackageError, match=r"^Zbuffer.png at \(row 0, column 0\) is \d+; the topmost printed layer is"):
        inspect_package(tmp_path / "c.gcvf")
    rec = np.frombuffer(bytes(stl[84:]), np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])).copy()
    rec["v"][:, :, 0] += VP[0] * 2  # the mesh two columns off
    rewrite(path, tmp_path / "d.gcvf", lambda n, d: bytes(stl[:84]) + rec.tobytes() if n == "Mesh.stl" else d)
    with pytest.raises(PackageError, match=r"^Mesh.stl's min x is 0.\d+ mm; the printed voxels' is 0.0000 mm$"):
        inspect_package(tmp_path / "d.gcvf")


def test_not_a_package(tmp_path):
    (tmp_path / "x.gcvf").write_text("no zip")
    with pytest.raises(PackageError, match=r"x.gcvf is no printer package inkopt reads \(png-slices, gcvf, 3mf\)$"):
        inspect_package(tmp_path / "x.gcvf")
    with zipfile.ZipFile(tmp_path / "y.gcvf", "w") as zf:
        zf.writestr("readme.txt", "no package")
    with pytest.raises(PackageError, match="no printer package"):
        inspect_package(tmp_path / "y.gcvf")
    with pytest.raises(PackageError, match="does not exist"):
        inspect_package(tmp_path / "none.gcvf")


def test_the_format_is_told_by_the_contents(tmp_path):
    """A 3MF exported under any name (``export --out``) is read as a 3MF."""
    import shutil

    labels = np.zeros((2, 3, 4), np.uint8)
    out = tmp_path / "a.3mf"
    FORMATS["3mf"].write(job(labels, ["white"]), out)
    shutil.copy(out, tmp_path / "renamed_3mf")
    assert inspect_package(tmp_path / "renamed_3mf")[0].kind == "3mf"
    assert format_of(tmp_path / "renamed_3mf") is FORMATS["3mf"]
