"""Printer profiles (inkopt.printing.profiles): typed, JSON round trip, lookups, the material-slot check and the
resolution check."""

import json

import pytest

from inkopt.cli.common import flag_of
from inkopt.errors import ParameterError
from inkopt.printing.profiles import (
    PRINTER_PROFILES,
    PrinterProfile,
    check_slots,
    material_name,
    printer_profile,
    resolution_mismatch,
)


def test_json_round_trip_and_keys():
    for key, prof in PRINTER_PROFILES.items():
        d = prof.to_json()
        assert PrinterProfile.from_json(json.loads(json.dumps(d))) == prof and d["key"] == key
    assert set(PRINTER_PROFILES["j750"].to_json()) == {
        "key",
        "name",
        "max_materials",
        "dpi",
        "layer_um",
        "materials",
        "gcvf_colors",
    }
    assert set(PRINTER_PROFILES["generic"].to_json()) == {"key", "name", "max_materials", "materials"}


def test_lookups():
    j = printer_profile(" J750 ")
    assert j.key == "j750" and j.max_materials == 6 and j.material("Cyan") == "VeroCY-V"
    assert material_name(j, "orange") is None and material_name(None, "cyan") is None
    with pytest.raises(ValueError, match="unknown printer 'j9000'"):
        printer_profile("j9000")


def test_resolution_mismatch():
    j = printer_profile("j750")
    assert resolution_mismatch(j, (25.4 / 600, 25.4 / 300, 0.027)) is None
    assert resolution_mismatch(j, (25.4 / 600, 25.4 / 300, 0.014)) is None
    msg = resolution_mismatch(j, (25.4 / 300, 25.4 / 300, 0.027))
    assert "300 x 300 DPI" in msg and "Stratasys J750 prints 600 x 300 DPI" in msg
    assert resolution_mismatch(printer_profile("mimaki-3duj-553"), (1.0, 1.0, 1.0)) is None  # no grid known


def test_check_slots_names_the_printer_parameter():
    check_slots(["cyan", "white"], 2, "j750")
    check_slots(["cyan", "white", "black"], None)
    with pytest.raises(ParameterError) as e:
        check_slots(["cyan", "white", "black"], 2, "Stratasys J55 Prime")
    msg = str(e.value)
    assert msg.startswith("the print uses 3 inks (cyan, white, black) but Stratasys J55 Prime holds 2 materials")
    assert msg.endswith("(printer)") and e.value.render(flag_of).endswith("(--printer)")
    with pytest.raises(ParameterError, match="but the printer holds 1"):
        check_slots(["cyan", "white"], 1)
