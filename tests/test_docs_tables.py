"""The tables of measured figures in README.md and docs/ are the ones docs/tables.py generates from the results
files (run ``python docs/tables.py`` after changing a results file or a table)."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _tables():
    spec = importlib.util.spec_from_file_location("docs_tables", ROOT / "docs" / "tables.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_documents_hold_the_generated_tables():
    assert _tables().main(["--check"]) == 0, "stale tables: run python docs/tables.py"


def test_every_table_is_placed_once_and_every_marker_is_known():
    tables = _tables()
    placed = [m.group(2) for doc in tables.DOCS for m in tables.MARKER.finditer(doc.read_text())]
    assert sorted(placed) == sorted(tables.TABLES)


def test_check_fails_on_a_stale_table(tmp_path, monkeypatch):
    tables = _tables()
    doc = tmp_path / "doc.md"
    doc.write_text("text\n<!-- table:ray-shards -->\n| stale |\n<!-- /table:ray-shards -->\n")
    monkeypatch.setattr(tables, "DOCS", [doc])
    monkeypatch.setattr(tables, "ROOT", tmp_path)
    assert tables.main(["--check"]) == 1
    assert tables.main([]) == 0 and tables.main(["--check"]) == 0
    assert "| how | seconds per iteration |" in doc.read_text()


def test_an_unknown_table_is_an_error(tmp_path, monkeypatch):
    tables = _tables()
    doc = tmp_path / "doc.md"
    doc.write_text("<!-- table:nope -->\n<!-- /table:nope -->\n")
    monkeypatch.setattr(tables, "DOCS", [doc])
    monkeypatch.setattr(tables, "ROOT", tmp_path)
    with pytest.raises(SystemExit, match="unknown table 'nope'"):
        tables.main(["--check"])
