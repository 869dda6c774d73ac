"""Tests of inkopt.evaluation.evaluate: printer->scene texel maps, averaging, pictures, and a full synthetic run
directory."""

import json
import tracemalloc
from dataclasses import replace

import numpy as np
import pytest
from PIL import Image
from slab_run import make_run

import inkopt.evaluation.evaluate as evaluate_mod
import inkopt.evaluation.printed as printed_mod
import inkopt.model.texels as texels_module
from inkopt.cli.common import flag_of
from inkopt.color import linear_to_srgb
from inkopt.errors import ParameterError
from inkopt.evaluation.evaluate import evaluate_run
from inkopt.evaluation.noise import MAX_SPP, PILOT_SPP, TARGET_NOISE_DE76
from inkopt.evaluation.options import EvaluateOptions
from inkopt.evaluation.outputs import table_lines
from inkopt.evaluation.printed import PrintedRenderer, average_to_scene, map_texels, printer_texels
from inkopt.evaluation.results import Evaluation
from inkopt.io import save_npz
from inkopt.model import InkTable, Quantization, Texels, Volume
from inkopt.pictures import panels
from inkopt.printing.dither import lightness_order
from inkopt.printing.quantize import _enclosing, printer_grid, quantize
from inkopt.printing.stream import quantize_run
from inkopt.rundir import RunDir

V300 = 25.4 / 300
INKS3 = InkTable.from_names(["cyan", "magenta", "white"])
SHAPE = (6, 16, 24)


def test_map_texels_is_the_enclosing_voxel_map():
    """Each printer texel maps to the scene texel whose voxel encloses it (the quantizer's own map), on all six
    faces of a box; every scene texel gets printer texels, so no stand-ins."""
    shape = (5, 7, 9)
    vo = np.array([V300] * 3)
    shape_p, vp = printer_grid(shape, vo)
    scene = Texels.box_faces(shape)
    printer = Texels.box_faces(shape_p)
    to_scene, stand_in = map_texels(printer, vp, scene, vo)
    enc = [_enclosing(shape_p[a], vp[2 - a], shape[a], vo[2 - a]) for a in range(3)]  # z, y, x
    expect_voxel = np.stack([enc[a][printer.voxel[:, a]] for a in range(3)], 1)
    np.testing.assert_array_equal(scene.voxel[to_scene], expect_voxel)
    np.testing.assert_array_equal(scene.face[to_scene], printer.face)
    assert np.all(stand_in == -1)
    # a coarser printer grid than the scene (x): some scene texels get none and take their nearest printer texel
    shape_p, vp = printer_grid(shape, vo, dpi=(150, 300))
    printer = Texels.box_faces(shape_p, ["top"])
    scene = Texels.box_faces(shape, ["top"])
    to_scene, stand_in = map_texels(printer, vp, scene, vo)
    missing = np.setdiff1d(np.arange(len(scene)), to_scene)
    assert len(missing) > 0 and np.all(stand_in[missing] >= 0)
    ps, pp = scene.position_mm(vo)[missing], printer.position_mm(vp)
    d = np.linalg.norm(ps - pp[stand_in[missing]], axis=1)
    brute = np.linalg.norm(ps[:, None] - pp[None], axis=2).min(1)  # the stand-in is the nearest printer texel
    np.testing.assert_allclose(d, brute, atol=1e-12)


def test_average_to_scene_matches_loop():
    rng = np.random.default_rng(0)
    to_scene = rng.integers(0, 6, 40)
    to_scene[to_scene == 4] = 5  # scene texel 4 gets nothing
    stand_in = np.full(6, -1)
    stand_in[4] = 7
    rgb_p, var_p = rng.random((40, 3)), rng.random((40, 3))
    rgb, var = average_to_scene(rgb_p, var_p, to_scene, stand_in, 6)
    for i in range(6):
        sel = to_scene == i
        if i == 4:
            np.testing.assert_allclose(rgb[i], rgb_p[7])
            np.testing.assert_allclose(var[i], var_p[7])
        else:
            np.testing.assert_allclose(rgb[i], rgb_p[sel].mean(0))
            np.testing.assert_allclose(var[i], var_p[sel].sum(0) / sel.sum() ** 2)


def test_panels_layout():
    pix = np.arange(12).reshape(3, 4)[::-1]
    a = np.random.default_rng(1).random((12, 3))
    img = np.asarray(panels([("one", a), ("two", a * 0.5)], pix))
    s = 64  # 4 px wide -> x64 to reach 256
    assert img.shape[1] == 2 * 4 * s + 3 * 8
    band = 20
    for j, col in enumerate([a, a * 0.5]):
        x0 = 8 + j * (4 * s + 8)
        got = img[band + s // 2, x0 + s // 2]  # pixel (row 0, col 0) of the panel
        expect = np.round(np.clip(linear_to_srgb(col[pix[0, 0]]), 0, 1) * 255)
        np.testing.assert_array_equal(got, expect)
    assert np.any(img[:band] < 128)  # the label text


def test_evaluate_run_synthetic(tmp_path, table3):
    vol, scene = make_run(tmp_path / "run", table3, "extrusion")
    ev = evaluate_run(tmp_path / "run", EvaluateOptions(spp=8, table=table3))
    disk = json.loads((tmp_path / "run" / "evaluation.json").read_text())
    assert disk == json.loads(json.dumps(ev.to_json())) and disk["format_version"] == 2
    assert Evaluation.read(tmp_path / "run" / "evaluation.json") == ev  # the typed round trip
    del disk["format_version"]  # a file written before files carried a version (0) reads the same
    assert Evaluation.from_json(disk) == ev
    keys = {"delta_e76_mean", "delta_e76_p95", "delta_e2000_mean", "ssim", "spp", "seconds", "method"}
    for entry in (disk["continuous"], disk["quantized"], disk["baselines"]["surface"], disk["baselines"]["extrusion"]):
        assert keys <= set(entry)
        assert all(np.isfinite(entry[k]) for k in keys - {"method"})
        assert 0 <= entry["delta_e76_mean"] <= entry["delta_e76_p95"] + 1e-9 and -1 <= entry["ssim"] <= 1
    assert disk["quantized"]["method"] == "count-adaptive" and (tmp_path / "run" / "quantized.npz").is_file()
    # the run's mixture is the extrusion baseline: quantized the same way and rendered with the same seed it
    # is bit-identical, so its figures equal ours exactly
    for k in ("delta_e76_mean", "delta_e76_p95", "delta_e2000_mean", "ssim"):
        assert disk["baselines"]["extrusion"][k] == disk["quantized"][k]
    # quantization changes the look little on uniform columns: the ΔE of the printed and continuous results
    # agree within the Monte Carlo noise of a texel's colour (both are means over 384 texels of ~8 spp each;
    # 3x the per-texel noise level is a generous bound on the difference of the means plus the dither error)
    c, q = disk["continuous"], disk["quantized"]
    assert abs(q["delta_e76_mean"] - c["delta_e76_mean"]) < 3 * max(c["delta_e76_noise"], q["delta_e76_noise"])
    assert q["spp_printer"] == 4  # 2 printer texels per scene texel on top at 600 x 300 DPI share the 8 spp
    with Image.open(tmp_path / "run" / "evaluation_top.png") as im:
        assert im.size[0] >= 5 * 256 and disk["pictures"] == ["evaluation_top.png"]
    assert disk["spp"] == 8 and not disk["spp_adaptive"] and c["spp_passes"] == [8]  # explicit spp: exact
    floor = disk["gamut_floor_delta_e76"]  # the baselines reach the table's colours: none is better than the floor
    assert 0 <= floor <= min(b["delta_e76_mean_corrected"] for b in disk["baselines"].values()) + 1


def test_printed_results_hold_no_printer_grid_array(tmp_path, table3, monkeypatch):
    """From the first printer-resolution render to the last, the traced (numpy) memory holds layer-sized
    temporaries and per-texel arrays, nothing per printer voxel: the labels are read from their layered files and
    the core keeps them by bricks (untraced, and per brick near the surface). A printer label grid (1 byte per
    printer voxel), an inside mask of it, a baseline's whole (z, y, x, N) float32 mixture (12 bytes per
    optimisation voxel, ~1.9 per printer voxel here) or any printer-resolution float array would break the bound
    below."""
    shape = (200, 40, 40)  # deep, textured on top: the printer grid (2.0 M voxels) dominates the texels (3200)
    vol, _ = make_run(tmp_path / "run", table3, "extrusion", shape)
    quantize_run(RunDir(tmp_path / "run"), Quantization())  # as `inkopt quantize` leaves it
    start, end = [], []
    quantized, loss = evaluate_mod._quantized_volume, evaluate_mod.TexelLoss

    def load_quantized(*a, **kw):  # the window opens where the printed results begin, before their labels load ...
        tracemalloc.reset_peak()
        start.append(tracemalloc.get_traced_memory()[0])
        return quantized(*a, **kw)

    def loss_after_renders(*a, **kw):  # ... and closes when the figures begin (the loss is texel-sized)
        end.append(tracemalloc.get_traced_memory()[1])
        return loss(*a, **kw)

    monkeypatch.setattr(evaluate_mod, "_quantized_volume", load_quantized)
    monkeypatch.setattr(evaluate_mod, "TexelLoss", loss_after_renders)
    monkeypatch.setattr(texels_module, "EXPOSED_SLAB", 4)  # the printer texels' slabs: a few planes, not 32
    tracemalloc.start()
    try:
        evaluate_run(tmp_path / "run", EvaluateOptions(spp=1, table=table3, write=False))
    finally:
        tracemalloc.stop()
    Z, Y, X = printer_grid(shape, [V300] * 3)[0]
    layer = Y * X * (2 * 3 + 4) * 4  # quantize: two cached 3-ink cumulative layers, thresholds, labels (float32)
    # what does not grow with the grid (the dither's tables, the renders' per-texel arrays: 0.63 MB, measured at
    # two depths) and a tenth of a byte per printer voxel (measured: 0.016): half of the label grid's 2.0 MB
    bound = 1e6 + 0.1 * Z * Y * X + layer
    assert len(start) == 1 and len(end) == 1 and end[0] - start[0] < bound, ((end[0] - start[0]) / 1e6, bound / 1e6)


def test_evaluate_run_adaptive(tmp_path, table3):
    """Default spp: every result is rendered until its estimated noise contribution is below the target (or the
    cap), pilot first, and the figures say so."""
    make_run(tmp_path / "run", table3, "surface")
    typed = evaluate_run(tmp_path / "run", EvaluateOptions(table=table3, write=False))
    ev = typed.to_json()
    assert ev["spp_adaptive"] and ev["spp"] == ev["continuous"]["spp"]
    for m in (ev["continuous"], ev["quantized"], *ev["baselines"].values()):
        assert m["spp_passes"][0] == PILOT_SPP and m["spp"] == sum(m["spp_passes"])
        assert m["delta_e76_noise_contribution"] <= TARGET_NOISE_DE76 or m["spp"] >= MAX_SPP
    assert any(line.startswith("gamut floor") for line in table_lines(typed))


@pytest.mark.parametrize(
    "method,ink_order", [("random", "index"), ("blue-noise", "index"), ("blue-noise", "lightness")]
)
def test_evaluate_surface_run_and_method_mismatch(tmp_path, table3, method, ink_order):
    """The baselines are dithered as the labels file says ours was (method, seed, and for blue noise the inks'
    order, a file made in index order included): a run whose mixture is the surface baseline prints identically."""
    d = tmp_path / "run"
    make_run(d, table3, "surface")
    q = Volume.load(d / "volume.npz")
    assert list(lightness_order(INKS3, q.g, q.ior)) != [0, 1, 2]  # the two orders differ for these inks
    labels, vp = quantize(q, Quantization(method, 5, None, "nearest", ink_order))
    setting = Quantization(method, 5, tuple(25.4 / vp), "nearest", ink_order)
    Volume.from_labels(voxel_mm=vp, labels=labels, inks=INKS3, quantization=setting).save(d / "quantized.npz")
    ev = evaluate_run(d, EvaluateOptions(spp=4, table=table3)).to_json()
    assert ev["quantization"]["method"] == method and ev["quantization"]["seed"] == 5
    for k in ("delta_e76_mean", "ssim"):  # the surface baseline, quantized like ours = ours
        assert ev["baselines"]["surface"][k] == ev["quantized"][k]
    other = "blue-noise" if method == "random" else "random"
    with pytest.raises(ParameterError, match=f"quantized with '{method}'") as exc:
        evaluate_run(d, EvaluateOptions(spp=1, method=other, table=table3))
    assert f"not --method '{other}'" in exc.value.render(flag_of)  # the command line names its flag


def test_baselines_are_dithered_without_our_share_compensation(tmp_path, table3, monkeypatch):
    """A run quantized with the share compensation (our method's step): its print is dithered compensated, the
    print-shop baselines as a print shop would, by plain blue noise (every other setting as ours)."""
    d = tmp_path / "run"
    make_run(d, table3, "surface")
    q = Volume.load(d / "volume.npz")
    ours = Quantization("blue-noise", 5, None, "nearest", "lightness", compensate=True)
    seen = []

    def recording(volume, settings, out=None):
        seen.append(settings)
        return quantize(volume, replace(settings, compensate=False), out)  # no compensation measured here

    labels, vp = recording(q, ours)
    record = replace(ours, dpi=tuple(25.4 / vp))
    Volume.from_labels(voxel_mm=vp, labels=labels, inks=INKS3, quantization=record).save(d / "quantized.npz")
    monkeypatch.setattr(printed_mod, "quantize", recording)
    ev = evaluate_run(d, EvaluateOptions(spp=2, table=table3)).to_json()
    assert ev["quantization"]["compensate"] is True  # the print's record says it was compensated
    baselines = seen[1:]
    assert len(baselines) == 2 and all(not s.compensate for s in baselines)
    assert all(replace(s, compensate=True) == replace(record, dpi=s.dpi) for s in baselines)


def test_evaluate_mesh_kind(tmp_path, table3):
    """A voxelized ball with shading normals: printer texels come from the upsampled normals."""
    n = 10
    c = np.indices((n, n, n)).transpose(1, 2, 3, 0)[..., ::-1] + 0.5 - n / 2  # xyz offsets from the centre
    inside = np.linalg.norm(c, axis=-1) < n / 2 - 0.5
    normals = (c / np.linalg.norm(c, axis=-1, keepdims=True)).astype(np.float32)
    mix = np.zeros((n, n, n, 3), np.float32)
    mix[inside] = [0.2, 0.1, 0.7]
    vol = Volume.from_mixture(voxel_mm=[V300] * 3, mixture=mix, inks=INKS3, inside=inside, normals=normals)
    tex = Texels.from_normals(inside, normals)
    d = tmp_path / "mesh"
    d.mkdir()
    vol.save(d / "volume.npz")
    save_npz(
        d / "scene.npz",
        {
            **tex.to_arrays(),
            "target_rgb": np.full((len(tex), 3), 0.3, np.float32),
            "kind": np.array("mesh"),
            "fixed_share": np.zeros(mix.shape, np.float32),
        },
    )
    ev = evaluate_run(d, EvaluateOptions(spp=2, table=table3)).to_json()
    q = Volume.load(d / "quantized.npz")
    assert q.normals is not None and len(printer_texels(q, tex, "mesh")) == ev["printer_texels"]
    assert all(np.isfinite(ev[k]["delta_e76_mean"]) for k in ("continuous", "quantized"))
    assert not list(d.glob("evaluation_*.png"))  # pictures only for slabs


def test_printed_renderer_keeps_its_geometry_and_renders_like_a_new_one():
    """The printer renderer is built once: a second labels volume swapped in renders bit for bit like a renderer
    built for it, the walk counts are the swapped-in volume's, and a volume with other inside voxels is refused."""
    shape = (8, 10, 12)
    rng = np.random.default_rng(3)
    inside = np.zeros(shape, bool)
    inside[1:7, 2:9, 2:11] = True
    a, b = (np.where(inside, rng.integers(0, 3, shape), 255).astype(np.uint8) for _ in range(2))
    vols = [Volume.from_labels(voxel_mm=[V300] * 3, labels=lab, inks=INKS3) for lab in (a, b)]
    scene = Texels.box_faces(shape, ["top"])
    kept = PrintedRenderer(vols[0], scene, [V300] * 3, "slab", threads=2)
    kept.use(vols[0])
    kept(16, 7)
    first = kept.events
    kept.use(vols[1])
    assert kept.builds == 1 and kept.events == 0
    fresh = PrintedRenderer(vols[1], scene, [V300] * 3, "slab", threads=2)
    fresh.use(vols[1])
    for got, want in zip(kept(16, 7), fresh(16, 7)):
        np.testing.assert_array_equal(got, want)
    assert kept.events == fresh.events and kept.paths == fresh.paths > 0 and first > 0
    other = a.copy()
    other[3, 5, 5] = 255  # a hole: other inside voxels than the renderer's geometry
    with pytest.raises(ValueError, match="inside voxels differ"):
        kept.use(Volume.from_labels(voxel_mm=[V300] * 3, labels=other, inks=INKS3))
    kept.use(None)
    assert kept.renderer is None
