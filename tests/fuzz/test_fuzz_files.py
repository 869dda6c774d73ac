"""Fuzzing the files inkopt reads (hypothesis): ink files (JSON, TOML), a run's .npz files (volume.npz through
``Volume.load`` and ``MixtureSource``, scene.npz, quantized.npz with its labels file, checkpoint.npz) and printer
packages (GCVF, 3MF: ``inspect_package``), each mutated from a small valid file: truncated, bytes flipped, keys or
members dropped, added, retyped or reshaped, values made non-finite, XML values and member names replaced,
declared sizes made huge.

The property everywhere: reading gives a correct result or one clean error, a ValueError or OSError (what the
command line prints as one ``inkopt: error: ...`` line, exit 2) whose message is one line naming the file; never
another exception. The examples are derandomized (the same every run); ``INKOPT_FUZZ_EXAMPLES=N`` runs N random
examples per property instead.
"""

import io
import json
import warnings
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from helpers import fuzz
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from PIL import Image

from inkopt.model import InkTable, Texels, Volume
from inkopt.model.mixturefile import MixtureSource
from inkopt.model.normals import SurfaceNormals
from inkopt.printing.formats import FORMATS, inspect_package
from inkopt.printing.formats.job import LabelVoxels, PrintJob
from inkopt.printing.profiles import printer_profile
from inkopt.rundir import RunDir, SceneRecord

INKS = InkTable.parse("vero-cmykw")


def clean(read, path, *args, named=()):
    """``read(path, *args)``: its result, or the clean error it raised (a ValueError or OSError whose message is
    one line naming the file, or one of the files ``named``); any other exception fails the property."""
    try:
        return read(path, *args)
    except (ValueError, OSError) as exc:
        msg = str(exc)
        assert msg and "\n" not in msg, repr(msg)
        assert any(Path(p).name in msg for p in (path, *named)), msg
        return exc


# ------------------------------------------------------------------------------------------- mutations
class Short(tuple):
    """A strategy's argument (a file's bytes, a package's members) shown short in hypothesis's reports."""

    def __repr__(self) -> str:
        return f"<{len(self)} items>"


@st.composite
def damaged(draw, data: bytes) -> bytes:
    """``data`` truncated, or with 1-4 bytes changed (mostly near its start and its end, where a zip keeps its
    headers and its central directory)."""
    data = bytes(data)
    n = len(data)
    if draw(st.booleans()):
        return data[: draw(st.integers(0, n - 1))]
    out = bytearray(data)
    for _ in range(draw(st.integers(1, 4))):
        where = draw(st.sampled_from(["head", "tail", "any"]))
        if where == "head":
            i = draw(st.integers(0, min(63, n - 1)))
        elif where == "tail":
            i = n - 1 - draw(st.integers(0, min(511, n - 1)))
        else:
            i = draw(st.integers(0, n - 1))
        out[i] ^= draw(st.integers(1, 255))
    return bytes(out)


ARRAYS = hnp.arrays(
    st.sampled_from([np.float32, np.float64, np.int64, np.uint8, np.bool_, np.dtype("U3")]),
    hnp.array_shapes(min_dims=0, max_dims=4, max_side=4),
)
TEXTS = st.sampled_from(["", "../x.npy", "/etc/passwd", "quantized_labels.npy", "mesh", "slab", "box", "nan"])
DTYPES = [np.float16, np.float64, np.int8, np.int64, np.uint8, np.bool_, np.complex64, np.dtype("U4"), object]


def _reshaped(a: np.ndarray, how: str) -> np.ndarray:
    if how == "flat":
        return a.reshape(-1)
    if how == "axis":
        return a[None]
    if how == "shorter" and a.ndim:
        return a[:-1]
    if how == "swap" and a.ndim > 1:
        return np.swapaxes(a, 0, -1)
    if how == "scalar":
        return a.reshape(-1)[:1].reshape(()) if a.size else np.zeros(())
    return a[:0] if a.ndim else a.reshape(1)


def _spoiled(a: np.ndarray, value, index: int) -> np.ndarray:
    """``a`` with entry ``index`` (mod its size) set to ``value`` (cast as the array's dtype takes it)."""
    if not a.size:
        return a
    b = np.array(a)
    try:
        b.reshape(-1)[index % b.size] = value
    except (ValueError, TypeError, OverflowError):
        b = np.array(value)
    return b


@st.composite
def mutated_arrays(draw, arrays: dict) -> dict:
    """The arrays of an .npz with 1-3 changes: a key dropped, added or replaced; an array retyped, reshaped, given
    a non-finite, huge or negative entry, or (a string) a path."""
    out = dict(arrays)
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["drop", "add", "retype", "reshape", "spoil", "replace", "text"]))
        if op == "add" or not out:
            out[draw(st.text("abcdefghijk_", min_size=1, max_size=10))] = draw(ARRAYS)
            continue
        key = draw(st.sampled_from(sorted(out)))
        a = np.asarray(out[key])
        if op == "drop":
            del out[key]
        elif op == "retype":
            dtype = draw(st.sampled_from(DTYPES))
            try:
                out[key] = a.astype(dtype)
            except (ValueError, TypeError, OverflowError):
                out[key] = np.zeros(a.shape, dtype)
        elif op == "reshape":
            out[key] = _reshaped(a, draw(st.sampled_from(["flat", "axis", "shorter", "swap", "scalar", "empty"])))
        elif op == "spoil":
            value = draw(st.sampled_from([np.nan, np.inf, -np.inf, -1.0, 1e38, 2**40, 255, -(2**63)]))
            out[key] = _spoiled(a, value, draw(st.integers(0, 1000)))
        elif op == "replace":
            out[key] = draw(ARRAYS)
        else:
            out[key] = np.array(draw(TEXTS | st.text(max_size=6)))
    return out


def fuzz_npz(data, path: Path, base: Path) -> None:
    """Write at ``path`` the .npz ``base`` with its bytes damaged or its arrays mutated."""
    if data.draw(st.booleans(), label="damage bytes"):
        path.write_bytes(data.draw(damaged(Short(base.read_bytes()))))
        return
    with np.load(base, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mutated = data.draw(mutated_arrays(arrays))
    np.savez(path, **mutated)


# ------------------------------------------------------------------------------------------- valid files
@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Small valid files of every kind in a module-wide folder, and a scratch folder for the mutants."""
    root = tmp_path_factory.mktemp("fuzz")
    rng = np.random.default_rng(0)
    shape = (2, 3, 4)
    mix = rng.dirichlet(np.ones(len(INKS)), size=shape).astype(np.float32)
    inside = np.ones(shape, bool)
    inside[0, 0, 0] = False
    normals = SurfaceNormals(shape, np.array([1, 5, 20]), rng.normal(size=(3, 3)))
    Volume.from_mixture((0.1,) * 3, mix, INKS, inside=inside, normals=normals, origin_mm=(1, 2, 3)).save(
        root / "mixture.npz"
    )
    Volume.from_coefficients((0.1,) * 3, mix[..., :3] * 5, mix[..., 1:4]).save(root / "dense.npz")
    lab = rng.integers(0, len(INKS), shape).astype(np.uint8)
    Volume.from_labels((0.1,) * 3, lab, INKS).save(root / "labels.npz")
    run = RunDir.create(root / "run")
    tex = Texels.box_faces(shape, ["top"])
    run.save_scene(SceneRecord("slab", tex, np.full((len(tex), 3), 0.5, np.float32), free_mask=inside))
    run.save_quantized(Volume.from_labels(np.array([25.4 / 600, 25.4 / 300, 0.027]), lab, INKS), "sha256:00")
    scratch = RunDir.create(root / "scratch")
    return SimpleNamespace(root=root, run=run, scratch=scratch)


def volume_check(path):
    """A volume file read whole: a correct result is a volume whose coefficients are non-negative numbers (a
    mixture's may overflow to infinity, which the renderer refuses) and whose geometry is finite."""
    vol = Volume.load(path)
    with np.errstate(over="ignore"):
        s, a = vol.coefficients()
    assert np.all(s >= 0) and np.all(a >= 0)  # NaN compares False
    assert vol.normals is None or np.all(np.isfinite(vol.normals.vectors))
    assert vol.origin_mm is None or np.all(np.isfinite(vol.origin_mm))
    return vol


@fuzz(150)
@given(data=st.data())
def test_volume_files(files, data):
    base = files.root / data.draw(st.sampled_from(["mixture.npz", "dense.npz", "labels.npz"]))
    fuzz_npz(data, files.root / "volume.npz", base)
    clean(volume_check, files.root / "volume.npz")


def mixture_check(path):
    """A mixture volume read lazily: every layer and every block finite and non-negative, the blocks the layers."""
    with MixtureSource(path) as src:
        layers = np.stack([np.array(src[z], np.float32) for z in range(src.shape[0])])
        blocks = np.concatenate([rows for _, rows in src.blocks(7)])
    assert np.all(np.isfinite(layers)) and np.all(layers >= 0)
    np.testing.assert_array_equal(blocks, layers.reshape(blocks.shape))


@fuzz(150)
@given(data=st.data())
def test_mixture_source(files, data):
    fuzz_npz(data, files.root / "volume.npz", files.root / "mixture.npz")
    clean(mixture_check, files.root / "volume.npz")


def scene_check(run: RunDir):
    rec = run.load_scene()
    assert rec.target_rgb.shape == (len(rec.texels), 3) and np.all(np.isfinite(rec.target_rgb))
    assert np.all(rec.texels.face <= 5) and np.all(np.isfinite(rec.texels.normal))
    return rec


@fuzz(150)
@given(data=st.data())
def test_scene_files(files, data):
    fuzz_npz(data, files.scratch.scene_path, files.run.scene_path)
    clean(lambda _: scene_check(files.scratch), files.scratch.scene_path)


def quantized_check(run: RunDir):
    vol = run.load_quantized()
    assert vol.form == "labels" and vol.labels.ndim == 3
    return vol


@fuzz(150)
@given(data=st.data())
def test_quantized_files(files, data):
    """quantized.npz mutated, or its labels file (damaged, or another array saved in its place)."""
    d, run = files.scratch, files.run
    d.quantized_path.write_bytes(run.quantized_path.read_bytes())
    d.quantized_labels_path.write_bytes(run.quantized_labels_path.read_bytes())
    which = data.draw(st.sampled_from(["npz", "labels", "labels array"]))
    if which == "npz":
        fuzz_npz(data, d.quantized_path, run.quantized_path)
    elif which == "labels":
        d.quantized_labels_path.write_bytes(data.draw(damaged(Short(run.quantized_labels_path.read_bytes()))))
    else:  # an array in the .npy form (label file version 1) in place of the labels file
        buf = io.BytesIO()
        np.save(buf, data.draw(ARRAYS))
        d.quantized_labels_path.write_bytes(buf.getvalue())
    clean(lambda _: quantized_check(d), d.quantized_path, named=[d.quantized_labels_path])


@pytest.fixture(scope="module")
def checkpoint(files):
    """A tiny slab run after one step, its checkpoint file, and the run to load mutants into."""
    from inkopt.charts import colour_chart
    from inkopt.color import srgb_to_linear
    from inkopt.optim import Optimization, OptimizeConfig
    from inkopt.scenes.slab import build_slab

    vox = 25.4 / 300
    top = srgb_to_linear(colour_chart(24, 18) / 255.0).astype(np.float32)
    scene = build_slab(top, None, (4 * vox, 3 * vox, 0.2), INKS)
    cfg = OptimizeConfig(iterations=3, spp=1, forward_spp=1).for_scene("slab")
    run = Optimization(scene, cfg, threads=1)
    run.step()
    run.save_checkpoint(files.root / "checkpoint.npz")
    return SimpleNamespace(run=run, path=files.root / "checkpoint.npz", x_shape=run.x.shape)


def resume_check(path, ck):
    """A checkpoint loaded into the run: a correct result is a run with finite variables of its shape that
    continues: one more step, or a one-line ValueError where finite but absurd values (moments of 1e38) make the
    run's numbers overflow."""
    ck.run.load_checkpoint(path)
    assert ck.run.x.shape == ck.x_shape and np.all(np.isfinite(ck.run.x))
    try:
        with np.errstate(all="ignore"):
            ck.run.plan()
            ck.run.step()
    except ValueError as exc:
        assert "\n" not in str(exc) and str(exc), repr(exc)


@fuzz(100)
@given(data=st.data())
def test_checkpoint_files(files, checkpoint, data):
    checkpoint.run.load_checkpoint(checkpoint.path)  # the state of the valid file again
    fuzz_npz(data, files.root / "mutant.npz", checkpoint.path)
    clean(resume_check, files.root / "mutant.npz", checkpoint)


# ------------------------------------------------------------------------------------------- ink files
JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.sampled_from([10**400, -1, 0]) | st.floats() | st.text(max_size=5),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner, max_size=3),
    max_leaves=8,
)


@st.composite
def mutated_json(draw, value):
    """``value`` (JSON: dicts, lists, scalars) with 1-3 entries, found by a random walk from the top, replaced by
    random JSON or dropped."""
    value = json.loads(json.dumps(value))
    for _ in range(draw(st.integers(1, 3))):
        node, parent, key = value, None, None
        while isinstance(node, (dict, list)) and node and draw(st.integers(0, 4)) < 4:  # mostly deep down
            key = draw(st.sampled_from(sorted(node) if isinstance(node, dict) else range(len(node))))
            parent, node = node, node[key]
        if parent is None:
            value = draw(JSON)
        elif draw(st.booleans()):
            del parent[key]
        else:
            parent[key] = draw(JSON)
    return value


def toml_value(v) -> str:
    """``v`` as a TOML value (lists and dicts inline; TOML has no null, so None is left out)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if v != v else ("inf" if v == np.inf else "-inf" if v == -np.inf else repr(v))
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v if x is not None) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {toml_value(x)}" for k, x in v.items() if x is not None) + "}"
    return json.dumps(v) if v is not None else '""'


VALID_INKS = {
    "format_version": 1,
    "g": 0.4,
    "inks": [{"name": "cyan", "mu_t": [9, 4.5, 7.5], "albedo": [0.05, 0.7, 0.98]}] * 2,
    "provenance": {"fitted": "test"},
}


@fuzz(200)
@given(data=st.data())
def test_ink_files(files, data):
    """An ink file (JSON or TOML) with its values mutated, or its text damaged."""
    suffix = data.draw(st.sampled_from([".json", ".toml"]))
    value = data.draw(mutated_json(VALID_INKS))
    if suffix == ".json":
        text = json.dumps(value)
    else:
        body = value.items() if isinstance(value, dict) else [("x", value)]
        text = "\n".join(f"{json.dumps(k)} = {toml_value(v)}" for k, v in body if v is not None)
    raw = text.encode()
    path = files.root / f"inks{suffix}"
    path.write_bytes(data.draw(damaged(Short(raw))) if raw and data.draw(st.booleans()) else raw)
    clean(lambda p: InkTable.parse(str(p)), path)


@pytest.mark.parametrize("text", ["[" * 100_000, '{"inks": ' + "[" * 100_000])
def test_deeply_nested_ink_files(files, text):
    (files.root / "deep.json").write_text(text)
    with pytest.raises(ValueError, match=r"deep.json is nested too deeply to read$"):
        InkTable.parse(str(files.root / "deep.json"))


# ------------------------------------------------------------------------------------------- packages
@pytest.fixture(scope="module")
def packages(files):
    """A small GCVF and a small 3MF: {kind: (path, [(member name, bytes), ...])}."""
    lab = np.random.default_rng(1).integers(0, 3, (3, 4, 5)).astype(np.uint8)
    lab[0, 0] = 255
    job = PrintJob(LabelVoxels(lab, [25.4 / 600, 25.4 / 300, 0.027], INKS.names[:3]), printer_profile("j750"))
    FORMATS["png-slices"].write(job, files.root / "slices")
    out = {}
    for kind in ("gcvf", "3mf"):
        path = files.root / f"good.{kind}"
        FORMATS[kind].write(job, path)
        with zipfile.ZipFile(path) as zf:
            out[kind] = (path, Short((n, zf.read(n)) for n in zf.namelist()))
    return out


NAMES = st.sampled_from(
    ["../../evil.png", "/abs.png", "\\abs.png", "C:x.png", "a\\b.png", "x\x01.png", "layer_9.png", "Mesh.stl"]
    + ["3D/volumetric/inks0/sheet00009.png", "ConfigFile.xml", "3D/3dmodel.model", "dir/"]
) | st.text(min_size=1, max_size=8)
VALUES = st.sampled_from(["", "0", "-1", "1e400", "nan", "99999999999", "abc", "1 2", "/../x.png", "#FFF", "2"])


def _png(arr: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(arr[..., 0] if arr.shape[2] == 1 else arr).save(buf, format="PNG")
    return buf.getvalue()


@st.composite
def edited_xml(draw, text: bytes) -> bytes:
    """An XML member with one element's text or attribute replaced, or the element removed or repeated."""
    text = bytes(text)
    try:
        root = ET.fromstring(text)
    except ET.ParseError:  # damaged by an earlier change
        return text
    parents = {child: parent for parent in root.iter() for child in parent}
    el = draw(st.sampled_from(list(root.iter())))
    op = draw(st.sampled_from(["text", "attribute", "remove", "repeat"]))
    if op == "text":
        el.text = draw(VALUES | st.text(max_size=6))
    elif op == "attribute":
        el.set(draw(st.sampled_from([*el.keys(), "path", "id"])), draw(VALUES | st.text(max_size=6)))
    elif el in parents:
        (parents[el].remove if op == "remove" else parents[el].append)(el)
    return ET.tostring(root)


@st.composite
def mutated_members(draw, members: list) -> list:
    """1-3 changes to a package's members: one dropped, added (an unsafe or random name) or repeated; its bytes
    damaged; its XML edited; a PNG replaced by a random image."""
    out = list(members)
    for _ in range(draw(st.integers(1, 3))):
        i = draw(st.integers(0, len(out) - 1))
        name, data = out[i]
        op = draw(st.sampled_from(["drop", "add", "twin", "damage", "xml", "image"]))
        if op == "drop":
            del out[i]
        elif op == "add":
            out.append((draw(NAMES), draw(st.binary(max_size=32) | st.just(data))))
        elif op == "twin":
            out.append((draw(st.sampled_from([name, name.upper()])), data))
        elif op == "damage" and data:
            out[i] = (name, draw(damaged(Short(data))))
        elif op == "xml" and name.endswith((".xml", ".model", ".rels")):
            out[i] = (name, draw(edited_xml(Short(data))))
        elif op == "image" and name.endswith(".png"):
            shape = st.tuples(st.integers(1, 6), st.integers(1, 6), st.sampled_from([1, 3, 4]))
            out[i] = (name, _png(draw(hnp.arrays(np.uint8, shape))))
        if not out:
            break
    return out


def declare_size(raw: bytes, index: int, size: int) -> bytes:
    """The zip ``raw`` with the uncompressed size its central directory declares for member ``index`` patched."""
    with zipfile.ZipFile(io.BytesIO(raw)) as zf:
        start, infos = zf.start_dir, zf.infolist()
    at, out = start, bytearray(raw)
    for info in infos[:index]:
        at += 46 + len(info.orig_filename.encode()) + len(info.extra) + len(info.comment)
    out[at + 24 : at + 28] = size.to_bytes(4, "little")
    return bytes(out)


@fuzz(200)
@given(data=st.data())
def test_packages(files, packages, data):
    """A GCVF or 3MF with its members mutated (and perhaps a member declaring a huge size), or its bytes damaged."""
    kind = data.draw(st.sampled_from(["gcvf", "3mf"]))
    good, members = packages[kind]
    path = files.root / f"package.{kind}"
    if data.draw(st.booleans(), label="damage bytes"):
        path.write_bytes(data.draw(damaged(Short(good.read_bytes()))))
    else:
        buf = io.BytesIO()
        with warnings.catch_warnings(), zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
            warnings.simplefilter("ignore")  # repeated names
            for name, body in data.draw(mutated_members(members)):
                zf.writestr(name, body)
        raw = buf.getvalue()
        with zipfile.ZipFile(buf) as zf:
            n = len(zf.infolist())
        if n and data.draw(st.booleans(), label="declare a huge size"):
            raw = declare_size(raw, data.draw(st.integers(0, n - 1)), data.draw(st.sampled_from([2**31, 2**32 - 1])))
        path.write_bytes(raw)
    report = clean(inspect_package, path)
    if not isinstance(report, Exception):
        assert report[0].layers >= 1 and len(report[0].bounding_box) == 6


@fuzz(100)
@given(data=st.data())
def test_slice_manifests(files, packages, data):
    """A PNG slice folder whose manifest.json has its values mutated."""
    folder = files.root / "slices"
    manifest = json.loads((folder / "manifest.json").read_text())
    (folder / "manifest.json").write_text(json.dumps(data.draw(mutated_json(manifest))))
    try:
        clean(inspect_package, folder)
    finally:
        (folder / "manifest.json").write_text(json.dumps(manifest))
