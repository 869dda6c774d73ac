"""bench/mesh_suite.py: its manifest is well formed, and ``run`` and ``table`` go end to end on a tiny synthetic
mesh standing in for a download (3 mm, 2 iterations, the fewest samples; no network), so the suite's script cannot
rot while its real runs take hours."""

import json
import re

import numpy as np
import pytest
from helpers import FAST_RUN, REPO, load_file_module, write_cube_obj
from PIL import Image


def _suite():
    return load_file_module(REPO / "bench" / "mesh_suite.py", "mesh_suite")


def test_manifest_is_well_formed():
    suite = _suite()
    assert len(suite.MESHES) >= 6
    for name, src in suite.SOURCES.items():
        assert src["registry"] in ("debian", "pypi"), name
        assert re.fullmatch(r"[0-9a-f]{64}", src["sha256"]), name
        assert src["version"] and (src["licence_file"] or src["registry"] == "pypi"), name
    formats = set()
    for name, m in suite.MESHES.items():
        assert re.fullmatch(r"[a-z]+", name)
        assert m["source"] in suite.SOURCES and suite.SOURCES[m["source"]]["registry"] == "debian", name
        assert m["files"] and len({f.rsplit("/", 1)[-1] for f in m["files"]}) == len(m["files"]), name
        assert all(m[k].strip() for k in ("format", "licence", "author", "tests")), name
        assert m.get("adapt") in (None, *suite.ADAPTATIONS), name
        if m.get("texture"):
            assert m["texture"] in [f.rsplit("/", 1)[-1] for f in m["files"]], name
        formats.add(m["format"].split()[0])
    assert formats == {"glTF", "OBJ"}
    text = suite.licences_text(list(suite.MESHES), {"neverball-common": "Files: *\nLicense: GPL-2+"})
    assert all(f"## {name}" in text for name in suite.MESHES) and "License: GPL-2+" in text


def test_budgets_and_mesh_files():
    suite = _suite()
    assert suite.budget_args("short") == ["--time-budget", "5m"]
    assert suite.budget_args("3it") == ["--iterations", "3"]
    with pytest.raises(SystemExit, match="unknown budget"):
        suite.budget_args("forever")
    assert suite.mesh_file("duck", suite.CACHE).name == "duck.glb"
    assert suite.mesh_file("spider", suite.CACHE).name == "spider.obj"


def test_mtl_paths_are_made_plain(tmp_path):
    suite = _suite()
    (tmp_path / "s.mtl").write_text("newmtl a\nmap_Kd .\\wal.jpg\nnewmtl b\nmap_Kd ./wood.jpg\nmap_Kd keep.jpg\n")
    suite.adapt("spider", tmp_path, tmp_path)
    assert (tmp_path / "s.mtl").read_text() == "newmtl a\nmap_Kd wal.jpg\nnewmtl b\nmap_Kd wood.jpg\nmap_Kd keep.jpg\n"


def test_run_and_table_end_to_end(tmp_path, monkeypatch):
    """A textured cube named through ``texture`` (as the neverball meshes are): run writes its cell with the four
    results' figures, a second run skips it without calling inkopt, and table puts it into a document."""
    suite = _suite()
    ramp = np.full((16, 16, 3), 200, np.uint8)  # a pastel ramp from light blue to light pink
    ramp[..., 0] = np.linspace(150, 250, 16)[None, :]
    write_cube_obj(tmp_path / "meshes" / "cube", mtllib=None, write_mtl=False, texture=Image.fromarray(ramp))
    entry = {
        "source": "neverball-common",
        "files": ["x/m.obj", "x/tex.png"],
        "texture": "tex.png",
        "format": "OBJ",
        "licence": "test",
        "author": "test",
        "tests": "the script",
    }
    monkeypatch.setitem(suite.MESHES, "cube", entry)
    results = tmp_path / "suite.json"
    argv = ["run", "--cache", str(tmp_path), "--meshes", "cube", "--sizes", "3", "--budgets", "2it"]
    fast = " ".join(FAST_RUN[2:])  # the fewest samples (the budget gives the iterations)
    variant = [f"--optimize-args={fast}", "--evaluate-args=--spp 8 --texel-sample 300", "--variant", "fast"]
    assert suite.main([*argv, "--results", str(results), *variant]) == 0
    cells = json.loads(results.read_text())["cells"]
    assert list(cells) == ["cube/3mm/2it+fast"] and (tmp_path / "runs" / "cube_3mm_2it_fast" / "report.json").is_file()
    cell = cells["cube/3mm/2it+fast"]
    assert cell["iterations"] == 2 and cell["height_mm"] == 3 and cell["variant"] == "fast"
    assert cell["optimize_args"][:4] == ["--height-mm", "3", "--iterations", "2"]
    assert cell["optimize_args"][-2:] == ["--texture", "tex.png"] and cell["evaluate_args"] == [
        "--spp",
        "8",
        "--texel-sample",
        "300",
    ]
    assert set(cell["results"]) == {"continuous", "printed", "surface", "extrusion"}
    assert cell["quantization"]["method"] == "count-adaptive"  # the halftone the print was made with
    # and what the run chose of the compensation (the default inks' factors ship: a choice was made)
    choice = cell["compensation_choice"]
    assert choice.startswith("compensated;" if cell["quantization"].get("compensate") else "plain"), choice
    for fig in cell["results"].values():
        assert 0 < fig["delta_e76_corrected"] < 100 and -1 <= fig["ssim"] <= 1 and fig["delta_e2000"] > 0
    # the evaluation's paired differences, and refresh adding them to a cell recorded without them
    ev = json.loads((tmp_path / "runs" / "cube_3mm_2it_fast" / "evaluation.json").read_text())
    assert ev["quantization"]["compensation_choice"]["compensate"] is bool(cell["quantization"].get("compensate"))
    lead = cell["differences"]["printed - extrusion"]
    assert lead["delta_e2000"] == ev["differences"]["quantized - extrusion"]["delta_e2000_mean"]
    assert lead["ssim"]["stderr"] >= 0 and set(cell["differences"]) == {
        "printed - extrusion",
        "printed - surface",
        "continuous - printed",
    }
    data = json.loads(results.read_text())
    del data["cells"]["cube/3mm/2it+fast"]["differences"]
    del data["cells"]["cube/3mm/2it+fast"]["quantization"]
    results.write_text(json.dumps(data))
    assert suite.main(["refresh", "--cache", str(tmp_path), "--results", str(results)]) == 0
    assert json.loads(results.read_text())["cells"]["cube/3mm/2it+fast"] == cell
    # a derived variant's volume: the run's last iterate after the finishing passes its result has (report.json's
    # finish_smooth: 1, the mesh default; 0 or 1 where the run chose them) is the run's own result
    paired = load_file_module(REPO / "bench" / "mesh_suite_paired.py", "mesh_suite_paired")
    run = tmp_path / "runs" / "cube_3mm_2it_fast"
    passes = json.loads((run / "report.json").read_text())["finish_smooth"]
    assert passes == 1 and cell["finish"] is None
    paired.checkpoint_volume(run, tmp_path / "again.npz", passes, str(tmp_path / "meshes" / "cube" / "tex.png"))
    assert np.array_equal(np.load(tmp_path / "again.npz")["mixture"], np.load(run / "volume.npz")["mixture"])
    real = suite.inkopt
    monkeypatch.setattr(suite, "inkopt", lambda *a: pytest.fail("a finished cell is run again"))
    assert suite.main([*argv, "--results", str(results), *variant]) == 0
    # --again: the recorded cell printed and evaluated anew from its optimised result, its entry replaced
    calls = []
    monkeypatch.setattr(suite, "inkopt", lambda args, log: calls.append(args[0]) or real(args, log))
    (run / "evaluation.json").write_text("{}")  # a stale output: removed, not read
    assert suite.main([*argv, "--results", str(results), *variant, "--again"]) == 0
    assert calls == ["quantize", "evaluate"]
    again = json.loads(results.read_text())["cells"]["cube/3mm/2it+fast"]
    assert again["results"]["printed"] == cell["results"]["printed"]  # the same result, seed and settings
    assert again["iterations"] == 2 and again["quantize_seconds"] > 0
    assert again["optimize_commit"] == cell["commit"]  # the optimisation's own record stays
    assert again["optimize_args"] == cell["optimize_args"] and again["optimize_seconds"] == cell["optimize_seconds"]

    doc = tmp_path / "doc.md"
    doc.write_text("# x\n<!-- table:mesh-suite -->\nold\n<!-- /table:mesh-suite -->\nafter\n")
    assert suite.main(["table", "--results", str(results), "--doc", str(doc)]) == 0
    assert "| cube |" not in doc.read_text()  # the defaults' table: the variant's cell is not one of them
    doc.write_text("# x\n<!-- table:mesh-suite-variants -->\nold\n<!-- /table:mesh-suite-variants -->\nafter\n")
    table = ["table", "--results", str(results), "--doc", str(doc), "--table-name", "mesh-suite-variants"]
    assert suite.main(table) == 0
    text = doc.read_text()
    row = next(line for line in text.splitlines() if line.startswith("| cube |"))
    printed = cell["results"]["printed"]["delta_e76_corrected"]
    assert "| 3 | 2it + fast | count-adaptive (auto) | 2 it," in row and f"{printed:.2f}" in row
    assert f"{lead['delta_e76_corrected']['value']:+.2f} ± {lead['delta_e76_corrected']['stderr']:.2f}" in row
    assert "old" not in text and text.endswith("<!-- /table:mesh-suite-variants -->\nafter\n")


def test_a_variant_is_named_and_keyed_apart():
    """Further arguments without a variant's name are refused (they would change a default's cell); a variant's
    key and run folder are its own."""
    suite = _suite()
    with pytest.raises(SystemExit, match="--variant NAME"):
        suite.Extra.of(["--finish-smooth", "0"], [])
    with pytest.raises(SystemExit, match="folder name"):
        suite.Extra.of(["--finish-smooth", "0"], [], "../x")
    assert suite.cell_key("duck", 10.0, "short", None) == "duck/10mm/short"
    assert suite.cell_key("duck", 10.0, "short", "nofinish") == "duck/10mm/short+nofinish"
