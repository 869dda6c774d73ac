"""HTML of the soft-proof page made from untrusted values, safe by construction.

Every value the page shows comes from files a run directory holds (report.json, evaluation.json, the .npz
files' names and metadata, ink and file names), which anyone may have written. Markup is therefore only made
here: ``html(template, ...)`` fills a template, a literal of this package, with values that it escapes for HTML
text and quoted attributes (``html.escape`` with quotes) unless they are ``Markup`` made by this module already;
``join`` joins parts the same way. Data for the page's scripts is JSON that cannot end its ``<script>`` element
(``script_json``). tests/proof/test_markup.py checks that no other module of the package writes a tag itself.
"""

from __future__ import annotations

import base64
import hashlib
import html as _html
import json
import string


class Markup(str):
    """A string of HTML that may be inserted as it is: made only by ``html``, ``join`` or ``escape``."""

    __slots__ = ()


def escape(value) -> Markup:
    """``value`` as HTML text or a quoted attribute's value (``& < > " '`` escaped); ``Markup`` as it is."""
    return value if isinstance(value, Markup) else Markup(_html.escape(str(value), quote=True))


class _Escaping(string.Formatter):
    """``str.format`` that escapes every replacement field (after its format spec) unless it is ``Markup``."""

    def format_field(self, value, format_spec):
        if isinstance(value, Markup) and not format_spec:
            return value
        try:
            text = format(value, format_spec)
        except (TypeError, ValueError):  # a string where a number belongs (an edited file): shown as it is
            text = str(value)
        return escape(text)


_FORMATTER = _Escaping()


def html(template: str, /, *args, **kwargs) -> Markup:
    """``template`` (trusted markup: a string literal of this package) with its ``{fields}`` replaced by the
    escaped arguments (``str.format`` syntax; ``{x:.2f}`` formats numbers first, and a value that does not take
    its format spec is shown as text)."""
    return Markup(_FORMATTER.vformat(template, args, kwargs))


def join(parts, sep: str = "") -> Markup:
    """The escaped ``parts`` joined by ``sep`` (trusted markup)."""
    return Markup(sep.join(escape(p) for p in parts))


def raw_text_element(tag: str, content: str, **attrs) -> Markup:
    """A ``<script>`` or ``<style>`` element (``tag``) with escaped attributes and ``content`` as it is: raw text,
    which HTML does not unescape, so it must not hold the element's end tag or ``<!--`` (ValueError); the page's
    own scripts and styles and ``script_json`` output only."""
    if tag not in ("script", "style"):
        raise ValueError(f"{tag} is not a raw-text element")
    if f"</{tag}" in content.lower() or "<!--" in content:
        raise ValueError(f"the content of a <{tag}> element holds '</{tag}' or '<!--'")
    attributes = "".join(f' {k}="{escape(v)}"' for k, v in attrs.items())
    return Markup(f"<{tag}{attributes}>{content}</{tag}>")


_SCRIPT_UNSAFE = {"<": "\\u003c", ">": "\\u003e", "&": "\\u0026", "\u2028": "\\u2028", "\u2029": "\\u2029"}


def script_json(value) -> str:
    """``value`` as compact JSON that may stand inside a ``<script>`` element: ``< > &`` and the line
    separators U+2028/U+2029 are written as ``\\u`` escapes (they occur only inside JSON strings, where the
    escapes mean the same characters), so no value can close the element or open a comment."""
    text = json.dumps(value, separators=(",", ":"))
    for c, esc in _SCRIPT_UNSAFE.items():
        text = text.replace(c, esc)
    return text


def sha256_digest(data: bytes | str) -> str:
    """``sha256-<base64>`` of ``data`` (text hashed as UTF-8): a subresource-integrity value, and quoted, a
    Content-Security-Policy hash source."""
    raw = data.encode() if isinstance(data, str) else data
    return "sha256-" + base64.b64encode(hashlib.sha256(raw).digest()).decode()
