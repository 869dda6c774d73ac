"""The soft-proof page's size budget (``inkopt report --max-mb``, ``proof.ProofOptions``): a page over it is
written with smaller pictures and within it, keeps every result and light, says that its pictures are
downsampled, and holds no markup from its files; a budget that cannot hold the page is refused in one line. The
same pages in Chromium: test_browser.py."""

import json
import subprocess
import sys

import pytest
from proof.conftest import picture_bytes
from proof.payloads import PAYLOADS
from proof.test_hostile import check_page

from inkopt.errors import ParameterError
from inkopt.proof import ProofOptions, write_proof
from inkopt.proof.bake import MIN_CELL
from inkopt.proof.budget import JPEG_QUALITY, MIN_QUALITY, next_mesh_choice

INKOPT = [sys.executable, "-m", "inkopt"]


def _data(path) -> dict:
    text = path.read_text()
    return json.loads(text.split('id="inkopt-data">', 1)[1].split("</script>", 1)[0])


@pytest.mark.parametrize("kind", ["mesh", "slab"])
def test_page_over_the_budget_is_written_within_it(kind, budget_pages):
    """The large run's page is over the budget as the page would choose its pictures; written with the budget it is
    within it, with every result's pictures and heat maps, says that its pictures are downsampled, and passes
    test_hostile's check (no tag, attribute, comment or script but the page's own)."""
    path, budget, full = budget_pages[kind]
    assert full > budget  # the budget does act
    assert path.stat().st_size <= budget
    assert picture_bytes(path) > 0
    data = _data(path)
    results = data["results"]
    if kind == "mesh":
        view = data["mesh"]
        assert list(view["textures"]) == results and list(view["heat"]) == [k for k in results if k != "target"]
    else:
        for face in data["slab"]["faces"]:
            assert list(face["pictures"]) == results and len(face["heat"]) == len(results) - 1
    text = path.read_text()
    assert "downsampled" in text and "MB budget" in text
    check_page(path)


def test_report_line_says_how_the_budget_reduced_the_pictures(mesh_run, tmp_path):
    """The command's line names the budget and the atlas it chose; within the default budget the page is not
    reduced."""
    full = mesh_run / "report.html"
    budget = full.stat().st_size - picture_bytes(full) // 2
    out = tmp_path / "page.html"
    cmd = INKOPT + ["report", str(mesh_run), "--out", str(out), "--max-mb", str(budget / 1e6)]
    r = subprocess.run(cmd, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "reduced to stay within --max-mb" in r.stdout and "atlas" in r.stdout and "JPEG quality" in r.stdout
    assert out.stat().st_size <= budget
    p = write_proof(mesh_run, tmp_path / "default.html")
    assert not p.reduced and p.quality == JPEG_QUALITY and p.max_mb == ProofOptions().max_mb


def test_spectral_page_keeps_every_light(spectral_mesh_run, tmp_path):
    """A spectral run's page within a budget that reduces its pictures still has every light's textures and heat
    maps."""
    full = spectral_mesh_run / "report.html"
    budget = full.stat().st_size - picture_bytes(full) // 2
    p = write_proof(spectral_mesh_run, tmp_path / "page.html", ProofOptions(max_mb=budget / 1e6))
    assert p.reduced and p.bytes <= budget
    data = _data(tmp_path / "page.html")
    assert len(data["mesh"]["by_light"]) == len(data["lights"]) == len(_data(full)["lights"]) >= 2
    for entry in data["mesh"]["by_light"][1:]:
        assert set(entry["textures"]) == {k for k in data["results"] if k != "target"} and entry["heat"]


@pytest.mark.parametrize("which", ["large_mesh_run", "large_slab_run"])
def test_budget_too_small_is_a_one_line_error(which, request, tmp_path):
    """A budget below the page's parts other than its pictures is refused in one line naming --max-mb, and nothing
    is written; so is a budget that is not a positive number."""
    run = request.getfixturevalue(which)
    out = tmp_path / "page.html"
    for mb in ("0.01", "-1"):
        r = subprocess.run(
            INKOPT + ["report", str(run), "--out", str(out), "--max-mb", mb], capture_output=True, text=True
        )
        assert r.returncode == 2 and "--max-mb" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert not out.exists()


def test_options_name_their_parameter():
    with pytest.raises(ParameterError) as e:
        ProofOptions(max_mb=0)
    assert e.value.parameters == ("max_mb",)
    with pytest.raises(ParameterError):
        ProofOptions(max_mb=float("nan"))


def test_mesh_choices_shrink_to_the_smallest():
    """From the page's own atlas, the choices lose pixels at full quality down to one pixel per texel, then
    quality, then pixels again, each smaller than the last, and end at the smallest cell and quality."""
    cell, quality, one = 39, JPEG_QUALITY, 12
    seen = [(cell, quality)]
    while (nxt := next_mesh_choice(cell, quality, 0.5, one)) is not None:
        assert nxt[0] < cell or nxt[1] < quality
        assert nxt[0] <= cell and nxt[1] <= quality
        if nxt[1] < JPEG_QUALITY:
            assert nxt[0] <= one  # quality falls only once the atlas is at one pixel per texel
        cell, quality = nxt
        seen.append(nxt)
    assert seen[-1] == (MIN_CELL, MIN_QUALITY) and (one, JPEG_QUALITY) in seen
    assert next_mesh_choice(20, JPEG_QUALITY, 0.01, one) == (one, JPEG_QUALITY)  # not below one pixel per texel


@pytest.mark.parametrize("kind", ["slab", "mesh"])
def test_planted_page_within_a_budget(planted_runs, kind, tmp_path):
    """The runs with a payload in every field of their files, written within a budget that reduces their
    pictures: still only the page's own markup, every payload as text."""
    full = planted_runs[kind] / "report.html"
    budget = full.stat().st_size - picture_bytes(full) // 2
    p = write_proof(planted_runs[kind], tmp_path / "page.html", ProofOptions(max_mb=budget / 1e6))
    assert p.reduced and p.bytes <= budget
    text = "".join(check_page(tmp_path / "page.html").text)
    assert all(s in text for s in PAYLOADS), [s for s in PAYLOADS if s not in text]
