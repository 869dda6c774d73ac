"""The CGATS.17 reader on files laid out as i1Profiler and ArgyllCMS write them, the writer's round trip, and
one-line errors for malformed files."""

import pytest

from inkopt.calibration import cgats
from inkopt.calibration.cgats import CgatsError, CgatsTable, canonical_field
from inkopt.calibration.measure import measured_lab, spectral_fields

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
    ],
)
def test_malformed_files_are_one_line_errors(text, needle):
    with pytest.raises(CgatsError) as e:
        cgats.parse(text, "f.txt")
    assert needle in str(e.value) and "\n" not in str(e.value)
