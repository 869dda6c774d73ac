"""Tests of ``inkopt report`` (inkopt.proof) without a browser: the page is self-contained, carries the run's own
figures, refuses missing or stale predictions in one line, and the mesh atlas shows the texel under each point."""

import json
import subprocess
import sys
from html.parser import HTMLParser

import numpy as np
import pytest
import trimesh

from inkopt.proof.bake import mesh_atlas
from inkopt.rundir import Predictions, RunDir

INKOPT = [sys.executable, "-m", "inkopt"]


class _Links(HTMLParser):
    """Every src/href attribute value and every script's type."""

    def __init__(self):
        super().__init__()
        self.links, self.scripts = [], []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.links += [a[k] for k in ("src", "href") if a.get(k) is not None]
        if tag == "script":
            self.scripts.append(a.get("type"))


def _links(path):
    p = _Links()
    p.feed(path.read_text())
    return p


@pytest.mark.parametrize("which", ["mesh_run", "slab_run"])
def test_page_is_self_contained(which, request):
    """Every picture, script and link is inline (data: URLs) or points inside the page; the import map's
    modules are data: URLs too."""
    page = request.getfixturevalue(which) / "report.html"
    p = _links(page)
    assert p.links and all(v.startswith(("data:", "#")) for v in p.links), [v[:40] for v in p.links]
    text = page.read_text()
    if which == "mesh_run":
        assert "importmap" in p.scripts and "module" in p.scripts
        imap = text.split('<script type="importmap">', 1)[1].split("</script>", 1)[0]
        assert all(v.startswith("data:text/javascript;base64,") for v in json.loads(imap)["imports"].values())
    assert 'name="inkopt-format-version"' in text


def test_page_shows_the_runs_figures(mesh_run, slab_run):
    """The figures table holds evaluation.json's figures, and a page written before evaluation holds the
    optimisation's own (report.json)."""
    ev = json.loads((mesh_run / "evaluation.json").read_text())
    text = (mesh_run / "report.html").read_text()
    for name in ("continuous", "quantized", "surface", "extrusion"):
        m = ev[name] if name in ("continuous", "quantized") else ev["baselines"][name]
        assert f'data-fig="{name}-de76">{m["delta_e76_mean"]:.2f}<' in text
    rep = json.loads((slab_run / "report.json").read_text())
    early = (slab_run / "report_optimised.html").read_text()
    assert f'data-fig="continuous-de76">{rep["delta_e76_mean"]:.2f}<' in early and "quantized-de76" not in early
    assert "quantized-de76" in (slab_run / "report.html").read_text()


def test_predictions_hold_every_evaluated_result(mesh_run):
    pred = RunDir(mesh_run).load_predictions()
    assert pred.source == "evaluation" and list(pred.rgb) == ["continuous", "quantized", "surface", "extrusion"]
    n = len(RunDir(mesh_run).load_scene().texels)
    assert all(v.shape == (n, 3) and np.isfinite(v).all() for v in pred.rgb.values())
    assert Predictions.from_arrays(pred.arrays()).spp == pred.spp


def test_missing_or_stale_predictions_are_one_line_errors(slab_run, tmp_path):
    """Without predictions.npz, or with one rendered from another volume.npz, the report is refused in one
    line (exit 2) and nothing is written."""
    run = tmp_path / "run"
    run.mkdir()
    for f in ("report.json", "scene.npz", "volume.npz"):
        (run / f).write_bytes((slab_run / f).read_bytes())
    r = subprocess.run(INKOPT + ["report", str(run)], capture_output=True, text=True)
    assert r.returncode == 2 and "inkopt evaluate" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    pred = RunDir(slab_run).load_predictions()
    pred.volume_digest = "sha256:" + "0" * 64
    RunDir(run).save_predictions(pred)
    r = subprocess.run(INKOPT + ["report", str(run)], capture_output=True, text=True)
    assert r.returncode == 2 and "another volume.npz" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (run / "report.html").exists()


def test_atlas_shows_the_nearest_facing_texel():
    """At each triangle's centroid (looked up through its UVs), the atlas holds the texel a brute-force search
    finds nearest to the centroid's 3D point among the texels facing the triangle's way."""
    sph = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(3000, 3))
    pts /= np.linalg.norm(pts, axis=1, keepdims=True)
    atlas = mesh_atlas(sph.vertices, sph.faces, pts, pts, voxel_mm=0.05)
    uv = atlas.uv.reshape(-1, 3, 2).mean(1)
    col = np.clip((uv[:, 0] * atlas.size).astype(int), 0, atlas.size - 1)
    row = np.clip(((1 - uv[:, 1]) * atlas.size).astype(int), 0, atlas.size - 1)
    got = atlas.texel[row, col]
    tri = sph.vertices[sph.faces]
    centroid = tri.mean(1)
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    d = np.linalg.norm(centroid[:, None] - pts[None], axis=2)
    d[np.einsum("fj,ij->fi", fn, pts) <= 0] = np.inf
    # the pixel's centre lies within half a pixel of the centroid: its texel is the brute-force nearest, or
    # one about as near (ties within the pixel's reach)
    reach = 2 * atlas.pixel_mm
    best = d.min(1)
    assert np.all(d[np.arange(len(got)), got] <= best + reach)
    assert np.mean(got == d.argmin(1)) > 0.9
    assert (atlas.texel >= 0).mean() > 0.9 and atlas.positions.shape == (3 * len(sph.faces), 3)


def test_an_evaluation_of_an_earlier_quantization_is_refused(slab_run, tmp_path):
    """Quantized again after the evaluation: the page would show the earlier print's figures beside the new ink
    shares, so the report is refused in one line until the run is evaluated again."""
    import shutil

    run = tmp_path / "run"
    shutil.copytree(slab_run, run)
    assert RunDir(run).read_evaluation() is not None
    assert subprocess.run(INKOPT + ["quantize", str(run), "--seed", "5"], capture_output=True).returncode == 0
    r = subprocess.run(
        INKOPT + ["report", str(run), "--out", str(tmp_path / "page.html")], capture_output=True, text=True
    )
    assert r.returncode == 2 and "another quantized.npz" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "page.html").exists()
