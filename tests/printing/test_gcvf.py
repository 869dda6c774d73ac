"""Tests of inkopt.printing.formats.gcvf: the GrabCAD Voxel Print package opened as a zip, its XML parsed, its slices
decoded through the XML palette, its STL loaded with trimesh and its z-buffer checked against the labels."""

import io
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
import trimesh
from PIL import Image

from inkopt.io import read_source_comment
from inkopt.printing.formats.gcvf import STL_RECORD, write_gcvf
from inkopt.printing.formats.job import LabelVoxels, PrintJob, Provenance
from inkopt.printing.formats.outline import outline_mesh
from inkopt.printing.profiles import printer_profile

VP = np.array([25.4 / 600, 25.4 / 300, 0.027])
INKS = ["cyan", "magenta", "yellow", "black", "white", "orange"]


def job(labels, inks=INKS, printer="j750", voxel_mm=VP, **kw) -> PrintJob:
    """A label job for ``printer`` (a profile key; J750, the command line's default for GCVF)."""
    return PrintJob(LabelVoxels(labels, voxel_mm, inks), printer_profile(printer), **kw)


def ball_labels(shape=(9, 12, 20), n=6, seed=0):
    """Random inks inside an off-centre ellipsoid (in mm, so it is round on the 2:1 grid), 255 outside."""
    z, y, x = (np.indices(shape) + 0.5) * VP[::-1, None, None, None]
    inside = ((x - 0.45) / 0.35) ** 2 + ((y - 0.5) / 0.4) ** 2 + ((z - 0.12) / 0.1) ** 2 < 1
    lab = np.random.default_rng(seed).integers(0, n, shape).astype(np.uint8)
    lab[~inside] = 255
    return lab


def read_package(path):
    with zipfile.ZipFile(path) as zf:
        return {name: zf.read(name) for name in zf.namelist()}


def text(el, tag):
    return el.find(tag).text


def test_package_structure_and_palette(tmp_path):
    lab = ball_labels()
    Z, Y, X = lab.shape
    summary = write_gcvf(job(lab), tmp_path / "job.gcvf")
    files = read_package(tmp_path / "job.gcvf")
    assert sorted(files) == sorted(
        [f"layer_{k}.png" for k in range(Z)] + ["ConfigFile.xml", "Mesh.stl", "Zbuffer.png", "MeshBbx.ktn"]
    )
    assert files["ConfigFile.xml"].startswith(b'<?xml version="1.0" encoding="UTF-8"?>')
    root = ET.fromstring(files["ConfigFile.xml"])
    assert root.tag == "GCVF" and text(root, "Version") == "2"
    res = root.find("Resolution")
    assert (text(res, "XDpi"), text(res, "YDpi"), text(res, "SliceThicknessNanoMeter")) == ("600", "300", "27000")
    assert (text(root, "SliceDimensions/SliceWidth"), text(root, "SliceDimensions/SliceHeight")) == (str(X), str(Y))
    assert (text(root, "SliceRange/StartIndex"), text(root, "SliceRange/NumberOfSlices")) == ("0", str(Z))
    assert text(root, "ImageFilePrefix") == "layer_" and text(root, "DataSemantics") == "Materials"
    assert text(root, "MaxNumberOfColors") == "6" and text(root, "CreationMode") == "MODEL_ONLY"
    assert text(root, "MaterialList/BackGroundMaterialRGBA") == "0 0 0 255"
    mats = root.findall("MaterialList/Material")
    assert [text(m, "Name") for m in mats] == [
        "VeroCY-V",
        "VeroMGT-V",
        "VeroYL-V",
        "VeroBlack",
        "VUltraWhite",
        "orange",
    ]
    palette = {tuple(int(v) for v in text(m, "RGBA").split()): i for i, m in enumerate(mats)}
    palette[(0, 0, 0, 255)] = 255
    assert len(palette) == len(INKS) + 1, "every ink has its own colour, none is the background"
    assert [int(text(m, "VoxelCount")) for m in mats] == [int(np.sum(lab == i)) for i in range(len(INKS))]
    for k in range(Z):
        with Image.open(io.BytesIO(files[f"layer_{k}.png"])) as im:
            assert im.mode == "RGBA" and im.size == (X, Y)
            assert im.info["dpi"] == pytest.approx((600, 300), abs=0.01)
            rgba = np.asarray(im).reshape(-1, 4)
        decoded = np.array([palette[tuple(int(v) for v in px)] for px in rgba], np.uint8).reshape(Y, X)
        np.testing.assert_array_equal(decoded, lab[k, ::-1, :])  # row 0 = largest y, as the PNG slices
    assert summary["layer_count"] == Z and [m["material"] for m in summary["materials"]][-1] is None
    assert not [p.name for p in tmp_path.iterdir() if p.name != "job.gcvf"], "no temporary left"


def test_stl_outline_matches_the_voxels(tmp_path):
    lab = ball_labels()
    write_gcvf(job(lab), tmp_path / "job.gcvf")
    stl = read_package(tmp_path / "job.gcvf")["Mesh.stl"]
    mesh = trimesh.load(io.BytesIO(stl), file_type="stl")
    assert mesh.is_watertight and mesh.volume > 0, "outward normals"
    assert stl.startswith(b"inkopt outline block 1 1 1 ")
    stored = np.frombuffer(stl[84:], STL_RECORD)["normal"]
    np.testing.assert_allclose(stored, mesh.face_normals, atol=1e-5)  # stored normals = winding normals
    occ = lab != 255
    idx = np.argwhere(occ)[:, ::-1]  # (x, y, z) voxel indices, y = label row
    lo, hi = idx.min(0) * VP, (idx.max(0) + 1) * VP  # outer faces of the outermost voxels, mm
    Y = lab.shape[1]
    lo[1], hi[1] = (idx[:, 1].min() - Y) * VP[1], (idx[:, 1].max() + 1 - Y) * VP[1]  # y = -image row x pitch
    np.testing.assert_allclose(mesh.bounds, [lo, hi], atol=1e-5)  # marching cubes at 0.5: on the voxel faces
    assert abs(mesh.volume / (occ.sum() * VP.prod()) - 1) < 0.1
    box = outline_mesh(np.ones((2, 3, 4), bool), VP)  # a box: exactly the voxels' extent
    np.testing.assert_allclose(box.bounds, [[0, 0, 0], [4 * VP[0], 3 * VP[1], 2 * VP[2]]], atol=1e-6)


def test_zbuffer_is_the_top_layer_seen_from_above(tmp_path):
    lab = ball_labels()
    write_gcvf(job(lab), tmp_path / "job.gcvf")
    with Image.open(io.BytesIO(read_package(tmp_path / "job.gcvf")["Zbuffer.png"])) as im:
        assert im.mode == "I;16" and "dpi" not in im.info
        zb = np.asarray(im).astype(int)
    occ = lab != 255
    want = np.zeros(occ.shape[1:], int)
    for k in range(occ.shape[0]):
        want[occ[k]] = k
    assert zb.shape == occ.shape[1:]
    np.testing.assert_array_equal(zb, want[::-1, :])


def test_parts_match_the_builders_packages(tmp_path):
    """The two jobs whose Mesh.stl, Zbuffer.png and MeshBbx.ktn a public GCVF builder ships (gcvf.py's docstring):
    a 200 x 100 px, 100-layer job filled everywhere and a 1000 x 500 px job occupying columns 2-999 and rows
    1-499 (four layers here: the box's z only follows the layer count)."""
    full = np.zeros((100, 100, 200), np.uint8)
    write_gcvf(job(full), tmp_path / "full.gcvf")
    files = read_package(tmp_path / "full.gcvf")
    assert len(files["MeshBbx.ktn"]) == 24
    assert np.frombuffer(files["MeshBbx.ktn"], "<f4").tolist() == [0, 0, 0, 200, 100, 100]
    with Image.open(io.BytesIO(files["Zbuffer.png"])) as im:
        assert np.unique(np.asarray(im)).tolist() == [99]
    mesh = trimesh.load(io.BytesIO(files["Mesh.stl"]), file_type="stl")
    np.testing.assert_allclose(mesh.bounds, [[0, -100 * 25.4 / 300, 0], [200 * 25.4 / 600, 0, 2.7]], atol=1e-5)
    wheel = np.full((4, 500, 1000), 255, np.uint8)
    wheel[:, 1:500, 2:1000] = 4  # label rows 1..499 = image rows 0..498: the image's top row stays empty below
    wheel = wheel[:, ::-1, :].copy()  # image rows 1..499 occupied
    write_gcvf(job(wheel), tmp_path / "wheel.gcvf")
    assert np.frombuffer(read_package(tmp_path / "wheel.gcvf")["MeshBbx.ktn"], "<f4").tolist() == [
        2,
        1,
        0,
        1000,
        500,
        4,
    ]


def test_material_names_and_source_digest(tmp_path):
    lab = ball_labels()
    write_gcvf(
        job(lab, materials={"White": "VeroPureWht"}, provenance=Provenance(digest="sha256:0f")), tmp_path / "job.gcvf"
    )
    root = ET.fromstring(read_package(tmp_path / "job.gcvf")["ConfigFile.xml"])
    assert [text(m, "Name") for m in root.findall("MaterialList/Material")][4] == "VeroPureWht"
    with zipfile.ZipFile(tmp_path / "job.gcvf") as zf:
        assert read_source_comment(zf.comment)["digest"] == "sha256:0f"
    with pytest.raises(ValueError, match="unknown ink 'teal'"):
        job(lab, materials={"teal": "VeroCY-V"})


def test_refusals_write_nothing(tmp_path):
    seven = INKS + ["transparent"]
    lab = np.arange(7, dtype=np.uint8).reshape(1, 1, 7)
    with pytest.raises(ValueError, match=r"uses 7 inks \(cyan, .*, transparent\) but Stratasys J750 holds 6") as e:
        write_gcvf(job(lab, seven), tmp_path / "a.gcvf")
    assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match="whole-number DPI"):
        write_gcvf(job(lab[..., :3], voxel_mm=(0.045, 0.09, 0.027)), tmp_path / "b.gcvf")
    with pytest.raises(ValueError, match="nothing to print"):
        write_gcvf(job(np.full((2, 2, 2), 255, np.uint8)), tmp_path / "c.gcvf")
    (tmp_path / "notes.gcvf").write_text("precious")
    with pytest.raises(ValueError, match="not a GCVF package"):
        write_gcvf(job(lab[..., :3]), tmp_path / "notes.gcvf")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.gcvf"]
    # seven inks fit a J850; the XML keeps the profile's MaxNumberOfColors, the clear ink its Vero material
    write_gcvf(job(lab, seven, "j850"), tmp_path / "j850.gcvf")
    root = ET.fromstring(read_package(tmp_path / "j850.gcvf")["ConfigFile.xml"])
    assert text(root, "MaxNumberOfColors") == "6"
    assert [text(m, "Name") for m in root.findall("MaterialList/Material")][-2:] == ["orange", "VeroClear"]
    write_gcvf(job(lab[..., :2], seven, "j850"), tmp_path / "j850.gcvf")  # an old package is replaced
    assert (
        text(ET.fromstring(read_package(tmp_path / "j850.gcvf")["ConfigFile.xml"]), "SliceDimensions/SliceWidth") == "2"
    )
