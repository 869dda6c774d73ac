"""Versioned files (``format_version``, ``inkopt.io.upgrade_format``): for volume.npz, scene.npz, checkpoints and
the slice manifest, a file written now carries version 1 and round-trips, today's files without the key
(version 0) load, a newer version is refused in one line, and each pre-release layout is refused in one line that
says what to do. (quantized.npz and dense normals: tests/printing/test_stream.py, tests/model/test_normals.py.)"""

import json
from dataclasses import asdict

import numpy as np
import pytest

from inkopt.charts import colour_chart
from inkopt.color import srgb_to_linear
from inkopt.io import FormatError, save_npz
from inkopt.model import InkTable, MeshInfo, Texels, Volume
from inkopt.optim import Optimization, OptimizeConfig
from inkopt.printing.formats.job import LabelVoxels, PrintJob
from inkopt.printing.formats.png_slices import read_png_slices, write_png_slices
from inkopt.rundir import RunDir, SceneRecord
from inkopt.scenes.slab import build_slab

INKS = InkTable.parse("vero-cmykw")


def _one_line(exc_info, *needles):
    msg = str(exc_info.value)
    assert "\n" not in msg and all(n in msg for n in needles), msg


def _without_version(path):
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files if k != "format_version"}
    save_npz(path, arrays)
    return arrays


def _with_version(path, version):
    with np.load(path) as z:
        arrays = {**{k: z[k] for k in z.files}, "format_version": np.int64(version)}
    save_npz(path, arrays)


def test_volume_file_versions(tmp_path):
    mix = np.random.default_rng(0).dirichlet(np.ones(len(INKS)), size=(2, 3, 4)).astype(np.float32)
    vol = Volume.from_mixture((0.1,) * 3, mix, INKS, origin_mm=(1.0, 2.0, 3.0))
    path = tmp_path / "v.npz"
    vol.save(path)
    assert int(np.load(path)["format_version"]) == 1
    back = Volume.load(path)
    np.testing.assert_array_equal(back.mixture, mix)
    _without_version(path)  # what inkopt wrote before files carried a version
    np.testing.assert_array_equal(Volume.load(path).mixture, mix)
    _with_version(path, 2)
    with pytest.raises(FormatError) as e:
        Volume.load(path)
    _one_line(e, str(path), "volume file of format version 2", "update inkopt")


def _scene_record(kind="slab"):
    tex = Texels.box_faces((2, 3, 4), ["top"])
    mesh = None
    if kind == "mesh":
        mesh = MeshInfo("spot.obj", 10.0, 20.0, "y", np.zeros(3), np.full(3, 0.1), np.zeros((len(tex), 3)), None)
    return SceneRecord(
        kind, tex, np.full((len(tex), 3), 0.5, np.float32), free_mask=np.ones((2, 3, 4), bool), mesh=mesh
    )


@pytest.mark.parametrize("kind", ["slab", "mesh"])
def test_scene_file_versions(tmp_path, kind):
    d = RunDir.create(tmp_path / "run")
    d.save_scene(_scene_record(kind))
    assert int(np.load(d.scene_path)["format_version"]) == 1
    rec = d.load_scene()
    assert rec.kind == kind and (rec.mesh is not None) == (kind == "mesh")
    np.testing.assert_array_equal(rec.free_mask, np.ones((2, 3, 4), bool))
    arrays = _without_version(d.scene_path)
    assert d.load_scene().kind == kind
    _with_version(d.scene_path, 2)
    with pytest.raises(FormatError) as e:
        d.load_scene()
    _one_line(e, "scene file of format version 2")
    lacking = "kind" if kind == "slab" else "height_mm"  # pre-release layouts
    save_npz(d.scene_path, {k: v for k, v in arrays.items() if k != lacking})
    with pytest.raises(FormatError) as e:
        d.load_scene()
    _one_line(e, f"lacks {lacking}", "pre-release", "rerun the optimisation")


def _optimization(**kw):
    vox = 25.4 / 300
    top = srgb_to_linear(colour_chart(24, 16) / 255.0).astype(np.float32)
    scene = build_slab(top, None, (6 * vox, 4 * vox, 0.2), INKS)
    cfg = OptimizeConfig(**{"iterations": 2, "spp": 1, "forward_spp": 2, **kw})
    return Optimization(scene, cfg.for_scene("slab"), threads=2)


def _version_0_key(run: Optimization) -> str:
    """The config_key version-0 checkpoints hold: settings at their "off" value left out, guided smoothing
    marked."""
    d = asdict(run.cfg)
    for name in ("iterations", "checkpoint_every", "stop_gain", "stop_horizon", "time_budget", "finish_smooth"):
        d.pop(name)  # never in a key
    if d["schedule_iterations"] is None:
        d.pop("schedule_iterations")
    if not d["decay"]:
        d.pop("decay")
    if not d["smooth"]:
        d.pop("smooth")
        d.pop("smooth_edge")
    elif d["smooth_edge"]:
        d["smooth_where"] = "flat"
    d.update(
        shape=list(run.base.shape),
        inks=list(run.base.inks.names),
        texels=len(run.texels),
        free=run.param.n_free,
        problem=run._problem_digest,
    )
    return json.dumps(d, sort_keys=True)


@pytest.mark.parametrize(
    "settings", [{}, {"decay": 0.0, "smooth": 0.0}, {"smooth_edge": 0.0}, {"schedule_iterations": 5}]
)
def test_checkpoint_versions(tmp_path, settings):
    path = tmp_path / "ck.npz"
    a = _optimization(**settings)
    a.step()
    a.save_checkpoint(path)
    assert int(np.load(path)["format_version"]) == 1
    b = _optimization(**settings)
    b.load_checkpoint(path)
    np.testing.assert_array_equal(b.x, a.x)
    arrays = _without_version(path)
    save_npz(path, {**arrays, "config_key": np.array(_version_0_key(a))})  # a checkpoint of today's layout
    c = _optimization(**settings)
    c.load_checkpoint(path)
    assert c.iteration == 1 and c.history.loss == a.history.loss
    np.testing.assert_array_equal(c.x, a.x)
    with pytest.raises(ValueError, match="different settings"):  # the upgraded key still tells settings apart
        _optimization(**{**settings, "lr": 0.3}).load_checkpoint(path)
    _with_version(path, 2)
    with pytest.raises(FormatError) as e:
        c.load_checkpoint(path)
    _one_line(e, "checkpoint of format version 2")


def test_pre_release_checkpoints_are_refused(tmp_path):
    path = tmp_path / "ck.npz"
    a = _optimization()
    a.step()
    a.save_checkpoint(path)
    arrays = _without_version(path)
    key = json.loads(_version_0_key(a))
    del key["smooth_where"]  # guided smoothing over every voxel: before it was limited to flat texels
    save_npz(path, {**arrays, "config_key": np.array(json.dumps(key, sort_keys=True))})
    with pytest.raises(FormatError) as e:
        _optimization().load_checkpoint(path)
    _one_line(e, "pre-release", "rerun without resume")
    save_npz(
        path, {k: v for k, v in arrays.items() if k != "hist_step_s"} | {"config_key": np.array(_version_0_key(a))}
    )  # before the history had every timing
    with pytest.raises(FormatError) as e:
        _optimization().load_checkpoint(path)
    _one_line(e, "pre-release", "rerun without resume")


def test_slice_manifest_versions(tmp_path):
    lab = np.random.default_rng(1).integers(0, 5, (3, 4, 5)).astype(np.uint8)
    out = tmp_path / "slices"
    man = write_png_slices(PrintJob(LabelVoxels(lab, (25.4 / 600, 25.4 / 300, 0.027), INKS.names)), out)
    assert man["format_version"] == 1 and man["version"] == 1  # "version": the key scripts already read
    labels, back = read_png_slices(out)
    np.testing.assert_array_equal(labels, lab)
    assert back == json.loads(json.dumps(man))
    path = out / "manifest.json"
    path.write_text(json.dumps({k: v for k, v in man.items() if k != "format_version"}))
    np.testing.assert_array_equal(read_png_slices(out)[0], lab)
    path.write_text(json.dumps({**man, "format_version": 2}))
    with pytest.raises(FormatError) as e:
        read_png_slices(out)
    _one_line(e, "slice manifest of format version 2")
