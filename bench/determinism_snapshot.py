"""Bit-identity check across refactors: renders, gradients and a short optimisation for fixed seeds.

    .venv/bin/python bench/determinism_snapshot.py --write  SNAP.npz   # before a change
    .venv/bin/python bench/determinism_snapshot.py --compare SNAP.npz  # after it: exit 1 on any difference
    (--core-only: only the Rust core's renders and gradients)

Covers every code path of the core (packets on a box and a periodic slab, the masked packet walk with shading
normals, the scalar tracer of a masked periodic slab, label media, dense and sparse gradients, replay and L_i = 1)
and the Python optimisation loop (3 iterations of a two-sided slab). Arrays are compared exactly (bytes).
"""

import argparse
import sys

import numpy as np

from inkopt import _core


def _medium(shape, rng, labels):
    """A random medium of ``shape`` (z, y, x): labels of 5 inks with their table, or dense coefficients."""
    if labels:
        return _core.Medium.labels(
            rng.integers(0, 5, size=shape).astype(np.uint8),
            np.array([[8.6, 3.1, 7.3], [2.4, 0.3, 9.0], [2.2, 3.7, 2.8], [1.7, 1.9, 2.2], [6.0, 9.0, 24.0]], np.float32)
            * np.float32(0.999),
            np.array(
                [[0.4, 1.4, 0.2], [0.1, 2.7, 1.0], [0.01, 0.02, 16.0], [3.2, 3.6, 4.2], [0.005, 0.003, 0.02]],
                np.float32,
            ),
        )
    return _core.Medium.dense(
        rng.uniform(0.5, 12.0, size=shape + (3,)).astype(np.float32),
        rng.uniform(0.0, 2.0, size=shape + (3,)).astype(np.float32),
    )


def _scene(shape, voxel_mm, rng, *, boundary="box", mask=None, normals=None, labels=False):
    kw = dict(boundary=boundary, ior=1.5, g=0.4, threads=None)
    if mask is not None:
        kw["inside"] = mask.astype(np.uint8)
    if normals is not None:
        kw["normals"] = normals
    return _core.Scene(shape, voxel_mm, _medium(shape, rng, labels), **kw)


def _texels(mask, faces=range(6)) -> _core.Texels:
    """Every exposed face of ``mask`` (z, y, x), with its face normal."""
    normals = np.array([[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, -1], [0, 0, 1]], np.float32)
    pad = np.pad(mask, 1)
    vox, fid = [], []
    for f in faces:
        axis, step = 2 - f // 2, (1 if f % 2 else -1)
        nb = np.roll(pad, -step, axis=axis)[1:-1, 1:-1, 1:-1]
        v = np.argwhere(mask & ~nb)
        vox.append(v)
        fid.append(np.full(len(v), f, np.uint8))
    fid = np.concatenate(fid)
    return _core.Texels(np.ascontiguousarray(np.concatenate(vox), np.int32), fid, normals[fid])


def core_snapshot() -> dict:
    rng = np.random.default_rng(12345)
    out = {}
    vmm = (0.0847, 0.0847, 0.0847)
    ball = np.linalg.norm(np.indices((14, 16, 18)).transpose(1, 2, 3, 0) - np.array([6.5, 7.5, 8.5]), axis=-1) < 6.4
    ball[5:9, 7:9, :6] = False  # a concave notch
    grad = np.gradient(ball.astype(np.float32))
    nrm = -np.stack([grad[2], grad[1], grad[0]], -1)
    nrm /= np.maximum(np.linalg.norm(nrm, axis=-1, keepdims=True), 1e-6)
    cases = {
        "box": (dict(shape=(10, 12, 14), voxel_mm=vmm), None),
        "periodic": (dict(shape=(12, 8, 8), voxel_mm=vmm, boundary="periodic-xy"), [4, 5]),
        "labels": (dict(shape=(9, 10, 11), voxel_mm=(0.042, 0.085, 0.027), labels=True), None),
        "masked": (dict(shape=ball.shape, voxel_mm=vmm, mask=ball, normals=nrm.astype(np.float32)), None),
        "masked_periodic": (
            dict(shape=(8, 6, 6), voxel_mm=vmm, boundary="periodic-xy", mask=np.ones((8, 6, 6), bool)),
            [4, 5],
        ),
    }
    for name, (kw, faces) in cases.items():
        shape = kw.pop("shape")
        mask = kw.get("mask")
        sc = _scene(shape, kw.pop("voxel_mm"), rng, **kw)
        m = mask if mask is not None else np.ones(shape, bool)
        tex = _texels(m, faces if faces is not None else range(6))
        for spec in (True, False):
            mean, var, st = sc.render(tex, spp=6, seed=7, include_specular=spec)
            out[f"{name}_render_spec{int(spec)}"] = np.concatenate([mean, var], 1)
            out[f"{name}_events_spec{int(spec)}"] = np.array([st["paths"], st["events"]], np.int64)
        adj = rng.normal(size=(len(tex), 3)).astype(np.float32)
        for method in ("replay", "li1"):
            sc.zero_grad(float(np.abs(adj).max()), None)
            mean, var, st = sc.backward(tex, adj, spp=5, seed=11, include_specular=True, method=method)
            gs, ga = sc.take_grad()
            out[f"{name}_grad_{method}"] = np.stack([gs, ga])
            out[f"{name}_grad_{method}_est"] = np.concatenate([mean, var], 1)
        idx = np.full(shape, -1, np.int32)
        sel = np.flatnonzero(m.reshape(-1))[::2]
        idx.reshape(-1)[sel] = np.arange(len(sel), dtype=np.int32)
        sc.zero_grad(float(np.abs(adj).max()), idx)
        sc.backward(tex, adj, spp=5, seed=13, include_specular=True, method="replay")
        out[f"{name}_grad_sparse"] = np.stack(sc.take_grad())
    return out


def optimisation_snapshot() -> dict:
    try:  # the layout after the stage-subpackage reorganisation
        from inkopt.model import InkTable
        from inkopt.optim import Optimization, OptimizeConfig
        from inkopt.scenes.slab import build_slab
    except ImportError:
        from inkopt.materials import InkTable
        from inkopt.optimize import Optimization, OptimizeConfig
        from inkopt.slab import build_slab
    from inkopt import charts

    try:
        from inkopt.color import srgb_to_linear
    except ImportError:
        from inkopt.loss import srgb_to_linear
    lin = lambda im: srgb_to_linear(im / 255.0).astype(np.float32)
    inks = InkTable.parse("vero-cmykw")
    scene = build_slab(
        lin(charts.colour_chart(96, 64)),
        lin(charts.zebra(24, 16)),
        (24 * 25.4 / 300, 16 * 25.4 / 300, 8 * 25.4 / 300),
        inks,
    )
    out = {}
    for opt in ("eg", "adam"):
        cfg = OptimizeConfig(iterations=3, spp=2, forward_spp=4, optimizer=opt, seed=5, gamma=(1.0, 1.0, 1.0))
        if hasattr(OptimizeConfig, "resolved"):  # the scene and its settings resolved for its kind
            run = Optimization(scene, cfg.for_scene(scene.kind), threads=None)
        else:  # the package's earlier layouts: the scene's arrays and its kind
            run = Optimization(scene.volume, scene.texels, scene.target_rgb, cfg, kind="slab", threads=None)
        run.run()
        out[f"opt_{opt}_mixture"] = run.mixture()
        out[f"opt_{opt}_loss"] = np.array(run.history.loss)
    return out


def main():
    ap = argparse.ArgumentParser()
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--write")
    g.add_argument("--compare")
    ap.add_argument("--core-only", action="store_true", help="skip the Python optimisation loop")
    a = ap.parse_args()
    snap = core_snapshot() if a.core_only else {**core_snapshot(), **optimisation_snapshot()}
    if a.write:
        np.savez(a.write, **snap)
        print(f"wrote {len(snap)} arrays to {a.write}")
        return 0
    ref = np.load(a.compare)
    keys = [k for k in ref.files if not (a.core_only and k.startswith("opt_"))]
    bad = [k for k in keys if k not in snap or snap[k].shape != ref[k].shape or snap[k].tobytes() != ref[k].tobytes()]
    missing = [k for k in snap if k not in ref.files]
    for k in bad:
        print(f"DIFFERS: {k}")
    print(f"{len(keys) - len(bad)} of {len(keys)} arrays bit-identical" + (f"; new: {missing}" if missing else ""))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
