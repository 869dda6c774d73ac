"""The soft-proof page in a real browser: headless Chromium (Debian's ``chromium``, or the one named by
``INKOPT_CHROMIUM``) driven by Playwright, with the network off. Skipped, with a message, where no browser or no
Playwright is found; CI installs both and requires them (.ci/run sets ``INKOPT_REQUIRE_BROWSER=1``)."""

import io
import os
import shutil

import numpy as np
import pytest
from PIL import Image

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


def _open(browser, path, hash_=""):
    """A page opened offline, and the list its console errors and uncaught exceptions go to."""
    ctx = browser.new_context(offline=True, viewport={"width": 900, "height": 700})
    page = ctx.new_page()
    errors = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("requestfailed", lambda r: errors.append(f"request failed: {r.url[:60]}"))
    page.goto(path.as_uri() + hash_)
    return page, errors


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
    assert not errors, errors


def test_pages_show_the_runs_figures(browser, mesh_run, slab_run):
    """The text the browser shows carries evaluation.json's figures."""
    import json

    for run in (mesh_run, slab_run):
        ev = json.loads((run / "evaluation.json").read_text())
        page, errors = _open(browser, run / "report.html")
        _settle(page)
        text = page.inner_text("table.figures")
        assert f"{ev['continuous']['delta_e76_mean']:.2f}" in text and f"{ev['quantized']['ssim']:.3f}" in text
        assert not errors, errors


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
    assert not errors, errors
