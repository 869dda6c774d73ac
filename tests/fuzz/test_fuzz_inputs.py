"""Property tests (hypothesis) of the input readers of scenes and calibration: whatever the text, a reader gives
a correct result or one clean error (a ValueError or OSError with a one-line message), never another exception.

- the CGATS.17 / ArgyllCMS .ti3 reader (``calibration.cgats.parse``) and what calibration reads from its tables
  (``measure.measured_lab``, ``calibrate.merge_measurements``), on structured files with broken parts and on
  arbitrary text; and the writer's round trip;
- an OBJ's material resolution (``scenes.mesh.source`` and ``load_mesh``) on small generated OBJ and MTL files:
  a mesh that loads shows the colours of its real textures, never trimesh's grey placeholder.

Each test's example count (``helpers.fuzz``: the same examples every run) keeps the whole file to a few seconds,
so it runs in the default selection.
"""

import tempfile
from pathlib import Path

import numpy as np
import pytest
import trimesh
from helpers import fuzz
from hypothesis import example, given
from hypothesis import strategies as st
from PIL import Image

from inkopt.calibration import cgats
from inkopt.calibration.calibrate import merge_measurements
from inkopt.calibration.cgats import CgatsError, CgatsTable
from inkopt.calibration.measure import MeasurementError, measured_lab
from inkopt.color import from_srgb8
from inkopt.scenes.mesh import load_mesh
from inkopt.scenes.mesh.source import MATERIAL_COLOURS, check_obj_materials

FAST = fuzz(150)


def clean(exc: BaseException, names: str = "") -> None:
    """The error is a ValueError or OSError with a one-line message (that contains ``names``: the file)."""
    assert isinstance(exc, (ValueError, OSError)), f"{type(exc).__name__}: {exc}"
    assert "\n" not in str(exc) and str(exc).strip(), repr(str(exc))
    assert names in str(exc), f"{names!r} not in {str(exc)!r}"


# ------------------------------------------------------------------------------------------------ CGATS / .ti3
WL10 = [f"SPEC_{w}" for w in range(380, 731, 10)]
FIELD_SETS = [
    ["LAB_L", "LAB_A", "LAB_B"],
    ["Lab_L", "Lab_a", "Lab_b"],
    ["XYZ_X", "XYZ_Y", "XYZ_Z"],
    WL10,
    [f"SPECTRAL_NM{w}" for w in range(400, 701, 20)],
    [f"nm{w}" for w in range(380, 731, 10)],
    [f"SPEC_{w:03.0f}" for w in np.linspace(380, 730, 106)],
    ["XYZ_X", "XYZ_Y"],
    [],
]
GOOD = st.floats(0, 100, allow_nan=False).map(lambda v: f"{v:.4g}")
NUMBER = st.one_of(
    GOOD,
    st.floats(-5, 250, allow_nan=False).map(lambda v: f"{v:.4g}"),
    st.integers(-3, 200).map(str),
    st.sampled_from(["nan", "inf", "-inf", "1e400", '""', "-", "1,5", "0x10", "50%"]),
)
TOKEN = st.one_of(NUMBER, st.text(st.characters(codec="utf-8", exclude_characters="\n\r"), max_size=6))
KEYWORDS = [
    "SPECTRAL_BANDS",
    "SPECTRAL_START_NM",
    "SPECTRAL_END_NM",
    "SPECTRAL_NORM",
    "ILLUMINANT_WHITE_POINT_XYZ",
    "NUMBER_OF_SETS",
    "NUMBER_OF_FIELDS",
    "KEYWORD",
    "DESCRIPTOR",
]
KEY_VALUE = st.one_of(NUMBER, st.sampled_from(['"36"', '"380.0"', '"730"', '"100"', '"96.42 100 82.49"', '"1 2"']))


@st.composite
def cgats_text(draw) -> str:
    """A CGATS.17 or .ti3 file: a first line, header keywords (the ones calibration reads, with any value), a field
    list of SAMPLE_ID and one kind of measurement columns (and extra fields), rows of numbers and junk (some the
    wrong length, some ids repeated); then, in some files, lines dropped, repeated, swapped or inserted. Most
    files are whole, so that the readers of the measurements see them."""
    fields = ["SAMPLE_ID"] * draw(st.sampled_from([1, 1, 1, 0])) + draw(st.sampled_from(FIELD_SETS))
    fields += draw(st.lists(st.sampled_from(["SAMPLE_LOC", "CMYK_C", "INK_CYAN", "A B", "#x", '"Q"']), max_size=1))
    lines = [draw(st.sampled_from(["CGATS.17"] * 4 + ["CTI3   "] * 4 + ["", "# comment", "BEGIN_DATA", "\x00"]))]
    lines += [
        f"{draw(st.sampled_from(KEYWORDS))} {draw(KEY_VALUE)}" for _ in range(draw(st.sampled_from([0] * 3 + [1, 2])))
    ]
    lines += ["BEGIN_DATA_FORMAT", " ".join(fields), "END_DATA_FORMAT", "BEGIN_DATA"]
    for k in range(draw(st.integers(0, 4))):
        width = len(fields) + draw(st.sampled_from([0] * 40 + [-1, 1]))
        sid = draw(st.sampled_from([str(k + 1)] * 6 + ["1", '"A 1"', '""']))
        values = [draw(GOOD) for _ in range(max(0, width - 1))]
        if values and draw(st.sampled_from([False] * 3 + [True])):  # one value anything
            values[draw(st.integers(0, len(values) - 1))] = draw(NUMBER)
        lines.append(" ".join([sid, *values]))
    lines.append("END_DATA")
    for _ in range(draw(st.sampled_from([0] * 8 + [1, 2]))):
        i = draw(st.integers(0, len(lines) - 1))
        op = draw(st.sampled_from(["drop", "repeat", "swap", "junk"]))
        if op == "drop":
            del lines[i]
        elif op == "repeat":
            lines.insert(i, lines[i])
        elif op == "swap" and i + 1 < len(lines):
            lines[i], lines[i + 1] = lines[i + 1], lines[i]
        elif op == "junk":
            lines.insert(i, draw(TOKEN))
        if not lines:
            break
    return draw(st.sampled_from(["\n", "\r\n", "\r"])).join(lines)


CHART = CgatsTable(["SAMPLE_ID", "INK_WHITE", "THICKNESS_MM"], [["1", "1", "2"], ["2", "1", "1"]])


def read_measurements(text: str) -> None:
    """Parse ``text`` and read its measurements directly and matched to a two-patch chart: a table and finite
    CIELAB in range, or one clean error at each step."""
    try:
        table = cgats.parse(text, "m.ti3")
    except Exception as exc:  # noqa: BLE001 - the property: which exceptions come out
        clean(exc, "m.ti3")
        assert isinstance(exc, CgatsError)
        return
    assert all(len(r) == len(table.fields) for r in table.rows)
    for source in ("direct", "chart"):
        try:
            t = table if source == "direct" else merge_measurements(CHART, table, "m.ti3")
            lab, kind = measured_lab(t, "D50")
        except Exception as exc:  # noqa: BLE001
            clean(exc)  # the reader's own errors, not numpy's or colour's
            assert isinstance(exc, MeasurementError) or str(exc).startswith("m.ti3: "), repr(exc)
            continue
        assert kind in ("lab", "xyz", "spectral") and lab.shape == (len(t.rows), 3)
        assert np.isfinite(lab).all() and (lab[:, 0] >= -1e-6).all()


@FAST
@given(cgats_text())
def test_cgats_structured_files(text):
    read_measurements(text)


@fuzz(100)
@given(st.text(st.characters(codec="utf-8"), max_size=300))
def test_cgats_arbitrary_text(text):
    read_measurements(text)


@fuzz(50)
@given(st.binary(max_size=200))
def test_cgats_arbitrary_bytes(data):
    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "m.txt").write_bytes(data)
        try:
            cgats.read(Path(d) / "m.txt")
        except Exception as exc:  # noqa: BLE001
            clean(exc)


NAME = st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,7}", fullmatch=True)
VALUE = st.one_of(
    st.text(st.characters(codec="utf-8", exclude_characters='"\n\r'), max_size=8),
    st.integers(-(10**6), 10**6),
    st.floats(-1e6, 1e6, allow_nan=False),
)


@fuzz(100)
@given(st.lists(NAME, min_size=1, max_size=4, unique_by=str.upper), st.data())
def test_cgats_write_then_read(fields, data):
    """A table the writer accepts reads back with the same fields and the values it wrote; values it cannot
    write are refused in one line."""
    rows = data.draw(st.lists(st.lists(VALUE, min_size=len(fields), max_size=len(fields)), max_size=3))
    header = data.draw(
        st.dictionaries(NAME, st.text(st.characters(codec="utf-8", exclude_characters='"\n\r'), max_size=6), max_size=2)
    )
    table = CgatsTable(fields, rows, header)
    try:
        text = cgats.format_table(table)
    except Exception as exc:  # noqa: BLE001
        clean(exc)
        return
    back = cgats.parse(text, "t.txt")
    assert back.fields == fields
    want = [[v if isinstance(v, str) else f"{v:.6g}" if isinstance(v, float) else str(v) for v in r] for r in rows]
    assert back.rows == want


# ------------------------------------------------------------------------------------------------ OBJ / MTL
RED = (200, 30, 30)
LINEAR_RED = from_srgb8(np.array(RED, np.float32) / 255)
BLUE = np.array([0.0, 0.0, 1.0], np.float32)  # every material's Kd, the colour of an untextured one
MATERIAL = st.sampled_from(["mat", "mat", "mat", "other", "Mat", "mat two", "m\u00e9t"])
MAP = st.sampled_from(
    ["tex.png"] * 8
    + ["small.png"] * 4
    + ["nothere.png", "junk.txt", "-s 1 1 1 tex.png", "tex.png extra", "sub/tex.png"]
)
MTLLIB = st.sampled_from(
    ["m.mtl"] * 12 + ["other.mtl", "junk.txt", "nothere.mtl", "m.mtl other.mtl", "", "/etc/hostname"]
)


@st.composite
def obj_files(draw) -> dict:
    """An OBJ of a unit cube and its material library: ``mtllib`` statements (mostly one; none, two, junk,
    missing), ``usemtl`` before the first and/or the second half of the faces (names the library may not define),
    uv coordinates or not; m.mtl and other.mtl, whose materials (mostly the ones the OBJ uses) name textures that
    exist (uniform RED, 8 x 8 and 4 x 4), do not exist, are not images, or carry options; comments that mention
    the statements."""
    box = trimesh.creation.box((1, 1, 1))
    uv = draw(st.sampled_from([True] * 9 + [False]))
    lines = draw(st.lists(st.sampled_from(["# made without mtllib", "o cube", "g part", "s off", "# c"]), max_size=1))
    lines += [f"mtllib {draw(MTLLIB)}" for _ in range(draw(st.sampled_from([1] * 8 + [0, 2])))]
    lines += ["v {:g} {:g} {:g}".format(*p) for p in box.vertices]
    lines += [f"vt {p[0] + 0.5:g} {p[1] + 0.5:g}" for p in box.vertices] if uv else []
    faces = ["f " + " ".join(f"{i}/{i}" if uv else f"{i}" for i in t) for t in box.faces + 1]
    used = [draw(MATERIAL), draw(st.sampled_from([None, None, None, "again"]) | MATERIAL)]
    used[0] = draw(st.sampled_from([used[0]] * 9 + [None]))
    for half, use in zip((faces[:6], faces[6:]), used):
        if use == "again":
            use = None if used[0] is None else used[0]
        lines += ([f"usemtl {use}"] if use is not None else []) + half
    files = {"m.obj": "\n".join(lines) + "\n"}
    for lib in ("m.mtl", "other.mtl"):
        names = [u for u in used if u not in (None, "again")] if draw(st.sampled_from([True] * 9 + [False])) else []
        mtl = []
        for name in dict.fromkeys(names + [draw(MATERIAL) for _ in range(draw(st.sampled_from([0, 0, 0, 1, 2])))]):
            mtl += [f"newmtl {name}", "Kd 0 0 1"]
            mtl += [f"map_Kd {draw(MAP)}"] if draw(st.sampled_from([True, True, True, False])) else []
        mtl += draw(st.lists(st.sampled_from(["# map_Kd tex.png", "Ns 10", "illum 2", "map_Kd tex.png"]), max_size=1))
        files[lib] = "\n".join(mtl) + "\n"
    return files


def _write(folder: Path, files: dict) -> Path:
    for name, text in files.items():
        (folder / name).write_text(text)
    Image.new("RGB", (8, 8), RED).save(folder / "tex.png")
    Image.new("RGB", (4, 4), RED).save(folder / "small.png")
    (folder / "junk.txt").write_text("root:x:0:0:root:/root:/bin/bash\n")
    return folder / "m.obj"


#: an OBJ without vt lines, one material textured and one not: trimesh's atlas gives every face uv of its own, which
#: looked the faces up in the wrong cells (black and red where red and blue were meant)
NO_VT_TWO_MATERIALS = {
    "m.obj": "mtllib m.mtl\n"
    + "".join(f"v {x} {y} {z}\n" for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5))
    + "usemtl other\nf 2 4 1\nf 5 2 1\nf 1 4 3\nf 3 5 1\nf 2 8 4\nf 6 2 5\n"
    + "usemtl mat\nf 6 8 2\nf 4 8 3\nf 7 5 3\nf 3 8 7\nf 7 6 5\nf 8 6 7\n",
    "m.mtl": "newmtl other\nKd 0 0 1\nmap_Kd small.png\nnewmtl mat\nKd 0 0 1\n",
    "other.mtl": "\n",
}


#: two untextured materials: trimesh's atlas of their colours, a tile each, blended with its black surround
TWO_UNTEXTURED = {
    "m.obj": "mtllib m.mtl\n"
    + "".join(f"v {x} {y} {z}\n" for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5))
    + "".join(f"vt {u} {v}\n" for u in (0, 1) for v in (0, 0, 1, 1)[::2] for _ in (0, 1))
    + "usemtl other\n"
    + "".join(
        f"f {a}/{a} {b}/{b} {c}/{c}\n" for a, b, c in ((2, 4, 1), (5, 2, 1), (1, 4, 3), (3, 5, 1), (2, 8, 4), (6, 2, 5))
    )
    + "usemtl mat\n"
    + "".join(
        f"f {a}/{a} {b}/{b} {c}/{c}\n" for a, b, c in ((6, 8, 2), (4, 8, 3), (7, 5, 3), (3, 8, 7), (7, 6, 5), (8, 6, 7))
    ),
    "m.mtl": "newmtl other\nKd 0 0 1\nnewmtl mat\nKd 0 0 1\n",
    "other.mtl": "\n",
}


@FAST
@given(obj_files())
@example(files=NO_VT_TWO_MATERIALS)
@example(files=TWO_UNTEXTURED)
def test_obj_material_resolution(files):
    """Either one clean error, or a mesh whose target is its real texture: red at every face of a textured
    material, its Kd (blue) at every face of an untextured one, a texture of a file's size (or an atlas of them),
    named by its files, without alpha; never trimesh's 2 x 2 grey placeholder."""
    with tempfile.TemporaryDirectory() as d:
        obj = _write(Path(d), files)
        try:
            check_obj_materials(obj)
            mesh = load_mesh(obj, height_mm=2.0)
        except Exception as exc:  # noqa: BLE001
            clean(exc, d)  # names a file of the folder
            return
    assert mesh.color_source == "texture", mesh.color_source  # nothing else colours these files
    assert mesh.texture.size != (2, 2) and mesh.texture_name
    assert set(mesh.texture_name.split(", ")) <= {"tex.png", "small.png", MATERIAL_COLOURS}
    assert mesh.texture_alpha is None  # none of the files has alpha; an atlas's transparent padding is not
    f = np.arange(len(mesh.faces))
    colours = mesh.colors_at(f, np.full((len(f), 3), 1 / 3))
    off = np.minimum(np.abs(colours - LINEAR_RED).max(1), np.abs(colours - BLUE).max(1))
    assert off.max() < 0.02, colours[np.argmax(off)]  # a textured material's red, an untextured one's Kd blue


@fuzz(100)
@given(st.text(st.characters(codec="utf-8"), max_size=200))
def test_obj_statements_of_arbitrary_text(text):
    """The statement reader on any text: its materials, or one clean error (junk is not an OBJ's colour)."""
    with tempfile.TemporaryDirectory() as d:
        obj = Path(d) / "x.obj"
        obj.write_text(text)
        Image.new("RGB", (8, 8), RED).save(Path(d) / "tex.png")
        try:
            check_obj_materials(obj)
        except Exception as exc:  # noqa: BLE001
            clean(exc)


if __name__ == "__main__":
    pytest.main([__file__, "-q"])
