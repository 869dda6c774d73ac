"""The soft-proof page in a real browser: headless Chromium (Debian's ``chromium``, or the one named by
``INKOPT_CHROMIUM``) driven by Playwright, with the network off. Skipped, with a message, where no browser or no
Playwright is found; CI installs both and requires them (.ci/run sets ``INKOPT_REQUIRE_BROWSER=1``)."""

import io
import os
import shutil

import numpy as np
import pytest
from PIL import Image
from proof.payloads import FILE_PAYLOADS

BROWSER = os.environ.get("INKOPT_CHROMIUM") or next(
    (p for n in ("chromium", "chromium-browser", "google-chrome") if (p := shutil.which(n))), None
)
if os.environ.get("INKOPT_REQUIRE_BROWSER") == "1":  # CI: a missing browser is a failure, not a skip
    import playwright.sync_api as pw

    assert BROWSER is not None, "INKOPT_REQUIRE_BROWSER=1 but no Chromium found"
else:
    pw = pytest.importorskip("playwright.sync_api", reason="Playwright is not installed (pip install playwright)")
pytestmark = pytest.mark.skipif(
    BROWSER is None,
    reason="no Chromium found (apt-get install chromium, or set INKOPT_CHROMIUM): browser tests skipped",
)
# WebGL without a GPU: Chromium's software rasterizer
ARGS = ["--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--no-sandbox"]


@pytest.fixture(scope="module")
def browser():
    with pw.sync_playwright() as p:
        b = p.chromium.launch(executable_path=BROWSER, args=ARGS)
        yield b
        b.close()


# every Content-Security-Policy violation (a script, style, image or connection the page's policy refused)
WATCH_CSP = """window.__csp = [];
document.addEventListener('securitypolicyviolation', (e) =>
  window.__csp.push(e.violatedDirective + ' ' + (e.blockedURI || '').slice(0, 40) + ' ' + (e.sample || '')));"""


def _open(browser, path, hash_=""):
    """A page opened offline, and the list its console errors, uncaught exceptions, failed requests and dialogs
    (alert, confirm, ...: dismissed) go to; ``_problems`` adds the policy's violations."""
    ctx = browser.new_context(offline=True, viewport={"width": 900, "height": 700})
    page = ctx.new_page()
    errors = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("requestfailed", lambda r: errors.append(f"request failed: {r.url[:60]}"))
    page.on("dialog", lambda d: (errors.append(f"dialog {d.type}: {d.message}"), d.dismiss()))
    page.add_init_script(WATCH_CSP)
    page.goto(path.as_uri() + hash_)
    return page, errors


def _problems(page, errors) -> list[str]:
    """The console errors, failed requests and dialogs so far, and the policy's violations."""
    return errors + [f"CSP violation: {v}" for v in page.evaluate("window.__csp")]


def _pixels(page, selector) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(page.locator(selector).screenshot())).convert("RGB"), np.float64)


def _settle(page):
    """Wait until the textures have loaded and the view has been drawn again (two animation frames)."""
    page.wait_for_load_state("load")
    page.wait_for_timeout(300)
    page.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")


def test_mesh_page_draws_and_switches(browser, mesh_run):
    """#3d opens the 3D view full-window; the canvas draws the object (pixels that are not the white
    background); showing another result changes the picture; no console errors."""
    page, errors = _open(browser, mesh_run / "report.html", "#3d")
    page.wait_for_selector("#view3d[data-ready='1']", timeout=20000)
    _settle(page)
    assert page.evaluate("document.body.classList.contains('full3d')")
    assert page.locator("#stage3d .needs").is_hidden()  # the note shown where the view does not start
    box = page.locator("#stage3d").bounding_box()
    assert box["width"] >= 880 and box["height"] >= 500  # most of the 900 x 700 window
    a = _pixels(page, "#stage3d")
    drawn = np.any(np.abs(a - 255) > 8, axis=2)
    assert drawn.mean() > 0.02, drawn.mean()  # the ball fills a good part of the view, not a blank canvas
    page.select_option("#other3d", "")
    page.select_option("#pick3d", "target")
    _settle(page)
    t = _pixels(page, "#stage3d")
    page.check("#heat3d")
    page.select_option("#pick3d", "surface")
    _settle(page)
    h = _pixels(page, "#stage3d")
    assert page.evaluate("document.body.dataset.view") == "heat:surface"
    assert np.abs(h - t)[drawn].mean() > 5 and np.abs(a - t)[drawn].mean() > 1
    assert not _problems(page, errors), _problems(page, errors)


def test_pages_show_the_runs_figures(browser, mesh_run, slab_run):
    """The text the browser shows carries evaluation.json's figures."""
    import json

    for run in (mesh_run, slab_run):
        ev = json.loads((run / "evaluation.json").read_text())
        page, errors = _open(browser, run / "report.html")
        _settle(page)
        text = page.inner_text("table.figures")
        assert f"{ev['continuous']['delta_e76_mean']:.2f}" in text and f"{ev['quantized']['ssim']:.3f}" in text
        assert not _problems(page, errors), _problems(page, errors)


def test_slab_page_swipes(browser, slab_run):
    """Each face's two pictures load; moving the swipe line and switching to the heat map change the picture."""
    page, errors = _open(browser, slab_run / "report.html")
    _settle(page)
    face = page.locator("#face-top")
    assert page.evaluate("[...document.images].every(i => i.complete && i.naturalWidth > 0)")
    a = _pixels(page, "#face-top .swipe")
    face.locator("input[type=range]").fill("10")
    _settle(page)
    b = _pixels(page, "#face-top .swipe")
    face.locator("input[type=checkbox]").check()
    _settle(page)
    c = _pixels(page, "#face-top .swipe")
    assert face.get_attribute("data-view") == "heat:target|quantized"
    assert np.abs(a - b).mean() > 0.5 and np.abs(b - c).mean() > 5
    assert not _problems(page, errors), _problems(page, errors)


def _hostile_run(which, request):
    if which.startswith("planted-"):
        return request.getfixturevalue("planted_runs")[which.split("-")[1]]
    return request.getfixturevalue(which)


@pytest.mark.parametrize("which", ["hostile_slab_run", "hostile_mesh_run", "planted-slab", "planted-mesh"])
def test_planted_script_does_not_run(browser, which, request):
    """The pages of test_hostile.py in Chromium: no dialog opens, no element a payload would make exists, the
    policy refuses nothing (nothing tried to run) and the view works: the 3D view draws and shows the result named
    by a payload, the slab's pictures load."""
    run = _hostile_run(which, request)
    page, errors = _open(browser, run / "report.html")
    _settle(page)
    if page.locator("#view3d").count():
        page.wait_for_selector("#view3d[data-ready='1']", timeout=20000)
        drawn = np.any(np.abs(_pixels(page, "#stage3d") - 255) > 8, axis=2)
        assert drawn.mean() > 0.01, drawn.mean()
        if which.startswith("planted"):
            page.select_option("#pick3d", FILE_PAYLOADS[2])
            page.select_option("#other3d", "")
            _settle(page)
            assert page.evaluate("document.body.dataset.view") == FILE_PAYLOADS[2]
    else:
        assert page.evaluate("[...document.images].every(i => i.complete && i.naturalWidth > 0)")
        face = page.locator(".face").first
        assert face.get_attribute("data-view") == "target|quantized"
        assert face.evaluate("e => e.style.getPropertyValue('--w')") == "384px"  # 24 texels x 16
    page.wait_for_timeout(300)  # events of elements a payload made (load, error, toggle) have fired
    assert page.evaluate("document.querySelectorAll('[pwn], pwn').length") == 0
    assert not _problems(page, errors), _problems(page, errors)


def test_policy_refuses_script_that_got_in(browser, slab_run, tmp_path):
    """The policy is the second line: markup inserted into a written page (an inline script, an event handler, a
    data: script, a style attribute) does not run, and the browser reports each as a violation."""
    text = (slab_run / "report.html").read_text()
    planted = (
        "<script>alert(1)</script><img src=x onerror=alert(2)><script src='data:text/javascript,alert(3)'></script>"
        "<p id=styled style='color:red'>x</p>"
    )
    path = tmp_path / "report.html"
    path.write_text(text.replace("</body>", planted + "</body>"))
    page, errors = _open(browser, path)
    _settle(page)
    assert not [e for e in errors if e.startswith("dialog")]
    seen = " ".join(page.evaluate("window.__csp"))
    assert all(d in seen for d in ("script-src-elem", "script-src-attr", "style-src-attr")), seen
    assert page.evaluate("getComputedStyle(document.getElementById('styled')).color") != "rgb(255, 0, 0)"


def test_view_that_cannot_start_says_so(browser, mesh_run, tmp_path):
    """Where the browser does not run the view (here: the vendored modules altered, so that their integrity and
    the policy refuse them), the stage says what the view needs after a few seconds."""
    text = (mesh_run / "report.html").read_text()
    path = tmp_path / "report.html"
    path.write_text(
        text.replace('"three":"data:text/javascript;base64,', '"three":"data:text/javascript;base64,Ly8K', 1)
    )
    page, errors = _open(browser, path)
    page.wait_for_selector("#stage3d .needs", state="visible", timeout=10000)
    assert not page.evaluate("document.getElementById('view3d').dataset.ready")


def test_spectral_slab_page_switches_the_light(browser, spectral_slab_run):
    """The light selector changes every face's pictures and shows that light's figures table only; the heat map
    follows the light too; nothing is refused or fails."""
    page, errors = _open(browser, spectral_slab_run / "report.html")
    _settle(page)
    face = page.locator("#face-top")
    face.locator("select").nth(1).select_option("continuous")
    face.locator("input[type=range]").fill("0")  # the right picture (the continuous result) everywhere
    _settle(page)
    a, src = _pixels(page, "#face-top .swipe"), face.locator("img.top").get_attribute("src")
    assert (
        page.locator("div[data-light-table='0']").is_visible() and page.locator("div[data-light-table='3']").is_hidden()
    )
    page.select_option("#light", "3")  # A
    _settle(page)
    b = _pixels(page, "#face-top .swipe")
    assert face.get_attribute("data-light") == "3" and page.evaluate("document.body.dataset.light") == "3"
    assert (
        page.locator("div[data-light-table='3']").is_visible() and page.locator("div[data-light-table='0']").is_hidden()
    )
    assert face.locator("img.top").get_attribute("src") != src
    assert np.abs(a - b).mean() > 0.5, np.abs(a - b).mean()  # adapted to each light's white: a small change
    face.locator("input[type=checkbox]").check()
    _settle(page)
    h3 = _pixels(page, "#face-top .swipe")
    page.select_option("#light", "0")
    _settle(page)
    h0 = _pixels(page, "#face-top .swipe")
    assert np.abs(h3 - h0).mean() > 0.5, np.abs(h3 - h0).mean()
    assert page.evaluate("[...document.images].every(i => i.complete && i.naturalWidth > 0)")
    assert page.evaluate("document.querySelectorAll('[pwn], pwn').length") == 0
    assert not _problems(page, errors), _problems(page, errors)


def test_spectral_mesh_page_switches_the_light(browser, spectral_mesh_run):
    """The 3D view draws the continuous result under D65 and redraws it under A when the light changes."""
    page, errors = _open(browser, spectral_mesh_run / "report.html")
    page.wait_for_selector("#view3d[data-ready='1']", timeout=20000)
    page.select_option("#other3d", "")
    page.select_option("#pick3d", "continuous")
    _settle(page)
    a = _pixels(page, "#stage3d")
    drawn = np.any(np.abs(a - 255) > 8, axis=2)
    assert drawn.mean() > 0.02, drawn.mean()
    page.select_option("#light", "1")
    _settle(page)
    b = _pixels(page, "#stage3d")
    assert page.evaluate("document.body.dataset.light") == "1"
    assert np.abs(a - b)[drawn].mean() > 1, np.abs(a - b)[drawn].mean()
    assert not _problems(page, errors), _problems(page, errors)


def test_planted_light_names_do_not_run(browser, planted_spectral_run):
    """Lights named by payloads: switching to each shows its pictures and table, and nothing a payload would make
    exists or ran."""
    page, errors = _open(browser, planted_spectral_run / "report.html")
    _settle(page)
    for i in range(6):
        page.select_option("#light", str(i))
        _settle(page)
        assert page.locator(f"div[data-light-table='{i}']").is_visible()
        assert page.evaluate("[...document.images].every(i => i.complete && i.naturalWidth > 0)")
    page.wait_for_timeout(300)
    assert page.evaluate("document.querySelectorAll('[pwn], pwn').length") == 0
    assert not _problems(page, errors), _problems(page, errors)


@pytest.mark.parametrize("kind", ["mesh", "slab"])
def test_budget_page_loads(browser, budget_pages, kind):
    """A page written within a small budget (``--max-mb``: smaller pictures) opens: the 3D view draws the object
    and switches to a heat map, or every face picture loads; nothing fails or is refused."""
    path = budget_pages[kind][0]
    page, errors = _open(browser, path, "#3d" if kind == "mesh" else "")
    if kind == "mesh":
        page.wait_for_selector("#view3d[data-ready='1']", timeout=20000)
        _settle(page)
        a = _pixels(page, "#stage3d")
        drawn = np.any(np.abs(a - 255) > 8, axis=2)
        assert drawn.mean() > 0.02, drawn.mean()
        page.check("#heat3d")
        _settle(page)
        assert np.abs(_pixels(page, "#stage3d") - a)[drawn].mean() > 5
    else:
        _settle(page)
        assert page.evaluate("[...document.images].every(i => i.complete && i.naturalWidth > 0)")
        assert page.locator("#faces p.note").inner_text().count("downsampled") == 1
    assert not _problems(page, errors), _problems(page, errors)
