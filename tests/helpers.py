"""Shared test helpers: where the shared data lives, and the gradient-vs-finite-difference checks.

Shared data (test meshes) is found relative to the repository: ``../shared`` beside the project root, as CI
and every developer machine lay it out.
"""

import os
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"
# the shared data set when it is beside the checkout, else the copy the package ships for its demo (the same files)
SPOT = SHARED_DATA / "spot" / "spot.obj"
if not SPOT.is_file():
    SPOT = REPO / "python" / "inkopt" / "data" / "spot" / "spot.obj"
#: the optimisation arguments of a CLI test's run: the fewest iterations and samples that exercise every stage
#: property tests run fixed (derandomized) examples, the same every run, unless INKOPT_FUZZ_EXAMPLES=N asks for N
#: random ones (a search for new failures, outside CI)
FUZZ_RANDOM = int(os.environ.get("INKOPT_FUZZ_EXAMPLES", "0"))


def fuzz(examples: int):
    """hypothesis settings of a property test: ``examples`` derandomized examples (or ``FUZZ_RANDOM`` random
    ones), no deadline, no example database."""
    from hypothesis import HealthCheck, settings

    return settings(
        max_examples=FUZZ_RANDOM or examples,
        deadline=None,
        derandomize=not FUZZ_RANDOM,
        database=None,
        suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow, HealthCheck.data_too_large],
    )


FAST_RUN = ["--iterations", "2", "--spp", "1", "--forward-spp", "2", "--eval-spp", "4", "--threads", "2"]


def central_differences(f, x, h=1e-3) -> np.ndarray:
    """Central finite differences of a deterministic scalar function ``f`` at every entry of ``x``."""
    g = np.zeros_like(x)
    for i in np.ndindex(x.shape):
        e = np.zeros_like(x)
        e[i] = h
        g[i] = (f(x + e) - f(x - e)) / (2 * h)
    return g


def assert_same_mean(estimates, references, rel_bias: float = 0.02, false_alarm: float = 1e-4, what=""):
    """Two unbiased Monte Carlo estimators of one quantity (e.g. a replay gradient and central finite differences
    with common random numbers), one pair per independent seed: their paired difference must have mean ~0.

    The bound is the Student-t quantile for a two-sided false-alarm rate ``false_alarm`` times the standard error
    estimated from the seeds (a normal 4-sigma bound would fire ~1 % of the time with 12 seeds), plus
    ``rel_bias`` of |mean(references)| for a known deterministic bias (e.g. the O(h^2) error of a difference
    quotient), plus 1e-5 absolute for estimates that are exactly zero."""
    from scipy.stats import t as student_t

    d = np.asarray(estimates, np.float64) - np.asarray(references, np.float64)
    if len(d) < 2:
        raise ValueError("assert_same_mean needs at least two seeds")
    t_crit = student_t.ppf(1 - false_alarm / 2, len(d) - 1)
    se = d.std(ddof=1) / np.sqrt(len(d))
    bound = t_crit * se + rel_bias * abs(np.mean(references)) + 1e-5
    assert abs(d.mean()) < bound, (what, float(np.mean(estimates)), float(np.mean(references)), float(se))


def replay_matches_fd(vol, probes, spp=800, seeds=tuple(range(11, 23)), h=0.3, lighting=None):
    """Replay gradient of sum(adj * c) vs central finite differences with common random numbers, per probe
    (z, y, x, channel, 'sigma_s'|'sigma_a'). Both are unbiased estimators, so their difference over independent
    seeds has mean ~0 (``assert_same_mean``: Student-t bound, false-alarm rate 1e-4 per probe, plus 2 %
    for the O(h^2) bias of the difference quotient). ``lighting``: as ``Renderer``'s."""
    from inkopt.model import Texels, Volume
    from inkopt.render import Renderer, render

    tex = Texels.for_volume(vol, ["top"])
    adj = np.random.default_rng(0).uniform(0.2, 1.0, (len(tex), 3)).astype(np.float32)
    for z, y, x, c, which in probes:
        g, fd = [], []
        for seed in seeds:
            gs, ga, _ = Renderer(vol, lighting=lighting).gradient(tex, adj, spp=spp, seed=seed)
            g.append((gs if which == "sigma_s" else ga)[z, y, x, c])
            vals = []
            for sign in (1, -1):
                arr = {"sigma_s": vol.sigma_s.copy(), "sigma_a": vol.sigma_a.copy()}
                arr[which][z, y, x, c] += sign * h
                v2 = Volume.from_coefficients(
                    vol.voxel_mm, arr["sigma_s"], arr["sigma_a"], boundary=vol.boundary, inside=vol.inside
                )
                vals.append(float(np.sum(render(v2, tex, spp=spp, seed=seed, lighting=lighting).rgb * adj)))
            fd.append((vals[0] - vals[1]) / (2 * h))
        assert_same_mean(g, fd, rel_bias=0.02, false_alarm=1e-4, what=(z, y, x, c, which))


def small_chart_scene(w=24, h=16, depth_mm=0.5, bottom=False):
    """A small slab scene (``w`` x ``h`` voxels of 300 DPI, ``depth_mm`` deep) with a colour chart on top (and a
    zebra chart below with ``bottom``), CMYKW inks."""
    from inkopt import charts
    from inkopt.color import srgb_to_linear
    from inkopt.model import InkTable
    from inkopt.scenes.slab import build_slab

    top = charts.colour_chart(w * 4, h * 4)
    lin = lambda im: srgb_to_linear(im / 255.0).astype(np.float32)
    bot = lin(charts.zebra(w * 4, h * 4, (8, 4))) if bottom else None
    vox = 25.4 / 300
    return build_slab(lin(top), bot, (w * vox, h * vox, depth_mm), InkTable.parse("vero-cmykw"))


def small_run(scene, **kw):
    """An ``Optimization`` of ``scene`` on 2 threads: 30 iterations of 4 + 16 spp unless ``kw`` says otherwise."""
    from inkopt.optim import Optimization, OptimizeConfig

    cfg = OptimizeConfig(**{"iterations": 30, "spp": 4, "forward_spp": 16, **kw})
    return Optimization(scene, cfg.for_scene(scene.kind), threads=2)


def with_fixed_shares(scene, fixed_share):
    """``scene`` as the optimiser reads it (``optim.Optimization``: kind, volume, texels, targets) with other fixed
    ink shares (a ``model.FixedShares``)."""
    from types import SimpleNamespace

    return SimpleNamespace(
        kind=scene.kind,
        volume=scene.volume,
        texels=scene.texels,
        target_rgb=scene.target_rgb,
        fixed_share=fixed_share,
    )


def srgb_to_linear(v):
    """IEC 61966-2-1 decoding, written out here (not inkopt's)."""
    v = np.asarray(v, np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


RED = (200, 30, 30)


def write_cube_obj(
    folder, mtllib="m.mtl", map_kd="tex.png", uv=True, write_mtl=True, texture=None, usemtl="mat", head=(), sep=" "
):
    """A unit cube OBJ in ``folder``: ``mtllib`` (None: no line), ``usemtl`` before the faces (None: no line;
    ``sep`` between the keyword and the name), the lines ``head`` at the top; its MTL defines material "mat"
    naming ``map_Kd`` (None: no line); the texture tex.png (uniform RED, or the PIL image ``texture``)."""
    folder.mkdir(parents=True, exist_ok=True)
    box = trimesh.creation.box((1, 1, 1))
    lines = list(head) + ([f"mtllib {mtllib}"] if mtllib else [])
    lines += ["v {:g} {:g} {:g}".format(*p) for p in box.vertices]
    if uv:
        lines += [f"vt {p[0] + 0.5:g} {p[1] + 0.5:g}" for p in box.vertices]
    lines += [f"usemtl{sep}{usemtl}"] if mtllib and usemtl else []
    lines += ["f " + " ".join(f"{i}/{i}" if uv else f"{i}" for i in t) for t in box.faces + 1]
    (folder / "m.obj").write_text("\n".join(lines) + "\n")
    if write_mtl:
        (folder / "m.mtl").write_text("newmtl mat\nKd 1 1 1\n" + (f"map_Kd {map_kd}\n" if map_kd else ""))
    (texture or Image.new("RGB", (8, 8), RED)).save(folder / "tex.png")
    return folder / "m.obj"


def load_file_module(path, name: str):
    """The module of a Python file outside the package (a bench script, docs/tables.py, another test file), loaded
    under ``name``."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
