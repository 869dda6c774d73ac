"""The soft-proof page itself: one self-contained HTML file. Scripts, pictures and data are inlined (data: URLs
and inline scripts), so the page opens without network access and can be sent on its own. The 3D view uses
three.js, vendored in ``vendor/`` (its version in ``THREE_VERSION``, its licence beside it) and handed to the
page's module script through an import map of data: URLs.

All markup is made by ``markup.html`` from escaped values, and the page carries a Content-Security-Policy that
lets run only its own scripts, by their SHA-256 hashes computed as the page is written (the vendored modules'
through the import map's ``integrity``): no inline event handler, no style attribute, no other script, images
from data: URLs only and no network connection. A value that got past the escaping could still not run.
"""

from __future__ import annotations

import base64
from dataclasses import dataclass
from importlib import resources

from .figures import LABELS
from .markup import Markup, html, join, raw_text_element, script_json, sha256_digest

THREE_VERSION = "0.170.0"  # python/inkopt/proof/vendor/: three.module.min.js, OrbitControls.js, LICENSE-three.txt
PAGE_FORMAT = 1  # the page's format_version (in its data block and a meta tag)

CSS = """
body{font:14px/1.4 system-ui,sans-serif;margin:0 auto;max-width:1100px;padding:0 16px 40px;color:#222}
h1{font-size:22px;margin:18px 0 4px}h2{font-size:17px;margin:26px 0 8px;border-bottom:1px solid #ddd}
.sub{color:#555;margin:0 0 10px}.note{color:#555;font-size:12.5px}
table{border-collapse:collapse;margin:6px 0}td,th{padding:3px 9px;border-bottom:1px solid #e5e5e5;text-align:right}
td:first-child,th:first-child{text-align:left}th{font-weight:600;background:#f6f6f6}
.swatch{display:inline-block;width:12px;height:12px;border:1px solid #999;margin-right:6px;vertical-align:-1px}
img.loss{max-width:100%}
dl{display:grid;grid-template-columns:max-content auto;gap:3px 14px}dt{font-weight:600}dd{margin:0}
.bar{display:flex;flex-wrap:wrap;gap:8px 14px;align-items:center;margin:6px 0}
#view3d{position:relative}#stage3d{position:relative;height:560px;border:1px solid #ddd;background:#fff}
#stage3d canvas{display:block;touch-action:none}
#stage3d .needs{position:absolute;left:12px;top:4px;color:#555;visibility:hidden;animation:needs 0s 4s forwards}
@keyframes needs{to{visibility:visible}}#view3d[data-ready] .needs{display:none}
.line{position:absolute;top:0;bottom:0;width:2px;background:#e33;pointer-events:none;display:none}
input[type=range]{width:260px}
body.full3d{max-width:none;padding:0}body.full3d #view3d{position:fixed;inset:0;z-index:5;background:#fff;
display:flex;flex-direction:column}body.full3d #stage3d{flex:1;height:auto;border:0}
body.full3d #view3d .bar{padding:4px 10px}
.face{display:inline-block;margin:0 20px 14px 0;vertical-align:top;width:max(var(--w),300px)}
.swipe{position:relative;display:inline-block}
.swipe img{display:block;image-rendering:pixelated;width:var(--w)}.swipe img.top{position:absolute;left:0;top:0}
.swipe .line{display:block}.legend{display:flex;align-items:center;gap:6px;font-size:12.5px}
.legend img{width:200px;height:10px;image-rendering:pixelated}
"""


def data_uri(data: bytes, mime: str) -> str:
    return f"data:{mime};base64," + base64.b64encode(data).decode()


def _vendor(name: str) -> bytes:
    return resources.files(__package__).joinpath("vendor", name).read_bytes()


def _asset(name: str) -> str:
    return resources.files(__package__).joinpath(name).read_text()


def _options(keys: list[str], selected: str, none: str | None = None) -> Markup:
    opts = [html('<option value="">{}</option>', none)] if none is not None else []
    opts += [
        html('<option value="{}"{}>{}</option>', k, html(" selected") if k == selected else "", LABELS.get(k, k))
        for k in keys
    ]
    return join(opts)


def _legend(legend_uri: str, scale: float) -> Markup:
    return html(
        '<span class="legend">ΔE76 0 <img alt="heat scale" src="{}"> {:.0f}+ (magma, shared by all results)</span>',
        legend_uri,
        scale,
    )


def mesh_section(keys: list[str], legend_uri: str, scale: float, note: str) -> Markup:
    """The 3D view: result picker, swipe partner, heat toggle, full-window link and the canvas."""
    first = "quantized" if "quantized" in keys else "continuous"
    return html(
        """
<section id="3d"><div id="view3d">
<div class="bar"><label>show <select id="pick3d">{pick}</select></label>
<label>swipe against <select id="other3d">{other}</select></label>
<input id="swipe3d" type="range" min="0" max="100" value="50" aria-label="swipe position">
<label><input id="heat3d" type="checkbox"> ΔE76 heat map</label>{legend}
<a href="#3d">full window</a> <a href="#">back</a></div>
<div id="stage3d"><div id="line3d" class="line"></div><p class="needs">The 3D view did not start: it needs
JavaScript and a browser that checks the integrity of the modules an import map names (Chromium-based browsers and
Safari since 2024).</p></div>
<p class="note">Drag to turn, wheel or pinch to zoom, right-drag to pan. {note}</p>
</div></section>""",
        pick=_options(keys, first),
        other=_options(keys, "target", "(nothing)"),
        legend=_legend(legend_uri, scale),
        note=note,
    )


def slab_section(faces: list[dict], keys: list[str], legend_uri: str, scale: float, note: str | None = None) -> Markup:
    """Every textured face of a slab: two results with a swipe line, and the heat-map toggle (faces.js sizes
    them); ``note``: a line below them (text), if any."""
    second = "quantized" if "quantized" in keys else "continuous"
    left, right = _options(keys, "target"), _options(keys, second)
    return html(
        '<section id="faces"><h2>Faces</h2>{}<div>{}</div>{}</section>',
        join(_face(f["name"], left, right) for f in faces),
        _legend(legend_uri, scale),
        "" if note is None else html('<p class="note">{}</p>', note),
    )


def _face(name: str, left: Markup, right: Markup) -> Markup:
    return html(
        """<div class="face" id="face-{name}"><h3>{name} face</h3>
<div class="bar"><label>left <select>{left}</select></label>
<label>right <select>{right}</select></label>
<label><input type="checkbox"> ΔE76 heat map</label></div>
<div class="swipe"><img class="layer" alt="left"><img class="layer top" alt="right">
<div class="line"></div></div>
<div class="bar"><input type="range" min="0" max="100" value="50" aria-label="swipe position"></div></div>""",
        name=name,
        left=left,
        right=right,
    )


@dataclass(frozen=True)
class Scripts:
    """The page's script elements (``html``) and the hashes of those that run (``hashes``: the CSP's sources,
    ``sha256-<base64>`` each)."""

    html: Markup
    hashes: tuple[str, ...]


def scripts(data: dict, mesh: bool) -> Scripts:
    """The data block (``data`` as JSON, read by the scripts with JSON.parse) and the view's scripts: for meshes
    the import map of the vendored three.js (with their integrity, so that the policy admits them by hash) and
    viewer3d.js as a module, else faces.js; with ``lights`` in ``data`` (a spectral run) also lights.js."""
    blob = script_json({"format_version": PAGE_FORMAT, **data})
    out = [raw_text_element("script", blob, type="application/json", id="inkopt-data")]
    hashes = []
    if mesh:
        modules = {"three": "three.module.min.js", "three/addons/controls/OrbitControls.js": "OrbitControls.js"}
        source = {name: _vendor(file) for name, file in modules.items()}
        uris = {name: data_uri(src, "text/javascript") for name, src in source.items()}
        integrity = {uris[name]: sha256_digest(src) for name, src in source.items()}
        imap = script_json({"imports": uris, "integrity": integrity})
        viewer = _asset("viewer3d.js")
        out.append(raw_text_element("script", imap, type="importmap"))
        out.append(raw_text_element("script", viewer, type="module"))
        hashes += [sha256_digest(imap), sha256_digest(viewer), *integrity.values()]
    else:
        faces = _asset("faces.js")
        out.append(raw_text_element("script", faces))
        hashes.append(sha256_digest(faces))
    if data.get("lights"):  # a spectral run's light selector
        lights = _asset("lights.js")
        out.append(raw_text_element("script", lights))
        hashes.append(sha256_digest(lights))
    return Scripts(join(out), tuple(hashes))


def content_security_policy(script_hashes, style_hashes) -> str:
    """The page's policy: nothing loads or runs but the scripts and styles of these hashes (``sha256-...``) and
    data: images; no inline event handler or style attribute, no connection, no form, no base URL."""
    sources = lambda hashes: " ".join(f"'{h}'" for h in hashes)  # noqa: E731
    return "; ".join(
        [
            "default-src 'none'",
            f"script-src {sources(script_hashes)}",
            "script-src-attr 'none'",
            f"style-src {sources(style_hashes)}",
            "style-src-attr 'none'",
            "img-src data:",
            "base-uri 'none'",
            "form-action 'none'",
        ]
    )


def page_html(
    title: str, subtitle: Markup, data: dict, view: Markup, sections: list[tuple[str, Markup]], mesh: bool
) -> Markup:
    """The whole page (``Markup``): ``data`` (pictures and geometry for the scripts) as JSON, the view section,
    then the (heading, HTML) sections."""
    s = scripts(data, mesh)
    body = join(html("<section><h2>{}</h2>{}</section>", h, part) for h, part in sections)
    credit = (
        f"3D view: three.js {THREE_VERSION} (MIT licence, Copyright 2010-2024 three.js authors), inlined."
        if mesh
        else ""
    )
    return html(
        """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta http-equiv="Content-Security-Policy" content="{policy}">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="generator" content="inkopt report"><meta name="inkopt-format-version" content="{version}">
<title>{title}</title>{style}</head>
<body><h1>{title}</h1><p class="sub">{subtitle}</p>
{view}{body}
<p class="note">Written by <code>inkopt report</code>. {credit}</p>
{scripts}</body></html>
""",
        policy=content_security_policy(s.hashes, [sha256_digest(CSS)]),
        version=PAGE_FORMAT,
        title=title,
        style=raw_text_element("style", CSS),
        subtitle=subtitle,
        view=view,
        body=body,
        credit=credit,
        scripts=s.html,
    )
