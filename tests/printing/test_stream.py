"""Tests of the streaming printer output: inkopt.printing.stream (a run quantized layer by layer into
quantized.npz + quantized_labels.layers), model.labelfile (both label file forms), the pre-release layouts refused,
and GCVF's block outline."""

import io
import zipfile
import zlib

import numpy as np
import pytest
import trimesh

from inkopt.io import FormatError, file_digest, save_npz
from inkopt.model import InkTable, Quantization, Volume
from inkopt.model.labelfile import LabelFileWriter, LabelLayers, LabelLayersWriter, load_label_file
from inkopt.model.mixturefile import MixtureSource
from inkopt.printing.formats import gcvf, outline
from inkopt.printing.formats.job import LabelVoxels, PrintJob
from inkopt.printing.formats.png_slices import read_png_slices, write_png_slices
from inkopt.printing.quantize import quantize, quantize_volume
from inkopt.printing.stream import quantize_run
from inkopt.rundir import RunDir

V300 = 25.4 / 300
KW = dict(dpi=(600, 300), layer_um=27.0, seed=3)


def mixture_run(path, shape=(6, 9, 11), inside=True, normals=False):
    inks = InkTable.parse("vero-cmykw")
    rng = np.random.default_rng(1)
    mix = rng.dirichlet(np.ones(len(inks)), size=shape).astype(np.float32)
    kw = {}
    if inside:
        kw["inside"] = rng.random(shape) < 0.7
        mix[~kw["inside"]] = 0.0  # outside rows may be empty
    if normals:
        kw["normals"] = np.tile(np.array([0, 0, 1], np.float32), shape + (1,))
    vol = Volume.from_mixture(voxel_mm=(V300,) * 3, mixture=mix, inks=inks, origin_mm=(1.0, 2.0, 3.0), **kw)
    d = RunDir.create(path)
    d.save_volume(vol)
    return d, vol


@pytest.mark.parametrize(
    "method,upsample",
    [
        ("blue-noise", "nearest"),
        ("random", "linear"),
        ("error-diffusion", "linear"),
        ("error-diffusion", "nearest"),
        ("count-diffusion", "nearest"),
    ],
)
def test_streaming_run_equals_in_memory_quantization(tmp_path, method, upsample):
    d, vol = mixture_run(tmp_path / "r")
    lines = quantize_run(d, Quantization(method, upsample=upsample, **KW))
    expect = quantize_volume(vol, Quantization(method, upsample=upsample, **KW))
    raw = np.load(d.quantized_path)
    assert "labels" not in raw.files and str(raw["labels_file"]) == d.quantized_labels_path.name
    assert int(raw["format_version"]) == 1
    q = d.load_quantized()
    assert not d.dense_labels_path.exists() and isinstance(d.quantized_layers().labels, LabelLayers)
    np.testing.assert_array_equal(q.labels, expect.labels)
    np.testing.assert_array_equal(d.quantized_layers().labels[:], expect.labels)
    np.testing.assert_allclose(q.voxel_mm, expect.voxel_mm)
    np.testing.assert_allclose(q.origin_mm, vol.origin_mm)
    assert q.quantization == expect.quantization and q.inks.names == vol.inks.names
    counts = np.bincount(expect.labels.ravel(), minlength=256)
    np.testing.assert_array_equal(raw["label_counts"], counts)
    assert f"{counts[255]} empty" in lines[1]


def test_normals_stream_like_in_memory_and_the_same_files(tmp_path):
    d, vol = mixture_run(tmp_path / "m", normals=True)
    quantize_run(d, Quantization(**KW))
    q = d.load_quantized()
    expect = quantize_volume(vol, Quantization(**KW))
    assert q.normals is not None and q.normals.shape == q.shape and len(q.normals.index) > 0
    np.testing.assert_array_equal(q.normals.index, expect.normals.index)
    np.testing.assert_array_equal(q.normals.vectors, expect.normals.vectors)
    np.testing.assert_array_equal(q.labels, expect.labels)
    assert "labels" not in np.load(d.quantized_path).files
    # a volume file of the pre-release layout (dense normals, no format_version) is refused in one line
    old = vol.to_arrays()
    dense = vol.normals.dense()
    del old["normal_index"], old["normal_vectors"], old["format_version"]
    save_npz(d.volume_file(), {**old, "normals": dense})
    with pytest.raises(FormatError, match="dense shading normals, a pre-release layout") as e:
        MixtureSource(d.volume_file())
    assert "\n" not in str(e.value)
    np.savez(d.volume_file(), **{**vol.to_arrays(), "format_version": np.int64(2)})  # a newer inkopt's file
    with pytest.raises(FormatError, match="format version 2; this inkopt reads versions up to 1"):
        MixtureSource(d.volume_file())


def test_mixture_source_reads_layers_in_any_order(tmp_path):
    d, vol = mixture_run(tmp_path / "r")
    src = MixtureSource(d.volume_file())
    assert src.shape == vol.mixture.shape and src.normals is None
    np.testing.assert_array_equal(src.inside, vol.inside.dense())
    for z in (0, 3, 3, 2, 5, 1, 0, 4):
        np.testing.assert_array_equal(src[z], vol.mixture[z])
    src.close()
    vol.with_medium(quantize_volume(vol).medium, inside=None).save(tmp_path / "labels.npz")
    with pytest.raises(ValueError, match="needs a mixture volume"):
        MixtureSource(tmp_path / "labels.npz")


def test_bad_layer_is_refused_and_leaves_no_file(tmp_path):
    d, vol = mixture_run(tmp_path / "r", inside=False)
    bad = vol.mixture.copy()
    bad[4, 2, 3] = 0.0
    vol.with_mixture(bad).save(d.volume_path)
    with pytest.raises(ValueError, match="positive sum"):
        quantize_run(d, Quantization(**KW))
    assert not d.has_quantized() and sorted(p.name for p in d.path.iterdir()) == ["volume.npz"]


def test_quantized_files_of_each_version(tmp_path):
    """Today's quantized.npz without format_version (version 0) loads; the pre-release layout with the labels
    inside is refused in one line that says to quantize again; a file written now carries version 1."""
    d, vol = mixture_run(tmp_path / "r")
    q = quantize_volume(vol, Quantization(**KW))
    d.save_quantized(q)
    assert int(np.load(d.quantized_path)["format_version"]) == 1
    np.testing.assert_array_equal(Volume.load(d.quantized_path).labels, q.labels)
    v0 = {k: v for k, v in np.load(d.quantized_path).items() if k != "format_version"}
    save_npz(d.quantized_path, v0)
    np.testing.assert_array_equal(d.load_quantized().labels, q.labels)
    arrays = {k: v for k, v in q.to_arrays().items() if k != "format_version"}
    save_npz(d.quantized_path, arrays)  # labels inside the npz, no format_version: the pre-release layout
    with pytest.raises(FormatError, match=f"holds its labels inside .*run 'inkopt quantize {d.path}' again") as e:
        d.load_quantized()
    assert "\n" not in str(e.value)
    d.save_quantized(q)
    d.quantized_labels_path.unlink()
    with pytest.raises(ValueError, match="does not exist"):
        d.load_quantized()


@pytest.mark.parametrize("writer,name", [(LabelFileWriter, "l.npy"), (LabelLayersWriter, "l.layers")])
def test_label_file_writer(tmp_path, writer, name):
    lab = np.random.default_rng(0).integers(0, 6, (3, 4, 5), dtype=np.uint8)
    w = writer(tmp_path / name, lab.shape)
    with pytest.raises(ValueError, match="in order"):
        w[1] = lab[1]
    w[0] = lab[0]
    with pytest.raises(ValueError, match="incomplete"):
        w.commit()
    assert list(tmp_path.iterdir()) == []
    w = writer(tmp_path / name, lab.shape)
    for k in range(3):
        w[k] = lab[k]
    w.commit()
    assert w.digest == file_digest(tmp_path / name)
    np.testing.assert_array_equal(load_label_file(tmp_path / name, lab.shape), lab)
    np.testing.assert_array_equal(w.counts, np.bincount(lab.ravel(), minlength=256))
    with pytest.raises(ValueError, match="expected uint8|expected \\(3, 4, 6\\)"):
        load_label_file(tmp_path / name, (3, 4, 6))


def test_label_layers_read_layers_slices_and_refuse_damage(tmp_path):
    """A version-2 file gives each layer, slices of layers and the whole stack as written; a file cut short, one
    with a damaged layer or index, and one that is no label file are one-line ValueErrors."""
    rng = np.random.default_rng(2)
    lab = np.full((9, 12, 17), 255, np.uint8)
    lab[2:8, 2:10, 3:15] = 4  # a homogeneous core
    lab[2:8, 2:4, 3:15] = rng.integers(0, 5, (6, 2, 12))  # a dithered band
    w = LabelLayersWriter(tmp_path / "a.layers", lab.shape)
    for k in range(lab.shape[0]):
        w[k] = lab[k]
    w.commit()
    src = load_label_file(tmp_path / "a.layers", lab.shape, layered=True)
    assert isinstance(src, LabelLayers) and src.shape == lab.shape and len(src) == 9
    for k in (0, 3, 3, 8, -1, 5):
        np.testing.assert_array_equal(src[k], lab[k])
    np.testing.assert_array_equal(src[2:7:2], lab[2:7:2])
    np.testing.assert_array_equal(src[4, 2, 3:9], lab[4, 2, 3:9])
    dense = load_label_file(tmp_path / "a.layers")
    np.testing.assert_array_equal(dense, lab)
    assert not dense.flags.writeable and not src[1].flags.writeable
    with pytest.raises(IndexError):
        src[9]
    data = (tmp_path / "a.layers").read_bytes()
    cases = {
        "cut": (data[:-20], "its end is missing"),
        "index": (data[: -16 - 10 * 8] + b"\xff" * 8 + data[-16 - 9 * 8 :], "its index is damaged"),
        "header": (data[:22] + b"{" + data[23:], "header is damaged"),
        "other": (b"\x93NUMPY" + data[7:], "does not start as one"),
    }
    for name, (bad, what) in cases.items():
        (tmp_path / name).write_bytes(bad)
        with pytest.raises(ValueError, match=what) as e:
            LabelLayers(tmp_path / name)
        assert "\n" not in str(e.value)
    start = int(src.offsets[3])
    (tmp_path / "layer").write_bytes(data[:start] + bytes(4) + data[start + 4 :])
    with pytest.raises(ValueError, match="layer 3 is damaged") as e:
        LabelLayers(tmp_path / "layer")[3]
    assert "\n" not in str(e.value)

    class OneByteTooMany(LabelLayersWriter):  # layer 3 inflates to one byte more than a layer holds
        def _layer(self, lay):
            self.offsets.append(self.written)
            self._write(zlib.compress(lay.tobytes() + bytes(len(self.offsets) == 4), 1))

    w = OneByteTooMany(tmp_path / "long", lab.shape)
    for k in range(lab.shape[0]):
        w[k] = lab[k]
    w.commit()
    np.testing.assert_array_equal(LabelLayers(tmp_path / "long")[2], lab[2])
    with pytest.raises(ValueError, match="layer 3 is damaged .it does not inflate to 204 bytes"):
        LabelLayers(tmp_path / "long")[3]


def test_label_layers_read_the_file_they_opened(tmp_path):
    """Label layers opened before their file is rewritten under the same name (an atomic rewrite, as a second
    ``inkopt quantize`` does) or removed read every layer of the file they opened, never the new one's; pickled,
    they open the path again and refuse a file that changed; closed, a read is a one-line ValueError."""
    import pickle

    def write(path, lab):
        w = LabelLayersWriter(path, lab.shape)
        for k in range(lab.shape[0]):
            w[k] = lab[k]
        w.commit()

    rng = np.random.default_rng(3)
    old, new = (rng.integers(0, 5, (6, 8, 9), dtype=np.uint8) for _ in range(2))
    path = tmp_path / "labels.layers"
    write(path, old)
    src = LabelLayers(path)
    np.testing.assert_array_equal(src[0], old[0])
    again = pickle.loads(pickle.dumps(src))  # the same file, opened again
    np.testing.assert_array_equal(again[:], old)
    write(path, new)  # replaced by rename: the layers opened before still read the old file
    np.testing.assert_array_equal(src[1:], old[1:])
    with pytest.raises(ValueError, match="changed since"):
        pickle.loads(pickle.dumps(src))
    path.unlink()
    np.testing.assert_array_equal(again[:], old)
    src.close()
    with pytest.raises(ValueError, match="closed") as e:
        src[5]
    assert "\n" not in str(e.value)


def test_both_label_file_forms_export_the_same_packages(tmp_path):
    """A run quantized now (quantized_labels.layers) and the same labels in the version-1 file an older inkopt
    wrote (quantized_labels.npy, read memory-mapped) load to the same labels and give byte-identical GCVF members
    and PNG slices; writing one form removes the other."""
    d, vol = mixture_run(tmp_path / "new")
    quantize_run(d, Quantization(**KW))
    q = d.load_quantized()
    old = RunDir.create(tmp_path / "old")
    old.save_volume(vol)
    with old.quantized_writer(q, q.shape, dense=True) as w:
        for k in range(q.shape[0]):
            w[k] = q.labels[k]
    assert old.dense_labels_path.is_file() and not old.quantized_labels_path.exists()
    assert isinstance(old.quantized_layers().labels, np.memmap)
    np.testing.assert_array_equal(old.load_quantized().labels, q.labels)
    members = {}
    for run in (d, old):
        lq = run.quantized_layers()
        job = PrintJob(LabelVoxels(lq.labels, lq.voxel_mm, lq.inks.names))
        gcvf.write_gcvf(job, run.path / "j.gcvf")
        write_png_slices(job, run.path / "s")
        with zipfile.ZipFile(run.path / "j.gcvf") as zf:
            members[run] = {n: zf.read(n) for n in zf.namelist()}
        members[run]["slices"] = {p.name: p.read_bytes() for p in (run.path / "s").glob("*.png")}
    assert members[d] == members[old] and len(members[d]["slices"]) == q.shape[0]
    with old.quantized_writer(q, q.shape) as w:  # quantized again now: the version-1 file goes
        for k in range(q.shape[0]):
            w[k] = q.labels[k]
    assert old.quantized_labels_path.is_file() and not old.dense_labels_path.exists()


def test_export_from_a_label_layers_file(tmp_path):
    d, vol = mixture_run(tmp_path / "r")
    quantize_run(d, Quantization(**KW))
    q = d.quantized_layers()
    write_png_slices(PrintJob(LabelVoxels(q.labels, q.voxel_mm, q.inks.names)), tmp_path / "s")
    np.testing.assert_array_equal(read_png_slices(tmp_path / "s")[0], q.labels)


def test_gcvf_block_outline_encloses_every_voxel(tmp_path, monkeypatch):
    z, y, x = np.indices((30, 20, 40))
    lab = np.where((x - 20) ** 2 / 300 + (y - 10) ** 2 / 80 + (z - 15) ** 2 / 200 < 1, 1, 255).astype(np.uint8)
    vp = np.array([25.4 / 600, 25.4 / 300, 0.027])
    monkeypatch.setattr(outline, "OUTLINE_MAX_CELLS", 2000)
    f = outline.outline_factors(lab.shape, vp, 2000)
    assert np.prod(-(-np.array(lab.shape) // f)) <= 2000 and max(f) > 1
    summary = gcvf.write_gcvf(PrintJob(LabelVoxels(lab, vp, ["cyan", "white"])), tmp_path / "j.gcvf")
    assert summary["outline_block"] == [f[2], f[1], f[0]]
    with zipfile.ZipFile(tmp_path / "j.gcvf") as zf:
        mesh = trimesh.load(io.BytesIO(zf.read(gcvf.STL)), file_type="stl")
    assert mesh.is_watertight
    occ = np.argwhere(lab != 255)  # (z, y, x): every printed voxel's box lies inside the outline's box
    shift = np.array([0.0, -lab.shape[1] * vp[1], 0.0])  # the STL's y = -image row x pitch
    lo, hi = occ.min(0)[::-1] * vp + shift, (occ.max(0)[::-1] + 1) * vp + shift
    assert np.all(mesh.bounds[0] <= lo + 1e-6) and np.all(mesh.bounds[1] >= hi - 1e-6)  # float32 STL
    block = np.array(f[::-1]) * vp  # (x, y, z) mm: the outline lies within two blocks of the voxels
    assert np.all(mesh.bounds[0] >= lo - 2 * block - 1e-6) and np.all(mesh.bounds[1] <= hi + 2 * block + 1e-6)
    centres = (occ[:, ::-1] + 0.5) * vp + shift
    assert mesh.contains(centres).all()


def test_quantization_metadata_roundtrip(tmp_path):
    d, vol = mixture_run(tmp_path / "r")
    q = quantize_volume(vol, Quantization("random", 9, (600, 300), layer_um=27.0))
    d.save_quantized(q)
    assert d.load_quantized().quantization == Quantization("random", 9, q.quantization.dpi, "nearest", "index")
    lab, _ = quantize(vol, Quantization("random", 9, (600, 300)))
    np.testing.assert_array_equal(d.load_quantized().labels, lab)


def test_quantization_record_says_the_ink_order():
    """The labels file records the inks' order of blue-noise dithering; a file that does not say (written before the
    order was recorded) was dithered in index order, and the evaluation's baselines then follow it."""
    for order in ("lightness", "index"):
        q = Quantization("blue-noise", 3, (600.0, 300.0, 940.7), "nearest", order)
        assert Quantization.from_arrays(q.arrays()) == q
    older = {k: v for k, v in Quantization().arrays().items() if k != "ink_order"}
    assert Quantization.from_arrays(older).ink_order == "index"
