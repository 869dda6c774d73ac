"""CGATS.17 text files (ANSI CGATS.17, as i1Profiler, ArgyllCMS and most colour instruments write them): read
one data table and write one.

A file is a header of ``KEYWORD value`` lines (values may be double-quoted; ``KEYWORD "NAME"`` declares a
non-standard keyword), a field list between ``BEGIN_DATA_FORMAT`` and ``END_DATA_FORMAT`` (one or several lines)
and one row per sample between ``BEGIN_DATA`` and ``END_DATA``. Fields are separated by tabs or spaces; ``#``
starts a comment outside quoted strings. The first line names the format (``CGATS.17``, or ``CTI3`` for
ArgyllCMS's .ti3 files); it is not checked beyond being present. Field names are kept as written;
:func:`canonical_field` maps the spellings of instruments' software to one name (``SampleID`` -> ``SAMPLE_ID``,
``Lab_L`` -> ``LAB_L``, ``nm380`` / ``SPECTRAL_NM_380`` / ArgyllCMS's ``SPEC_380`` -> ``SPECTRAL_NM380``).
"""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path

from ..io import atomic_write_bytes


class CgatsError(ValueError):
    """A file that is not a readable CGATS.17 table (one line)."""


@dataclass
class CgatsTable:
    """One table: ``header`` keyword -> value (strings, quotes removed), ``fields`` as written, ``rows`` of
    strings (each as long as ``fields``; an empty quoted value is "")."""

    fields: list[str]
    rows: list[list[str]]
    header: dict[str, str] = field(default_factory=dict)
    source: str = "CGATS.17"

    def column(self, name: str) -> list[str]:
        """The values of the field whose canonical name is ``name`` (KeyError if it is absent)."""
        for i, f in enumerate(self.fields):
            if canonical_field(f) == name:
                return [r[i] for r in self.rows]
        raise KeyError(name)

    def has(self, name: str) -> bool:
        return any(canonical_field(f) == name for f in self.fields)


_ALIASES = {"SAMPLEID": "SAMPLE_ID", "SAMPLE_ID": "SAMPLE_ID", "ID": "SAMPLE_ID"}
_SPECTRAL = re.compile(r"^(?:SPECTRAL_NM_?|SPECTRAL_|SPEC_|NM_?|R)(\d{3,4})$")


def canonical_field(name: str) -> str:
    """Upper case, and the common spellings of the sample id, CIELAB and spectral fields (``nm380``,
    ``SPECTRAL_NM_380``, ``SPEC_380``, ``R380``) mapped to
    ``SAMPLE_ID``, ``LAB_L``/``LAB_A``/``LAB_B`` and ``SPECTRAL_NM<λ>``."""
    up = name.strip().upper()
    if up in _ALIASES:
        return _ALIASES[up]
    m = _SPECTRAL.match(up)
    if m:
        return f"SPECTRAL_NM{int(m.group(1))}"
    return up


_STRUCTURE = {"BEGIN_DATA_FORMAT", "END_DATA_FORMAT", "BEGIN_DATA", "END_DATA", "NUMBER_OF_SETS", "NUMBER_OF_FIELDS"}


def _tokens(line: str, where: str) -> list[str]:
    lex = shlex.shlex(line, posix=True)
    lex.whitespace_split, lex.commenters = True, "#"
    lex.escape = ""  # CGATS has no escapes: a backslash is itself (a Windows path), also in a quoted string
    try:
        return list(lex)
    except ValueError as exc:
        raise CgatsError(f"{where}: {exc}") from None


def parse(text: str, where: str = "CGATS file") -> CgatsTable:
    """The first data table of a CGATS.17 text; :class:`CgatsError` (one line) for a malformed file."""
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    first_at = next((i for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")), None)
    if first_at is None:
        raise CgatsError(f"{where}: the file is empty")
    first = lines[first_at].strip()
    if first.split()[0].upper() in _STRUCTURE:
        raise CgatsError(
            f"{where} line {first_at + 1}: the file must start with the name of its format (CGATS.17, or CTI3 for "
            f"ArgyllCMS), got {first.split()[0]}"
        )
    header: dict[str, str] = {}
    fields: list[str] | None = None
    rows: list[list[str]] = []
    state = "header"
    declared_sets = None
    for no, raw in enumerate(lines[first_at + 1 :], start=first_at + 2):
        toks = _tokens(raw, f"{where} line {no}")
        if not toks:
            continue
        key = toks[0].upper()
        if state == "header":
            if key == "BEGIN_DATA_FORMAT":
                state, fields = "format", list(toks[1:])
            elif key == "BEGIN_DATA":
                raise CgatsError(f"{where} line {no}: BEGIN_DATA before the field list (BEGIN_DATA_FORMAT)")
            elif key == "NUMBER_OF_SETS":
                declared_sets = toks[1] if len(toks) > 1 else None
            elif key not in ("KEYWORD", "NUMBER_OF_FIELDS"):
                header[toks[0]] = " ".join(toks[1:])
        elif state == "format":
            if key == "END_DATA_FORMAT":
                state = "between"
            else:
                fields.extend(toks)
        elif state == "between":
            if key == "BEGIN_DATA":
                state = "data"
            elif key == "NUMBER_OF_SETS":
                declared_sets = toks[1] if len(toks) > 1 else None
            elif key not in ("KEYWORD", "NUMBER_OF_FIELDS"):
                header[toks[0]] = " ".join(toks[1:])
        elif state == "data":
            if key == "END_DATA":
                state = "done"
                break
            if len(toks) != len(fields):
                raise CgatsError(f"{where} line {no}: {len(toks)} values for {len(fields)} fields")
            rows.append(toks)
    if fields is None:
        raise CgatsError(f"{where}: no BEGIN_DATA_FORMAT field list")
    if state != "done":
        raise CgatsError(f"{where}: no complete BEGIN_DATA ... END_DATA table")
    if not fields:
        raise CgatsError(f"{where}: the field list is empty")
    if declared_sets is not None and declared_sets.isdigit() and int(declared_sets) != len(rows):
        raise CgatsError(f"{where}: NUMBER_OF_SETS is {declared_sets} but the table has {len(rows)} rows")
    return CgatsTable(fields, rows, header, first.split()[0])


def read(path) -> CgatsTable:
    p = Path(path)
    if not p.is_file():
        raise CgatsError(f"{path}: no such file")
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        text = p.read_text(encoding="latin-1")
    return parse(text, str(path))


def _value(v) -> str:
    if isinstance(v, str):
        if '"' in v or "\n" in v:
            raise CgatsError(f"a CGATS string value cannot hold a double quote or a line break: {v!r}")
        return f'"{v}"'
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def format_table(table: CgatsTable) -> str:
    """The text of ``table`` (strings double-quoted, numbers as written, tab-separated)."""
    standard = {"ORIGINATOR", "DESCRIPTOR", "CREATED", "FILE_DESCRIPTOR", "NUMBER_OF_FIELDS", "NUMBER_OF_SETS"}
    out = [table.source]
    for k, v in table.header.items():
        if k.upper() not in standard:
            out.append(f'KEYWORD\t"{k}"')
        out.append(f"{k}\t{_value(str(v))}")
    out += [f"NUMBER_OF_FIELDS\t{len(table.fields)}", "BEGIN_DATA_FORMAT", "\t".join(table.fields)]
    out += ["END_DATA_FORMAT", f"NUMBER_OF_SETS\t{len(table.rows)}", "BEGIN_DATA"]
    for r in table.rows:
        if len(r) != len(table.fields):
            raise CgatsError(f"a row has {len(r)} values for {len(table.fields)} fields")
        out.append("\t".join(_value(v) for v in r))
    out.append("END_DATA")
    return "\n".join(out) + "\n"


def write(path, table: CgatsTable) -> Path:
    """Write ``table`` atomically (row values: str -> quoted string, numbers as they are)."""
    atomic_write_bytes(path, format_table(table).encode("utf-8"))
    return Path(path)
