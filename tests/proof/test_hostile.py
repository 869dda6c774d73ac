"""Script planted in every user string that reaches the soft-proof page (conftest's ``PAYLOADS``: ink names,
file names of the lighting map, picture, texture and mesh, the run directory's name, every value of report.json
and evaluation.json, result and face names and the lighting in predictions.npz and scene.npz) ends up as text:
the page, parsed, holds no element, attribute or comment a payload made, its scripts are its own and allowed by
its Content-Security-Policy by hash, and each payload is there to read. The same pages in a browser:
test_browser.py."""

import base64
import hashlib
import json
from html.parser import HTMLParser

import pytest
from proof.payloads import FILE_PAYLOADS, PAYLOADS

from inkopt.proof.page import CSS

# every tag the page writes itself
TAGS = {
    "html", "head", "meta", "title", "style", "body", "h1", "h2", "h3", "p", "section", "div", "label", "select",
    "option", "input", "a", "span", "img", "table", "thead", "tbody", "tr", "th", "td", "dl", "dt", "dd", "ul",
    "li", "code", "svg", "rect", "script",
}  # fmt: skip


class Page(HTMLParser):
    """A page's start tags (name, attributes), comments, scripts (attributes, text) and visible text."""

    def __init__(self, text: str):
        super().__init__(convert_charrefs=True)
        self.tags, self.comments, self.scripts, self.text = [], [], [], []
        self._script = None
        self.feed(text)
        self.close()

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))
        if tag == "script":
            self._script = (dict(attrs), [])

    handle_startendtag = handle_starttag

    def handle_endtag(self, tag):
        if tag == "script" and self._script is not None:
            self.scripts.append((self._script[0], "".join(self._script[1])))
            self._script = None

    def handle_data(self, data):
        (self._script[1] if self._script is not None else self.text).append(data)

    def handle_comment(self, data):
        self.comments.append(data)

    def policy(self) -> dict[str, list[str]]:
        """The Content-Security-Policy meta tag's directives."""
        (csp,) = [
            a["content"] for t, a in self.tags if t == "meta" and a.get("http-equiv") == "Content-Security-Policy"
        ]
        return {d.split()[0]: d.split()[1:] for d in csp.split(";")}


def _sha(text: str) -> str:
    return "'sha256-" + base64.b64encode(hashlib.sha256(text.encode()).digest()).decode() + "'"


def check_page(path) -> Page:
    """The page at ``path`` holds only the page's own markup: no tag or attribute a payload made (``pwn``), no
    event handler, no comment, and exactly its own scripts, which the policy admits by hash (and nothing else)."""
    text = path.read_text()
    page = Page(text)
    assert not page.comments, page.comments
    for tag, attrs in page.tags:
        assert tag in TAGS, tag
        assert "pwn" not in attrs and not any(a.startswith("on") for a in attrs), (tag, attrs)
    types = [a.get("type") for a, _ in page.scripts]
    if types[-1:] == [None] and len(types) in (3, 4):  # a spectral run's light selector (lights.js) comes last
        types = types[:-1]
    assert types in (["application/json", None], ["application/json", "importmap", "module"]), types
    policy = page.policy()
    assert policy["default-src"] == ["'none'"] and policy["script-src-attr"] == ["'none'"]
    assert policy["style-src"] == [_sha(CSS)] and policy["style-src-attr"] == ["'none'"]
    assert policy["img-src"] == ["data:"] and policy["base-uri"] == ["'none'"]
    run = [_sha(s) for a, s in page.scripts if a.get("type") != "application/json"]
    imports = [json.loads(s) for a, s in page.scripts if a.get("type") == "importmap"]
    run += [f"'{h}'" for m in imports for h in m["integrity"].values()]
    assert sorted(policy["script-src"]) == sorted(run)  # its own scripts and the vendored modules, no other source
    data = next(s for a, s in page.scripts if a.get("type") == "application/json")
    assert "<" not in data and ">" not in data
    return page


def _text(page: Page) -> str:
    return "".join(page.text)


def test_hostile_slab_page(hostile_slab_run):
    """Ink names, the lighting file's name, the picture's name and the run directory's name are shown as text."""
    page = check_page(hostile_slab_run / "report.html")
    text = _text(page)
    assert f"inkopt soft proof: run{FILE_PAYLOADS[1]}" in text  # title and heading
    assert f"inks {FILE_PAYLOADS[0]}, {FILE_PAYLOADS[2]}, {FILE_PAYLOADS[3]}, white;" in text
    assert f"predicted under environment map {FILE_PAYLOADS[1]}.npy" in text
    assert f"top picture {FILE_PAYLOADS[0]}.png" in text


def test_hostile_mesh_page(hostile_mesh_run):
    """... and for a mesh the mesh file's and texture's names."""
    page = check_page(hostile_mesh_run / "report.html")
    text = _text(page)
    assert f"inkopt soft proof: run{FILE_PAYLOADS[2]}" in text
    assert f"inks {FILE_PAYLOADS[0]}, {FILE_PAYLOADS[2]}, {FILE_PAYLOADS[3]}, white;" in text
    assert f"mesh file{FILE_PAYLOADS[0]}.obj" in text and f"{FILE_PAYLOADS[2]}.png" in text
    assert f"environment map {FILE_PAYLOADS[1]}.npy" in text


@pytest.mark.parametrize("kind", ["slab", "mesh"])
def test_planted_fields(planted_runs, kind):
    """Every value of report.json and evaluation.json, a result's name, the lighting and (slab) a face's name
    replaced by payloads: each payload is read as text, result and face names are attribute values and data."""
    page = check_page(planted_runs[kind] / "report.html")
    text = _text(page)
    assert all(p in text for p in PAYLOADS), [p for p in PAYLOADS if p not in text]
    values = [a.get("value") for t, a in page.tags if t == "option"]
    assert FILE_PAYLOADS[2] in values
    data = json.loads(next(s for a, s in page.scripts if a.get("type") == "application/json"))
    assert FILE_PAYLOADS[2] in data["results"]
    if kind == "slab":
        assert f"face-{FILE_PAYLOADS[1]}" in [a.get("id") for t, a in page.tags]
        assert FILE_PAYLOADS[1] in [f["name"] for f in data["slab"]["faces"]]
    else:
        assert f"predictions.npz from the {PAYLOADS[3]}" in text


@pytest.mark.parametrize("page", ["mesh_run/report.html", "slab_run/report.html", "slab_run/report_optimised.html"])
def test_ordinary_pages_pass_the_same_checks(page, request):
    run, name = page.split("/")
    check_page(request.getfixturevalue(run) / name)
