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
    with pytest.raises(PackageError, match=r"/s: layer 3 is missing \(5 layer images, manifest.json declares 6\)$"):
        inspect_package(tmp_path / "s")


def edit_config(old, new):
    return lambda name, data: data.replace(old, new, 1) if name == "ConfigFile.xml" else data


def drop(member):
    return lambda name, data: None if name == member else data


BREAKS = [
    (drop("layer_2.png"), r"\.gcvf: layer 2 is missing \(5 layer images, ConfigFile.xml declares 6\)$"),
    (
        edit_config(b"<NumberOfSlices>6<", b"<NumberOfSlices>5<"),
        r"\.gcvf: layer image layer_5.png is beyond the 5 layers",
    ),
    (
        edit_config(b"<SliceWidth>14<", b"<SliceWidth>15<"),
        r"\.gcvf: layer_0.png is 14 x 10 px; the package declares 15 x 10$",
    ),
    (
        edit_config(b"<VoxelCount>", b"<VoxelCount>1"),
        r"\.gcvf: ConfigFile.xml gives VeroCY-V 1\d+ voxels; the slices hold \d+$",
    ),
    (
        edit_config(b"<RGBA>0 255 255 255<", b"<RGBA>0 250 255 255<"),
        r"\.gcvf: layer_1.png: pixel \(row \d+, column \d+\) has colour \[0, 255, 255, 255\], not in the palette$",
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
    with pytest.raises(
        PackageError, match=r"\.gcvf: layer_3.png: pixel \(row 4, column 5\) has colour \[10, 20, 30, 255\]"
    ):
        inspect_package(tmp_path / "a.gcvf")
    ktn[3] += 1  # the box one column too wide
    rewrite(path, tmp_path / "b.gcvf", lambda n, d: ktn.tobytes() if n == "MeshBbx.ktn" else d)
    with pytest.raises(PackageError, match=r"\.gcvf: MeshBbx.ktn holds \[.*\]; the printed voxels' box is \[.*\]$"):
        inspect_package(tmp_path / "b.gcvf")
    zb[0, 0] += 1
    rewrite(path, tmp_path / "c.gcvf", lambda n, d: png(zb) if n == "Zbuffer.png" else d)
    with pytest.raises(
        PackageError, match=r"\.gcvf: Zbuffer.png at \(row 0, column 0\) is \d+; the topmost printed layer is"
    ):
        inspect_package(tmp_path / "c.gcvf")
    rec = np.frombuffer(bytes(stl[84:]), np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])).copy()
    rec["v"][:, :, 0] += VP[0] * 2  # the mesh two columns off
    rewrite(path, tmp_path / "d.gcvf", lambda n, d: bytes(stl[:84]) + rec.tobytes() if n == "Mesh.stl" else d)
    with pytest.raises(PackageError, match=r"\.gcvf: Mesh.stl's min x is 0.\d+ mm; the printed voxels' is 0.0000 mm$"):
        inspect_package(tmp_path / "d.gcvf")


def test_not_a_package(tmp_path):
    (tmp_path / "x.gcvf").write_text("no zip")
    with pytest.raises(PackageError, match=r"x.gcvf is no printer package inkopt reads \(png-slices, gcvf, 3mf\)$"):
        inspect_package(tmp_path / "x.gcvf")
    with zipfile.ZipFile(tmp_path / "y.zip", "w") as zf:
        zf.writestr("readme.txt", "no package")
    with pytest.raises(PackageError, match="no printer package"):
        inspect_package(tmp_path / "y.zip")
    # a zip named as a package: its checker names the part it lacks
    for name, part in (("y.gcvf", "ConfigFile.xml"), ("y.3mf", "3D/3dmodel.model")):
        (tmp_path / "y.zip").replace(tmp_path / name)
        with pytest.raises(PackageError, match=rf"/{name}: no {part} in the package \(a .* holds its .* there\)$"):
            inspect_package(tmp_path / name)
        (tmp_path / name).replace(tmp_path / "y.zip")
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


def with_member(src, dst, name: str, data=b"x"):
    """Copy the zip ``src`` to ``dst`` plus a member of the raw ``name`` (NUL bytes included: the name is written
    with a stand-in of the same length and patched in the file)."""
    stand_in = "".join("Q" if c == "\0" else c for c in name)
    rewrite(src, dst, lambda n, d: d)
    with zipfile.ZipFile(dst, "a") as zf:
        zf.writestr(stand_in, data)
    raw = dst.read_bytes()
    dst.write_bytes(raw.replace(stand_in.encode(), name.encode()))


UNSAFE = [
    ("../../evil.png", "has a '..' component"),
    ("layers/../../evil.png", "has a '..' component"),
    ("/etc/evil.png", "is an absolute path"),
    ("\\evil.png", "is an absolute path"),
    ("C:evil.png", "names a drive"),
    ("layers\\evil.png", "uses a backslash as a separator"),
    ("evil\x01.png", "holds a control character"),
    ("layer_0.png\0../../evil.png", "holds a control character"),
]


@pytest.mark.parametrize("kind", ["gcvf", "3mf"])
@pytest.mark.parametrize(("name", "problem"), UNSAFE)
def test_unsafe_member_names_are_refused(tmp_path, kind, name, problem):
    """A package a printer's software would unpack outside its folder is refused in one line naming the member,
    whatever else it holds (the parts agree otherwise)."""
    good = tmp_path / f"good.{kind}"
    FORMATS[kind].write(job(labels()), good)
    with_member(good, tmp_path / f"bad.{kind}", name)
    with pytest.raises(PackageError) as exc:
        inspect_package(tmp_path / f"bad.{kind}")
    assert str(exc.value) == (
        f"{tmp_path}/bad.{kind}: member {name!r} {problem}; a package must not unpack outside its folder"
    )


@pytest.mark.filterwarnings("ignore:Duplicate name")
@pytest.mark.parametrize("kind", ["gcvf", "3mf"])
def test_repeated_member_names_are_refused(tmp_path, kind):
    good = tmp_path / f"good.{kind}"
    FORMATS[kind].write(job(labels()), good)
    first = "layer_0.png" if kind == "gcvf" else "3D/3dmodel.model"
    for twin, also in ((first, ""), (first.upper(), f" \\(as '{first}'\\)")):
        with_member(good, tmp_path / f"bad.{kind}", twin)
        with pytest.raises(PackageError, match=rf"bad.{kind}: member '{twin}' appears twice{also}; a package names"):
            inspect_package(tmp_path / f"bad.{kind}")


def declare_size(path, member: str, size: int):
    """Patch the uncompressed size the zip's central directory declares for ``member``."""
    raw = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as zf:
        info, directory = zf.getinfo(member), zf.start_dir
    at = raw.index(info.orig_filename.encode(), directory) - 46  # its central directory record
    raw[at + 24 : at + 28] = size.to_bytes(4, "little")
    path.write_bytes(bytes(raw))


def test_a_huge_member_is_refused_naming_it_and_its_size(package, tmp_path):
    """A member declaring more bytes than its part can hold is refused before it is read (memory), in one line
    naming the member and its size."""
    _, path = package
    declare_size(path, "layer_2.png", 0xF0000000)
    with pytest.raises(
        PackageError, match=r"job.gcvf: layer_2.png is 3.8 GiB \(4026531840 bytes\) uncompressed, more "
    ):
        inspect_package(path)


def test_writers_refuse_names_that_break_their_xml():
    """Ink and material names end up in the packages' XML (and ink names in file names): control characters,
    separators and drives are refused when the job is made."""
    with pytest.raises(ValueError, match=r"^ink name 'cy\\x01an' holds a control character$"):
        job(labels(), ["cy\x01an", *INKS[1:]])
    with pytest.raises(ValueError, match=r"^ink name '../x' holds '/'"):
        job(labels(), ["../x", *INKS[1:]])
    with pytest.raises(ValueError, match=r"materials names 'Vero\\x02', a name with a control character"):
        job(labels(), materials={"cyan": "Vero\x02"})


def test_memory_running_out_names_the_member(package, monkeypatch):
    """A member too large for this machine's memory (a 4 GiB member under a 3 GB cap) names the member and its
    size, not "the volume"."""
    _, path = package

    def no_memory(self, name, pwd=None):
        raise MemoryError

    monkeypatch.setattr(zipfile.ZipFile, "read", no_memory)
    with pytest.raises(
        PackageError, match=r"job.gcvf: ConfigFile.xml \(\d+\.\d KiB \(\d+ bytes\) uncompressed\) does "
    ):
        inspect_package(path)


def test_slices_that_are_no_png_are_refused_before_their_declared_size_is_used(package, tmp_path):
    _, path = package
    huge = edit_config(b"<SliceWidth>14<", b"<SliceWidth>2000000000<")
    rewrite(path, tmp_path / "a.gcvf", lambda n, d: b"no png" if n == "layer_0.png" else huge(n, d))
    with pytest.raises(PackageError, match=r"a.gcvf: layer_0.png is not a PNG$"):
        inspect_package(tmp_path / "a.gcvf")
    rewrite(path, tmp_path / "b.gcvf", huge)
    with pytest.raises(PackageError, match=r"b.gcvf: layer_0.png is 14 x 10 px; the package declares 2000000000 x 10$"):
        inspect_package(tmp_path / "b.gcvf")


def test_a_broken_png_chunk_is_one_line(package, tmp_path):
    """A slice whose IDAT chunk declares the wrong length (the decoder raises SyntaxError, no OSError)."""
    _, path = package

    def shorten_idat(name, data):
        if name != "layer_1.png":
            return data
        at = data.index(b"IDAT") - 4
        return data[:at] + (4).to_bytes(4, "big") + data[at + 4 :]

    rewrite(path, tmp_path / "a.gcvf", shorten_idat)
    with pytest.raises(PackageError, match=r"a.gcvf: cannot read layer_1.png: broken PNG file"):
        inspect_package(tmp_path / "a.gcvf")
