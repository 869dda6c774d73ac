"""The CGATS.17 reader on files laid out as i1Profiler and ArgyllCMS write them, the writer's round trip, and
one-line errors for malformed files."""

import numpy as np
import pytest

from inkopt.calibration import cgats
from inkopt.calibration.cgats import CgatsError, CgatsTable, canonical_field
from inkopt.calibration.measure import MeasurementError, measured_lab, spectral_fields

WL = list(range(380, 731, 10))

# i1Profiler: tab-separated, "SampleID"/"SAMPLE_NAME", "nm380" spectral fields in fractions, LAB fields too.
I1PROFILER = (
    "CGATS.17\n"
    'FILE_DESCRIPTOR\t""\n'
    'ORIGINATOR\t"i1Profiler"\n'
    'CREATED\t"November 26, 2026"\n'
    'KEYWORD\t"DEVCALSTD"\n'
    'DEVCALSTD\t"XRGA"\n'
    'KEYWORD\t"SAMPLE_NAME"\n'
    "NUMBER_OF_FIELDS\t" + str(5 + len(WL)) + "\n"
    "BEGIN_DATA_FORMAT\n"
    "SampleID\tSAMPLE_NAME\tLab_L\tLab_a\tLab_b\t" + "\t".join(f"nm{w}" for w in WL) + "\n"
    "END_DATA_FORMAT\n"
    "NUMBER_OF_SETS\t2\n"
    "BEGIN_DATA\n"
    "1\tA1\t76.07\t0.00\t0.00\t" + "\t".join(["0.5"] * len(WL)) + "\n"
    "2\tA2\t53.39\t0.00\t0.00\t" + "\t".join(["0.2134"] * len(WL)) + "\n"
    "END_DATA\n"
)

# ArgyllCMS .ti3: "CTI3" first line, space-separated, quoted keywords, comments, SPECTRAL_NM fields in percent,
# the field list over two lines.
ARGYLL = (
    "CTI3   \n\n"
    'DESCRIPTOR "Argyll Calibration Target chart information 3"\n'
    'ORIGINATOR "Argyll chartread"\n'
    'CREATED "Thu Nov 26 09:00:00 2026"\n'
    'KEYWORD "DEVICE_CLASS"\nDEVICE_CLASS "OUTPUT"\n'
    'KEYWORD "SPECTRAL_BANDS"\nSPECTRAL_BANDS "36"\n'
    "# a comment line\n"
    "NUMBER_OF_FIELDS " + str(4 + len(WL)) + "\n"
    "BEGIN_DATA_FORMAT\n"
    "SAMPLE_ID XYZ_X XYZ_Y XYZ_Z\n" + " ".join(f"SPECTRAL_NM{w}" for w in WL) + "\n"
    "END_DATA_FORMAT\n\n"
    "NUMBER_OF_SETS 2\n"
    "BEGIN_DATA\n"
    "1 48.2 50.0 41.2 " + " ".join(["50.0"] * len(WL)) + "\n"
    "2 20.5 21.34 17.6 " + " ".join(["21.34"] * len(WL)) + "  # trailing comment\n"
    "END_DATA\n"
)


@pytest.mark.parametrize("text", [I1PROFILER, ARGYLL], ids=["i1profiler", "argyll"])
def test_instrument_layouts(text):
    t = cgats.parse(text, "file")
    assert t.column("SAMPLE_ID") == ["1", "2"]
    assert [w for w, _ in spectral_fields(t)] == WL
    lab, kind = measured_lab(t, "D50")
    assert kind == "spectral"
    # A flat reflectance R has Y = R and a* = b* = 0 under any illuminant: L* = 116 R^(1/3) - 16 (CIE 15).
    for k, r in enumerate((0.5, 0.2134)):
        assert lab[k, 0] == pytest.approx(116 * r ** (1 / 3) - 16, abs=0.02)
        assert abs(lab[k, 1]) < 0.05 and abs(lab[k, 2]) < 0.05


def test_lab_columns_and_round_trip(tmp_path):
    t = CgatsTable(
        ["SAMPLE_ID", "LAB_L", "LAB_A", "LAB_B", "NOTE"], [[1, 50.0, 10.0, -20.0, "a b"]], {"ORIGINATOR": "x"}
    )
    path = cgats.write(tmp_path / "t.txt", t)
    back = cgats.read(path)
    assert back.fields == t.fields and back.rows == [["1", "50", "10", "-20", "a b"]]
    assert back.header == {"ORIGINATOR": "x"}
    lab, kind = measured_lab(back, "D65")
    assert kind == "lab" and lab.tolist() == [[50.0, 10.0, -20.0]]


def test_backslashes_are_themselves(tmp_path):
    """CGATS has no escapes: a Windows path reads and writes back as it is, quoted or not."""
    t = CgatsTable(["SAMPLE_ID", "PATH"], [["1", "C:\\data\\a.txt"], ["2", "\\"]])
    back = cgats.read(cgats.write(tmp_path / "p.txt", t))
    assert back.rows == t.rows
    bare = cgats.parse("CGATS.17\nBEGIN_DATA_FORMAT\nA B\nEND_DATA_FORMAT\nBEGIN_DATA\n1 C:\\x\\y\nEND_DATA\n")
    assert bare.rows == [["1", "C:\\x\\y"]]


def test_a_table_without_rows_has_no_measurements():
    t = cgats.parse("CGATS.17\nBEGIN_DATA_FORMAT\nSAMPLE_ID LAB_L LAB_A LAB_B\nEND_DATA_FORMAT\nBEGIN_DATA\nEND_DATA\n")
    with pytest.raises(MeasurementError, match="^the measurements have no rows"):
        measured_lab(t, "D50")


def test_field_spellings():
    assert canonical_field("SampleID") == "SAMPLE_ID"
    assert canonical_field("Lab_L") == "LAB_L"
    assert canonical_field("nm400") == canonical_field("SPECTRAL_NM_400") == "SPECTRAL_NM400"


@pytest.mark.parametrize(
    "text,needle",
    [
        ("", "empty"),
        ("CGATS.17\nBEGIN_DATA\nEND_DATA\n", "before the field list"),
        ("CGATS.17\nBEGIN_DATA_FORMAT\nA B\nEND_DATA_FORMAT\nBEGIN_DATA\n1 2\n", "no complete"),
        ("CGATS.17\nBEGIN_DATA_FORMAT\nA B\nEND_DATA_FORMAT\nBEGIN_DATA\n1 2 3\nEND_DATA\n", "3 values for 2"),
        (
            "CGATS.17\nBEGIN_DATA_FORMAT\nA\nEND_DATA_FORMAT\nNUMBER_OF_SETS 2\nBEGIN_DATA\n1\nEND_DATA\n",
            "NUMBER_OF_SETS",
        ),
        ('CGATS.17\nBEGIN_DATA_FORMAT\nA\nEND_DATA_FORMAT\nBEGIN_DATA\n"1\nEND_DATA\n', "line 6"),
        ("\nBEGIN_DATA_FORMAT\nA\nEND_DATA_FORMAT\nBEGIN_DATA\n1\nEND_DATA\n", "line 2: the file must start with the"),
    ],
)
def test_malformed_files_are_one_line_errors(text, needle):
    with pytest.raises(CgatsError) as e:
        cgats.parse(text, "f.txt")
    assert needle in str(e.value) and "\n" not in str(e.value)


def ti3(fields, rows, keywords=(), name="SPEC") -> str:
    """An ArgyllCMS .ti3 file as chartread writes it: "CTI3", quoted keywords declared with KEYWORD, the
    spectral fields declared too, SAMPLE_LOC strings, CMYK device values, space-separated rows."""
    head = [
        "CTI3   ",
        "",
        'DESCRIPTOR "Argyll Calibration Target chart information 3"',
        'ORIGINATOR "Argyll chartread"',
        'CREATED "Thu Nov 26 09:00:00 2026"',
        'KEYWORD "DEVICE_CLASS"',
        'DEVICE_CLASS "OUTPUT"',
        'KEYWORD "COLOR_REP"',
        'COLOR_REP "CMYK_XYZ"',
        'KEYWORD "INSTRUMENT_TYPE_SPECTRAL"',
        'INSTRUMENT_TYPE_SPECTRAL "YES"',
    ]
    for k, v in keywords:
        head += [f'KEYWORD "{k}"', f'{k} "{v}"']
    head += [f'KEYWORD "{f}"' for f in fields if f.startswith(name + "_")]
    head += ["", f"NUMBER_OF_FIELDS {4 + len(fields)}", "BEGIN_DATA_FORMAT"]
    head += ["SAMPLE_ID SAMPLE_LOC CMYK_C CMYK_K " + " ".join(fields), "END_DATA_FORMAT", ""]
    head += [f"NUMBER_OF_SETS {len(rows)}", "BEGIN_DATA"]
    body = [f'{k + 1} "A{k + 1}" 0.0000 0.0000 ' + " ".join(r) for k, r in enumerate(rows)]
    return "\n".join(head + body + ["END_DATA", ""])


ARGYLL_SPECTRAL = [("SPECTRAL_BANDS", "36"), ("SPECTRAL_START_NM", "380.000000"), ("SPECTRAL_END_NM", "730.000000")]


@pytest.mark.parametrize(
    ("norm", "values"), [("100.000000", ("50.000", "21.340")), ("1.0", ("0.5", "0.2134")), (None, ("50.0", "21.34"))]
)
def test_argyll_ti3_spectral(norm, values):
    """chartread's spectral form: SPEC_380 ... SPEC_730 divided by SPECTRAL_NORM (the percent rule without it)."""
    keywords = ARGYLL_SPECTRAL + ([("SPECTRAL_NORM", norm)] if norm else [])
    fields = ["XYZ_X", "XYZ_Y", "XYZ_Z", *(f"SPEC_{w}" for w in WL)]
    rows = [["48.2", "50.0", "41.2", *[values[0]] * len(WL)], ["20.5", "21.34", "17.6", *[values[1]] * len(WL)]]
    t = cgats.parse(ti3(fields, rows, keywords), "m.ti3")
    assert t.source == "CTI3" and t.column("SAMPLE_ID") == ["1", "2"]
    lab, kind = measured_lab(t, "D50")
    assert kind == "spectral"
    for k, r in enumerate((0.5, 0.2134)):  # flat reflectance R: L* = 116 R^(1/3) - 16, a* = b* = 0 (CIE 15)
        assert lab[k, 0] == pytest.approx(116 * r ** (1 / 3) - 16, abs=0.02)
        assert abs(lab[k, 1]) < 0.05 and abs(lab[k, 2]) < 0.05


def test_argyll_ti3_high_resolution_bands():
    """chartread's 3.3 nm mode: 106 bands 380-730 nm whose field names are the rounded wavelengths (SPEC_383 is
    383.33 nm); the header's keywords give the wavelengths, interpolated onto whole nm for ASTM E308."""
    wl = np.linspace(380, 730, 106)
    fields = [f"SPEC_{w:03.0f}" for w in wl]
    keywords = [("SPECTRAL_BANDS", "106"), ("SPECTRAL_START_NM", "380"), ("SPECTRAL_END_NM", "730")]
    t = cgats.parse(ti3(fields, [["50.0"] * 106], [*keywords, ("SPECTRAL_NORM", "100")]), "hires.ti3")
    lab, kind = measured_lab(t, "D65")
    assert kind == "spectral" and lab[0, 0] == pytest.approx(116 * 0.5 ** (1 / 3) - 16, abs=0.02)
    bad = cgats.parse(ti3(fields[:-1], [["50.0"] * 105], keywords), "short.ti3")
    with pytest.raises(MeasurementError, match="declares 106 spectral bands from 380 to 730 nm, but the table has 105"):
        measured_lab(bad, "D50")


def test_argyll_ti3_xyz_against_hand_computed_lab():
    """XYZ on the 0-100 scale under D50 (ArgyllCMS's default): a patch with X = Xn/2, Y = 0.184187 (so that
    f(Y) = 66/116) and Z = 0.3 Zn has, by the CIE 15 formulas, L* = 116 * 66/116 - 16 = 50,
    a* = 500 (0.5^(1/3) - 66/116) = 112.3675, b* = 200 (66/116 - 0.3^(1/3)) = -20.0935. The D50 white
    xy (0.3457, 0.3585): Xn = 0.964296, Zn = 0.825105."""
    rows = [["48.2148", "18.4187", "24.7532"], ["96.4296", "100.0", "82.5105"]]
    t = cgats.parse(ti3(["XYZ_X", "XYZ_Y", "XYZ_Z"], rows), "xyz.ti3")
    lab, kind = measured_lab(t, "D50")
    assert kind == "xyz"
    np.testing.assert_allclose(lab[0], [50.0, 112.3675, -20.0935], atol=0.01)
    np.testing.assert_allclose(lab[1], [100.0, 0.0, 0.0], atol=0.01)
    # under D65 the file's D50 values are adapted (Bradford): its white stays the perfect white
    lab65, _ = measured_lab(t, "D65")
    np.testing.assert_allclose(lab65[1], [100.0, 0.0, 0.0], atol=0.01)
    assert abs(lab65[0, 0] - 50.0) < 1.0 and abs(lab65[0, 1] - 112.37) > 0.5
    # a white point keyword says which white the values are relative to: D65's here, so no adaptation under D65
    d65 = [("ILLUMINANT_WHITE_POINT_XYZ", "95.047 100.0 108.883")]
    t65 = cgats.parse(ti3(["XYZ_X", "XYZ_Y", "XYZ_Z"], [["95.047", "100.0", "108.883"]], d65), "w.ti3")
    np.testing.assert_allclose(
        measured_lab(t65, "D65")[0][0], [100.0, 0.0, 0.0], atol=0.03
    )  # the keyword white vs CIE D65 xy
    np.testing.assert_allclose(
        measured_lab(t65, "D50")[0][0], [100.0, 0.0, 0.0], atol=0.03
    )  # the keyword white vs CIE D65 xy


def test_argyll_field_spellings():
    assert canonical_field("SPEC_380") == "SPECTRAL_NM380" and canonical_field("spec_730") == "SPECTRAL_NM730"
