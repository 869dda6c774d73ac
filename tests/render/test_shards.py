"""Texel shards: renders and fixed-point gradients of texel ranges combine bit-identically into one pass, in
this process and on Ray workers (``inkopt.distributed``), and ``--ray`` without Ray is a one-line error."""

import sys

import numpy as np
import pytest

from inkopt import charts
from inkopt.color import srgb_to_linear
from inkopt.model import InkTable
from inkopt.optim import Optimization, OptimizeConfig
from inkopt.render import PassSettings, Renderer, fixed_to_float
from inkopt.scenes.slab import build_slab

pytest.importorskip("inkopt._core")


def chart_scene(w=12, h=8, depth_mm=0.3):
    top = srgb_to_linear(charts.colour_chart(w * 4, h * 4) / 255.0).astype(np.float32)
    vox = 25.4 / 300
    return build_slab(top, None, (w * vox, h * vox, depth_mm), InkTable.parse("vero-cmykw"))


def bounds(n, parts):
    cut = [0, *sorted(np.random.default_rng(3).choice(np.arange(1, n), parts - 1, replace=False)), n]
    return list(zip(cut[:-1], cut[1:]))


@pytest.mark.parametrize("sparse", [False, True])
def test_shards_in_one_process_equal_one_pass(sparse):
    """Three uneven texel ranges, each rendered with its global texel indices and given the whole pass's largest
    adjoint: concatenated renders and summed int64 gradients converted once equal one pass, bit for bit."""
    scene = chart_scene()
    vol = scene.volume.with_mixture(
        np.random.default_rng(0).dirichlet(np.ones(5), scene.volume.shape).astype(np.float32)
    )
    tex, n = scene.texels, len(scene.texels)
    adj = np.random.default_rng(1).normal(size=(n, 3)).astype(np.float32)
    gi = None
    if sparse:
        gi = np.full(vol.shape, -1, np.int32)
        gi[:, :, ::2] = np.arange(gi[:, :, ::2].size).reshape(gi[:, :, ::2].shape)
    r = Renderer(vol, threads=2)
    full = r.render(tex, 4, 7)
    gs, ga, gres = r.gradient(tex, adj, 4, 8, grad_index=gi)
    parts = [
        (
            r.render_pass(tex.subset(slice(a, b)), PassSettings(4, 7, first_texel=a)),
            r.gradient_fixed(
                tex.subset(slice(a, b)),
                adj[a:b],
                PassSettings(4, 8, first_texel=a),
                grad_index=gi,
                max_abs_adjoint=float(np.abs(adj).max()),
            ),
        )
        for a, b in bounds(n, 3)
    ]
    np.testing.assert_array_equal(np.concatenate([p.rgb for p, _ in parts]), full.rgb)
    np.testing.assert_array_equal(np.concatenate([p.var_mean for p, _ in parts]), full.var_mean)
    np.testing.assert_array_equal(np.concatenate([g[3].rgb for _, g in parts]), gres.rgb)
    q = parts[0][1][2]
    assert all(g[2] == q for _, g in parts)
    assert np.abs(ga).max() > 0
    np.testing.assert_array_equal(fixed_to_float(sum(g[0] for _, g in parts), q), gs)
    np.testing.assert_array_equal(fixed_to_float(sum(g[1] for _, g in parts), q), ga)


def test_ray_missing_is_one_line(tmp_path, capsys, monkeypatch):
    from PIL import Image

    from inkopt.cli import main

    Image.fromarray(charts.colour_chart(40, 24)).save(tmp_path / "c.png")
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    argv = ["slab", str(tmp_path / "c.png"), "--size-mm", "2x1.2x0.3", "--out", str(tmp_path / "run"), "--ray", "auto"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--ray needs Ray: pip install 'inkopt[ray]'" in err
    assert not (tmp_path / "run").exists()


def test_ray_shards_equal_one_machine():
    """Three iterations of a small slab with every render split over 2 local Ray workers (1 thread each): the
    same variables, loss history and running prediction as in one process, bit for bit; and a final render."""
    pytest.importorskip("ray")
    from inkopt.distributed import RayShards

    scene = chart_scene()
    cfg = OptimizeConfig(iterations=3, spp=2, forward_spp=4)
    cfg = cfg.for_scene(scene.kind)
    plain = Optimization(scene, cfg, threads=2)
    plain.run()
    shards = RayShards("auto", workers=2, threads=1, num_cpus=2)
    try:
        assert [hi - lo for lo, hi in shards.renderer(scene.volume)._bounds(len(scene.texels))] == [48, 48]
        made = []
        sharded = Optimization(
            scene, cfg, threads=2, renderer_factory=lambda *a: made.append(shards.renderer(*a)) or made[-1]
        )
        sharded.run()
        np.testing.assert_array_equal(sharded.x, plain.x)
        assert sharded.history.loss == plain.history.loss
        np.testing.assert_array_equal(sharded.c_avg, plain.c_avg)
        # the free-voxel index went out once (set_mixture's one slice is the same memory as the gradient index), not
        # per iteration; the gradients came back as fewer bytes than the raw int64 sums
        traffic, free = made[0].traffic, sharded.param.n_free
        assert traffic["out:index"] == 8 * free
        assert traffic["out:mixture"] == 3 * 4 * 5 * free
        assert 0 < traffic["back:gradient"] < traffic["dense:gradient"] == 3 * 2 * 48 * free
        final = sharded.renderer().render(scene.texels, 8, 99)
        np.testing.assert_array_equal(final.rgb, Renderer(plain.volume()).render(scene.texels, 8, 99).rgb)
    finally:
        shards.close()


def test_ray_shards_equal_one_machine_on_a_mesh(tmp_path):
    """The same for a voxelized mesh with a shell (masked object, label base volume, compact fixed shares, empty
    space around it): two iterations sharded over 2 local Ray workers equal one process, bit for bit."""
    pytest.importorskip("ray")
    import trimesh

    from inkopt.distributed import RayShards
    from inkopt.scenes.mesh import build_mesh_scene
    from inkopt.scenes.spec import MeshSpec

    sph = trimesh.creation.icosphere(subdivisions=3, radius=0.6)
    colours = np.where(sph.vertices[:, 2:3] > 0, [[0, 200, 230, 255]], [[230, 0, 160, 255]]).astype(np.uint8)
    trimesh.Trimesh(sph.vertices, sph.faces, vertex_colors=colours, process=False).export(tmp_path / "ball.ply")
    spec = MeshSpec(tmp_path / "ball.ply", scale=1.0, up="z", shell_mm=0.2)
    scene = build_mesh_scene(spec, InkTable.parse("vero-cmykw"))
    assert 0 < scene.free.sum() < scene.vox.inside.count
    cfg = OptimizeConfig(iterations=2, spp=2, forward_spp=4).for_scene("mesh")
    plain = Optimization(scene, cfg, threads=2)
    plain.run()
    assert plain.history.loss[-1] != plain.history.loss[0]
    shards = RayShards("auto", workers=2, threads=1, num_cpus=2)
    try:
        sharded = Optimization(scene, cfg, threads=2, renderer_factory=shards.renderer)
        sharded.run()
        np.testing.assert_array_equal(sharded.x, plain.x)
        assert sharded.history.loss == plain.history.loss
        np.testing.assert_array_equal(sharded.c_avg, plain.c_avg)
    finally:
        shards.close()


@pytest.mark.parametrize("impl", ["Renderer", "ShardedRenderer"])
def test_renderers_implement_the_protocol(impl):
    """Both renderers are TexelRenderers: each protocol method's parameters (names, kinds, defaults) begin their
    own, so a caller typed against the protocol can use either."""
    import inspect

    from inkopt import distributed, render

    cls = getattr(render, impl, None) or getattr(distributed, impl)
    assert render.TexelRenderer in cls.__mro__
    for name, member in vars(render.TexelRenderer).items():
        if name.startswith("_") or not callable(member):
            continue
        want = list(inspect.signature(member).parameters.values())
        got = list(inspect.signature(getattr(cls, name)).parameters.values())
        assert [(p.name, p.kind, p.default) for p in got[: len(want)]] == [(p.name, p.kind, p.default) for p in want], (
            f"{impl}.{name}"
        )
        assert all(p.default is not inspect.Parameter.empty for p in got[len(want) :]), f"{impl}.{name}: extras"
        assert inspect.getdoc(getattr(cls, name)), f"{impl}.{name}: no docstring, not even the protocol's"
