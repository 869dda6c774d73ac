"""Tests of inkopt.printing.formats.threemf: the volumetric elements validated against the 3MF Volumetric
extension's XSD (tests/printing/data), the file opened by lib3mf 2.5.0, the sheets sampled as the spec says (UVW of
a voxel centre -> row, column, sheet) and read back by its checker."""

import io
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import lib3mf
import numpy as np
import pytest
import trimesh
import xmlschema
from PIL import Image

from inkopt.model import InkTable, Volume
from inkopt.model.mixturefile import MixtureSource
from inkopt.printing.formats import inspect_package, outline
from inkopt.printing.formats.job import LabelVoxels, MixtureVoxels, PrintJob, Provenance
from inkopt.printing.formats.threemf import write_3mf
from inkopt.printing.formats.threemf_xml import CHANNELS, MODEL, NS_CORE, NS_V
from inkopt.printing.profiles import printer_profile

VP = np.array([25.4 / 600, 25.4 / 300, 0.027])
INKS = ["cyan", "magenta", "yellow", "black", "white", "orange"]
XSD = Path(__file__).parent / "data" / "volumetric.xsd"


def job(labels, printer=None, **kw) -> PrintJob:
    """A label job; ``printer`` a profile key."""
    return PrintJob(LabelVoxels(labels, VP, INKS), None if printer is None else printer_profile(printer), **kw)


def labels(shape=(5, 8, 12), seed=0):
    lab = np.random.default_rng(seed).integers(0, len(INKS), shape).astype(np.uint8)
    lab[:, :2] = 255
    lab[0, :, :3] = 255
    return lab


def model(path):
    with zipfile.ZipFile(path) as zf:
        return ET.fromstring(zf.read(MODEL)), {n: zf.read(n) for n in zf.namelist() if n.endswith(".png")}


def test_volumetric_elements_validate_against_the_spec_schema(tmp_path):
    write_3mf(job(labels(), "j750"), tmp_path / "a.3mf")
    root, _ = model(tmp_path / "a.3mf")
    schema = xmlschema.XMLSchema(XSD)
    top = [el for el in root.find("{*}resources") if el.tag.startswith(f"{{{NS_V}}}")]
    assert [el.tag.split("}")[1] for el in top] == ["image3d", "functionfromimage3d"] * 2 + ["volumedata"]
    for el in top:
        schema.validate(el)
    mesh = root.find("{*}resources/{*}object/{*}mesh")
    assert mesh.get(f"{{{NS_V}}}volumeid") == top[-1].get("id")
    bad = ET.fromstring(ET.tostring(top[-1]))
    bad.find(f"{{{NS_V}}}composite").set("basematerialid", "zero")
    with pytest.raises(xmlschema.XMLSchemaValidationError):  # the schema does check what we write
        schema.validate(bad)


def test_lib3mf_reads_the_file(tmp_path):
    lab = labels()
    s = write_3mf(job(lab, "j750"), tmp_path / "a.3mf")
    m = lib3mf.get_wrapper().CreateModel()
    m.QueryReader("3mf").ReadFromFile(str(tmp_path / "a.3mf"))
    it = m.GetMeshObjects()
    assert it.MoveNext()
    obj = it.GetCurrentMeshObject()
    assert obj.GetTriangleCount() == s["mesh_triangles"] and obj.GetVolumeData() is not None
    stacks = m.GetImage3Ds()
    sizes = []
    while stacks.MoveNext():
        st = m.GetImageStackByID(stacks.GetCurrentImage3D().GetModelResourceID())
        sizes.append((st.GetRowCount(), st.GetColumnCount(), st.GetSheetCount()))
    assert sizes == [lab.shape[1:] + lab.shape[:1]] * 2
    groups = m.GetBaseMaterialGroups()
    assert groups.MoveNext() and groups.GetCurrentBaseMaterialGroup().GetCount() == len(INKS)


def test_sheets_sampled_at_voxel_centres_give_the_voxels_ink(tmp_path):
    """The spec's sampling (UVW = transform x object position; column = floor(u X), row 0 at v = 1, sheet =
    floor(w Z)) at every printed voxel's centre finds that voxel's ink, 255 in its channel and 0 elsewhere."""
    lab = labels()
    Z, Y, X = lab.shape
    write_3mf(job(lab), tmp_path / "a.3mf")
    root, pngs = model(tmp_path / "a.3mf")
    res = root.find("{*}resources")
    sheets = {
        f.get("id"): [s.get("path") for s in res.find(f"{{*}}image3d[@id='{f.get('image3did')}']/{{*}}imagestack")]
        for f in res.findall("{*}functionfromimage3d")
    }
    for f in res.findall("{*}functionfromimage3d"):
        assert (f.get("filter"), f.get("tilestyleu")) == ("nearest", "clamp")
    maps = res.findall("{*}volumedata/{*}composite/{*}materialmapping")
    assert len(maps) == len(INKS)
    z, y, x = np.nonzero(lab != 255)
    centre = np.stack([(x + 0.5) * VP[0], (y + 0.5) * VP[1], (z + 0.5) * VP[2], np.ones(len(x))], 1)
    for i, mp in enumerate(maps):
        t = np.array([float(v) for v in mp.get("transform").split()]).reshape(4, 3)
        u, v, w = (centre @ t).T
        col, row, sh = np.floor(u * X).astype(int), np.floor((1 - v) * Y).astype(int), np.floor(w * Z).astype(int)
        got = np.array(
            [
                np.asarray(Image.open(io.BytesIO(pngs[sheets[mp.get("functionid")][k][1:]])))[
                    r, c, CHANNELS.index(mp.get("channel"))
                ]
                for k, r, c in zip(sh, row, col, strict=True)
            ]
        )
        np.testing.assert_array_equal(got, np.where(lab[z, y, x] == i, 255, 0))


def test_labels_round_trip_and_block_outline(tmp_path, monkeypatch):
    lab = labels()
    s = write_3mf(job(lab, provenance=Provenance(digest="sha256:ab")), tmp_path / "a.3mf")
    rep, scan = inspect_package(tmp_path / "a.3mf", labels=True)
    np.testing.assert_array_equal(scan.labels, lab)
    assert [m["voxel_count"] for m in rep.materials] == [np.sum(lab == i) for i in range(len(INKS))]
    assert rep.dpi == pytest.approx((600, 300)) and rep.layer_um == pytest.approx(27)
    assert rep.source == {"source": None, "digest": "sha256:ab"} and s["outline_block"] == [1, 1, 1]
    # a block outline: the mesh encloses every printed voxel, and every voxel centre inside it has shares
    monkeypatch.setattr(outline, "OUTLINE_MAX_CELLS", 40)
    s = write_3mf(job(lab), tmp_path / "b.3mf")
    assert s["outline_block"] != [1, 1, 1]
    root, pngs = model(tmp_path / "b.3mf")
    verts = [[float(v.get(a)) for a in "xyz"] for v in root.iter(f"{{{NS_CORE}}}vertex")]
    tris = [[int(t.get(a)) for a in ("v1", "v2", "v3")] for t in root.iter(f"{{{NS_CORE}}}triangle")]
    mesh = trimesh.Trimesh(verts, tris, process=True)
    assert mesh.is_watertight and mesh.volume > 0
    Z, Y, X = lab.shape
    centres = (np.indices(lab.shape).reshape(3, -1).T[:, ::-1] + 0.5) * VP
    inside = mesh.contains(centres).reshape(lab.shape)
    assert inside[lab != 255].all()
    total = np.zeros(lab.shape)
    for k in range(Z):
        for g in range(2):
            total[k] += np.asarray(Image.open(io.BytesIO(pngs[f"3D/volumetric/inks{g}/sheet{k:05d}.png"])))[::-1].sum(2)
    assert (total[inside] > 0).all()
    assert (total[lab != 255] == 255).all()


def test_mixture_round_trip(tmp_path):
    inks = InkTable.parse("vero-cmykw")
    rng = np.random.default_rng(1)
    mix = rng.dirichlet(np.ones(len(inks)), size=(3, 6, 7)).astype(np.float32)
    inside = np.ones((3, 6, 7), bool)
    inside[:, 0] = False
    vol = Volume.from_mixture(voxel_mm=[25.4 / 300] * 3, mixture=mix, inks=inks, inside=inside)
    vol.save(tmp_path / "volume.npz")
    with MixtureSource(tmp_path / "volume.npz") as src:
        s = write_3mf(PrintJob(MixtureVoxels(src), materials={"white": "VeroPureWht"}), tmp_path / "m.3mf")
        with pytest.raises(ValueError, match="uses 5 inks"):  # a mixture loads every ink of the table
            write_3mf(PrintJob(MixtureVoxels(src), printer_profile("generic"), max_materials=4), tmp_path / "n.3mf")
    assert s["image_stacks"] == 2 and s["materials"][4]["material"] == "VeroPureWht" and s["content"] == "mixture"
    assert not (tmp_path / "n.3mf").exists()
    rep, _ = inspect_package(tmp_path / "m.3mf")
    assert [m["name"] for m in rep.materials] == ["cyan", "magenta", "yellow", "black", "VeroPureWht"]
    want = mix[inside].sum(0)
    got = np.array([m["voxel_count"] for m in rep.materials])
    assert np.abs(got - want).max() <= inside.sum() * 0.5 / 255  # each share rounded to 1/255
    assert rep.bounding_box == [0, 0, 0, 7, 5, 3]  # label row 0 (image row 5) is outside


def test_inspect_finds_shares_that_do_not_sum_to_one(tmp_path):
    lab = labels()
    write_3mf(job(lab), tmp_path / "a.3mf")
    name = "3D/volumetric/inks1/sheet00002.png"
    with zipfile.ZipFile(tmp_path / "a.3mf") as zi, zipfile.ZipFile(tmp_path / "b.3mf", "w") as zo:
        for n in zi.namelist():
            data = zi.read(n)
            if n == name:
                rgba = np.asarray(Image.open(io.BytesIO(data))).copy()
                rgba[0, 0, 1] = 200  # a second ink in a voxel that is already wholly one ink
                buf = io.BytesIO()
                Image.fromarray(rgba).save(buf, format="PNG")
                data = buf.getvalue()
            zo.writestr(n, data)
    with pytest.raises(ValueError, match=r"\.3mf: sheet 2: the shares at \(row 0, column 0\) sum to 1.78\d*, not 1$"):
        inspect_package(tmp_path / "b.3mf")
