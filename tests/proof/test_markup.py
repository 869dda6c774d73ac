"""The soft-proof page's markup helpers (inkopt.proof.markup) and the rule that keeps the page safe by
construction: no module of inkopt.proof but markup.py writes a tag itself."""

import ast
import json
from pathlib import Path

import pytest

import inkopt.proof
from inkopt.proof.markup import Markup, escape, html, join, raw_text_element, script_json

PROOF = Path(inkopt.proof.__file__).parent


def test_html_escapes_every_value_but_markup():
    got = html('<a title="{}">{}</a>{}', "\"'<&>", "<b>x</b>", html("<i>{}</i>", "<y>"))
    assert got == '<a title="&quot;&#x27;&lt;&amp;&gt;">&lt;b&gt;x&lt;/b&gt;</a><i>&lt;y&gt;</i>'
    assert isinstance(got, Markup) and join(["<", html("<br>")], ", ") == "&lt;, <br>"
    assert escape(escape("<")) == "&lt;"  # escaped once: Markup passes through


def test_format_specs_apply_before_escaping():
    """Numbers take their format spec; a value that does not (a string in an edited file) is shown as text."""
    assert html("{:.2f} {:g} {x:.1f}", 1.234, 0.5, x=2) == "1.23 0.5 2.0"
    assert html("{:.2f}", "<img>") == "&lt;img&gt;" and html("{:.0f}", None) == "None"


def test_script_json_cannot_end_its_element():
    value = {"</script><script>": "<!--\u2028\u2029&-->", "n": [1.5, None]}
    text = script_json(value)
    assert not any(c in text for c in "<>&\u2028\u2029") and json.loads(text) == value


def test_raw_text_elements_refuse_their_end_tag():
    assert raw_text_element("script", "let a = 1 < 2;", type="module", id='"x') == (
        '<script type="module" id="&quot;x">let a = 1 < 2;</script>'
    )
    for bad in ("a</SCRIPT>b", "<!-- x"):
        with pytest.raises(ValueError):
            raw_text_element("script", bad)
    with pytest.raises(ValueError):
        raw_text_element("div", "x")


def _markup_strings(tree):
    """String literals that hold a tag (``<`` then a letter, ``/`` or ``!``) and are not the template of an
    ``html(...)`` call, a docstring or an error message, with their line numbers; f-strings with a ``<``; and
    every ``Markup(...)`` call."""
    templates, docstrings, bad = set(), set(), []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "html" and node.args:
            templates.add(id(node.args[0]))
        if isinstance(node, (ast.Module, ast.FunctionDef, ast.ClassDef)) and ast.get_docstring(node) is not None:
            docstrings.add(id(node.body[0].value))
        if isinstance(node, ast.Raise):  # error messages go to the terminal, not the page
            docstrings |= {id(n) for n in ast.walk(node)}
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "Markup":
            bad.append((node.lineno, "Markup(...)"))
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in templates | docstrings:
            text = node.value
            if any(
                text[i + 1 : i + 2].isalpha() or text[i + 1 : i + 2] in "/!"
                for i in range(len(text) - 1)
                if text[i] == "<"
            ):
                bad.append((node.lineno, text[:40]))
        if isinstance(node, ast.JoinedStr) and any(isinstance(v, ast.Constant) and "<" in v.value for v in node.values):
            bad.append((node.lineno, "f-string with a tag"))
    return bad


@pytest.mark.parametrize("module", sorted(p.name for p in PROOF.glob("*.py") if p.name != "markup.py"))
def test_only_markup_writes_tags(module):
    """Every tag of the page is in the template of an ``html(...)`` call, which escapes what fills it: no
    f-string, concatenation or ``Markup(...)`` of another module makes markup from values."""
    bad = _markup_strings(ast.parse((PROOF / module).read_text()))
    assert not bad, f"{module}: markup outside html(): {bad}"
