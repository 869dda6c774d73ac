"""The soft proof of a spectral run: every light the run or its evaluation asked and D65 and A, each light's
pictures and figures computed from predictions.npz's band values when the page is written, a light named by a
payload shown as text."""

import base64
import io
import json

import numpy as np
from PIL import Image
from proof.payloads import FILE_PAYLOADS
from proof.test_hostile import _text, check_page

from inkopt.color import ColourMap, delta_e2000, linear_to_lab
from inkopt.proof.bake import srgb8
from inkopt.rundir import RunDir
from inkopt.spectral.lights import named_light
from inkopt.spectral.viewing import display_under


def _data(run):
    page = check_page(run / "report.html")
    return page, json.loads(next(s for a, s in page.scripts if a.get("type") == "application/json"))


def _png(uri: str) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(uri.split(",", 1)[1]))).convert("RGB"))


def test_slab_page_offers_every_light_with_its_own_pictures(spectral_slab_run):
    """Lights: the evaluation's (D65, the payload file, F11) then A; each light's picture of the continuous result
    is its stored bands under that light, Bradford-adapted, and its figures table's mean ΔE2000 is the one from the
    stored bands (and evaluate's)."""
    page, data = _data(spectral_slab_run)
    light_file = f"{FILE_PAYLOADS[0]}.csv"
    assert data["lights"] == ["D65", light_file, "F11", "A"]
    d = RunDir(spectral_slab_run)
    pred, rec = d.load_predictions(), d.load_scene()
    face = data["slab"]["faces"][0]
    pix = rec.pix[face["name"]]
    assert len(face["by_light"]) == 4 and face["by_light"][0] == {}
    bands = pred.bands.values["continuous"]
    target_lab = linear_to_lab(rec.target_rgb.astype(np.float64))
    maps = [ColourMap(pred.bands.lights[n], n) for n in data["lights"][:3]]
    maps.append(named_light("A").colour_map(pred.bands.wavelengths_nm))
    pictures = [face["pictures"]["continuous"]] + [b["pictures"]["continuous"] for b in face["by_light"][1:]]
    for cmap, uri in zip(maps, pictures):
        want = srgb8(display_under(cmap, bands))[pix]
        assert np.abs(_png(uri).astype(int) - want).max() <= 0  # PNG: lossless
    assert np.abs(_png(pictures[0]).astype(int) - _png(pictures[3])).mean() > 1  # D65 and A differ
    ev = json.loads(d.evaluation_lights_path.read_text())
    text = _text(page)
    for cmap in maps:
        de = float(delta_e2000(cmap.lab(bands), target_lab).mean())
        assert f"{de:.2f}" in text
        if cmap.name in ev["continuous"]["by_light"]:
            assert abs(de - ev["continuous"]["by_light"][cmap.name]["delta_e2000_mean"]) < 1e-3
    options = [a.get("value") for t, a in page.tags if t == "option"]
    assert [o for o in options if o in {"0", "1", "2", "3"}] == ["0", "1", "2", "3"]
    assert light_file in text and f"under {light_file}: ΔE" in text  # a payload-named light: text, not markup


def test_mesh_page_switches_textures(spectral_mesh_run):
    """An optimised (not evaluated) spectral mesh: its run's lights D65 and A, a texture per result and light."""
    _, data = _data(spectral_mesh_run)
    assert data["lights"] == ["D65", "A"]
    by = data["mesh"]["by_light"]
    assert len(by) == 2 and set(by[1]["textures"]) == {"continuous"} and set(by[1]["heat"]) == {"continuous"}
    assert by[1]["textures"]["continuous"] != data["mesh"]["textures"]["continuous"]


def test_planted_light_names_stay_text(planted_spectral_run):
    """predictions.npz's light names replaced by payloads (and a name JavaScript objects hold): the page shows
    them as text, its data and options carry them as data, and its scripts admit nothing else."""
    from proof.conftest import PLANTED_LIGHTS

    page, data = _data(planted_spectral_run)
    assert data["lights"] == [*PLANTED_LIGHTS, "D65", "A"]
    text = _text(page)
    assert all(f"under {n}: ΔE" in text for n in PLANTED_LIGHTS)
    options = [a.get("value") for t, a in page.tags if t == "option"]
    assert [o for o in options if o.isdigit()] == [str(i) for i in range(6)]
