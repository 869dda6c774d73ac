"""The soft-proof page itself: one self-contained HTML file. Scripts, pictures and data are inlined (data: URLs
and inline scripts), so the page opens without network access and can be sent on its own. The 3D view uses
three.js, vendored in ``vendor/`` (its version in ``THREE_VERSION``, its licence beside it) and handed to the
page's module script through an import map of data: URLs."""

from __future__ import annotations

import base64
import json
from html import escape
from importlib import resources

from .figures import LABELS

THREE_VERSION = "0.170.0"  # python/inkopt/proof/vendor/: three.module.min.js, OrbitControls.js, LICENSE-three.txt
PAGE_FORMAT = 1  # the page's format_version (in its data block and a meta tag)

CSS = """
body{font:14px/1.4 system-ui,sans-serif;margin:0 auto;max-width:1100px;padding:0 16px 40px;color:#222}
h1{font-size:22px;margin:18px 0 4px}h2{font-size:17px;margin:26px 0 8px;border-bottom:1px solid #ddd}
.sub{color:#555;margin:0 0 10px}.note{color:#555;font-size:12.5px}
table{border-collapse:collapse;margin:6px 0}td,th{padding:3px 9px;border-bottom:1px solid #e5e5e5;text-align:right}
td:first-child,th:first-child{text-align:left}th{font-weight:600;background:#f6f6f6}
.swatch{display:inline-block;width:12px;height:12px;border:1px solid #999;margin-right:6px;vertical-align:-1px}
dl{display:grid;grid-template-columns:max-content auto;gap:3px 14px}dt{font-weight:600}dd{margin:0}
.bar{display:flex;flex-wrap:wrap;gap:8px 14px;align-items:center;margin:6px 0}
#view3d{position:relative}#stage3d{position:relative;height:560px;border:1px solid #ddd;background:#fff}
#stage3d canvas{display:block;touch-action:none}
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


def _options(keys: list[str], selected: str, none: str | None = None) -> str:
    opts = [f'<option value="">{escape(none)}</option>'] if none is not None else []
    opts += [
        f'<option value="{k}"{" selected" if k == selected else ""}>{escape(LABELS.get(k, k))}</option>' for k in keys
    ]
    return "".join(opts)


def _legend(legend_uri: str, scale: float) -> str:
    return (
        f'<span class="legend">ΔE76 0 <img alt="heat scale" src="{legend_uri}"> {scale:.0f}+ '
        "(magma, shared by all results)</span>"
    )


def mesh_section(keys: list[str], legend_uri: str, scale: float, note: str) -> str:
    """The 3D view: result picker, swipe partner, heat toggle, full-window link and the canvas."""
    first = "quantized" if "quantized" in keys else "continuous"
    return f"""
<section id="3d"><div id="view3d">
<div class="bar"><label>show <select id="pick3d">{_options(keys, first)}</select></label>
<label>swipe against <select id="other3d">{_options(keys, "target", "(nothing)")}</select></label>
<input id="swipe3d" type="range" min="0" max="100" value="50" aria-label="swipe position">
<label><input id="heat3d" type="checkbox"> ΔE76 heat map</label>{_legend(legend_uri, scale)}
<a href="#3d">full window</a> <a href="#">back</a></div>
<div id="stage3d"><div id="line3d" class="line"></div></div>
<p class="note">Drag to turn, wheel or pinch to zoom, right-drag to pan. {note}</p>
</div></section>"""


def slab_section(faces: list[dict], keys: list[str], legend_uri: str, scale: float, zoom: int) -> str:
    """Every textured face of a slab: two results with a swipe line, and the heat-map toggle."""
    out = ['<section id="faces"><h2>Faces</h2>']
    second = "quantized" if "quantized" in keys else "continuous"
    for f in faces:
        w = f["width"] * zoom
        out.append(
            f"""<div class="face" id="face-{f["name"]}" style="--w:{w}px"><h3>{escape(f["name"])} face</h3>
<div class="bar"><label>left <select>{_options(keys, "target")}</select></label>
<label>right <select>{_options(keys, second)}</select></label>
<label><input type="checkbox"> ΔE76 heat map</label></div>
<div class="swipe"><img class="layer" alt="left"><img class="layer top" alt="right">
<div class="line"></div></div>
<div class="bar"><input type="range" min="0" max="100" value="50" aria-label="swipe position"></div></div>"""
        )
    out.append(f"<div>{_legend(legend_uri, scale)}</div></section>")
    return "".join(out)


def page_html(title: str, subtitle: str, data: dict, view: str, sections: list[tuple[str, str]], mesh: bool) -> str:
    """The whole page: ``data`` (pictures and geometry for the scripts) as JSON, the view section, then the
    (heading, HTML) sections."""
    data = {"format_version": PAGE_FORMAT, **data}
    blob = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")
    scripts = f'<script type="application/json" id="inkopt-data">{blob}</script>'
    if mesh:
        imports = {
            "three": data_uri(_vendor("three.module.min.js"), "text/javascript"),
            "three/addons/controls/OrbitControls.js": data_uri(_vendor("OrbitControls.js"), "text/javascript"),
        }
        scripts += f'<script type="importmap">{json.dumps({"imports": imports})}</script>'
        scripts += f'<script type="module">{_asset("viewer3d.js")}</script>'
    else:
        scripts += f"<script>{_asset('faces.js')}</script>"
    body = "".join(f"<section><h2>{escape(h)}</h2>{html}</section>" for h, html in sections)
    credit = (
        f"3D view: three.js {THREE_VERSION} (MIT licence, Copyright 2010-2024 three.js authors), inlined."
        if mesh
        else ""
    )
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="generator" content="inkopt report"><meta name="inkopt-format-version" content="{PAGE_FORMAT}">
<title>{escape(title)}</title><style>{CSS}</style></head>
<body><h1>{escape(title)}</h1><p class="sub">{subtitle}</p>
{view}{body}
<p class="note">Written by <code>inkopt report</code>. {credit}</p>
{scripts}</body></html>
"""
