"""The tables of measured figures in README.md and docs/ are the ones docs/tables.py generates from the results
files (run ``python docs/tables.py`` after changing a results file or a table)."""

from pathlib import Path

import pytest
from helpers import load_file_module

ROOT = Path(__file__).resolve().parents[1]


def _tables():
    return load_file_module(ROOT / "docs" / "tables.py", "docs_tables")


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


def test_the_ink_table_is_read_from_the_code():
    """docs/method.md's ink table is ``INK_LIBRARY`` as the package defines it (parsed, not imported, by tables.py)."""
    from inkopt.model.inks import DEFAULT_G, INK_LIBRARY

    tables = _tables()
    assert tables.source_constant(tables.INKS, "INK_LIBRARY") == INK_LIBRARY
    assert tables.source_constant(tables.INKS, "DEFAULT_G") == DEFAULT_G
    text = tables.ink_library()
    for name, (mu_t, albedo) in INK_LIBRARY.items():
        assert f"| {name} | " + " | ".join(f"{x:g}" for x in (*mu_t, *albedo)) + " |" in text


def test_a_changed_ink_makes_the_page_stale(tmp_path, monkeypatch):
    tables = _tables()
    doc = tmp_path / "doc.md"
    doc.write_text("<!-- table:ink-library -->\n<!-- /table:ink-library -->\n")
    monkeypatch.setattr(tables, "DOCS", [doc])
    monkeypatch.setattr(tables, "ROOT", tmp_path)
    assert tables.main([]) == 0 and tables.main(["--check"]) == 0
    inks = tmp_path / "inks.py"
    inks.write_text(tables.INKS.read_text().replace('"cyan": ((9.0, 4.5, 7.5)', '"cyan": ((9.5, 4.5, 7.5)'))
    monkeypatch.setattr(tables, "INKS", inks)
    monkeypatch.setattr(tables, "REPO", tmp_path)
    assert tables.main(["--check"]) == 1


def test_a_constant_that_is_not_a_literal_is_an_error(tmp_path, monkeypatch):
    tables = _tables()
    src = tmp_path / "mod.py"
    src.write_text("A = 1\nB = f(2)\n")
    monkeypatch.setattr(tables, "REPO", tmp_path)
    assert tables.source_constant(src, "A") == 1
    for name in ("B", "C"):
        with pytest.raises(SystemExit, match=f"no top-level literal assignment to {name}"):
            tables.source_constant(src, name)
