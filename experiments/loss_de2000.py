"""A colour term weighted as ΔE2000 weighs an error, against the default mean ΔE76², side by side on one suite mesh:
both runs from the same start (the suite run's fine start) with the same settings and iteration seeds for the same
number of iterations, then both continuous results rendered on the same sampled texels with the same seeds and
scored in ΔE76 (noise-corrected) and ΔE2000. Writes the entry NAME of experiments/results/loss_de2000.json.

    nice -n 5 .venv/bin/python experiments/loss_de2000.py RUN_DIR --name NAME [--iterations 17] [--texels 1500]

The weighted term (``De2000WeightedLoss``) is E1 with each texel's CIELAB error d split along the target's own
lightness, chroma and hue directions and divided by the CIEDE2000 weights of the target (SL, SC = 1 + 0.045 C*,
SH = 1 + 0.015 C* T): mean (d_L / SL)² + (d_C / SC)² + (d_H / SH)², a fixed quadratic form per texel, so its
gradient is exact and as cheap as E1's. It leaves out CIEDE2000's a* stretch (G), its rotation term and its use of
the mean of both colours' chroma. A finite-difference check of its gradient runs before the runs.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import add_study_entry, machine, provenance  # noqa: E402

from inkopt.color import delta_e76, delta_e2000, linear_to_lab, linear_to_lab_vjp  # noqa: E402
from inkopt.evaluation.noise import NoiseModel  # noqa: E402
from inkopt.loss import E1_WEIGHT_SCALE, LossResult, TexelLoss  # noqa: E402
from inkopt.model import InkTable  # noqa: E402
from inkopt.optim import OptimizeConfig  # noqa: E402
from inkopt.optim.loop import Optimization  # noqa: E402
from inkopt.scenes import build_scene  # noqa: E402
from inkopt.scenes.spec import MeshSpec  # noqa: E402

EVAL_SEED = 2**62 + 7  # never an optimisation seed


def de2000_metric(target_lab: np.ndarray) -> np.ndarray:
    """(I, 3, 3) per-texel quadratic forms M with dᵀ M d = (d_L/SL)² + (d_C/SC)² + (d_H/SH)², d a CIELAB error, d_C
    and d_H its parts along the target's chroma (a*, b*)/C* and hue (−b*, a*)/C* directions (any frame in the a*b*
    plane for a grey target, where SC = SH = 1), SL, SC, SH CIEDE2000's weights of the target alone."""
    lt, at, bt = target_lab.T
    c = np.hypot(at, bt)
    h = np.degrees(np.arctan2(bt, at)) % 360
    hr = np.radians(h)
    t = 1 - 0.17 * np.cos(hr - np.radians(30)) + 0.24 * np.cos(2 * hr)
    t += 0.32 * np.cos(3 * hr + np.radians(6)) - 0.20 * np.cos(4 * hr - np.radians(63))
    sl = 1 + 0.015 * (lt - 50) ** 2 / np.sqrt(20 + (lt - 50) ** 2)
    sc, sh = 1 + 0.045 * c, 1 + 0.015 * c * t
    safe = np.where(c > 0, c, 1.0)
    uc = np.stack([np.zeros_like(c), np.where(c > 0, at / safe, 1.0), np.where(c > 0, bt / safe, 0.0)], 1)
    uh = np.stack([np.zeros_like(c), -uc[:, 2], uc[:, 1]], 1)
    ul = np.tile([1.0, 0.0, 0.0], (len(c), 1))
    return (
        np.einsum("ik,il->ikl", ul, ul) / sl[:, None, None] ** 2
        + np.einsum("ik,il->ikl", uc, uc) / sc[:, None, None] ** 2
        + np.einsum("ik,il->ikl", uh, uh) / sh[:, None, None] ** 2
    )


class De2000WeightedLoss(TexelLoss):
    """``TexelLoss`` whose colour term E1 is mean dᵀ M d (``de2000_metric``) instead of mean |d|² (module docstring);
    colour only: the optimiser's training steps (``all_terms=False``) at γ = (1, 0, 0)."""

    def __init__(self, target_rgb, pos_vox, gamma=(1.0, 0.0, 0.0), sigma: float = 1.5):
        super().__init__(target_rgb, pos_vox, gamma, sigma)
        if tuple(self.gamma) != (1.0, 0.0, 0.0):
            raise ValueError(f"the ΔE2000-weighted term is colour only: gamma (1, 0, 0), got {tuple(self.gamma)}")
        self.metric = de2000_metric(self.target_lab)

    def __call__(self, pred_rgb, pred_var=None, *, all_terms: bool = True) -> LossResult:
        pred = self._check(pred_rgb)
        self._check_var(pred, pred_var)
        lab = linear_to_lab(pred)
        d = lab - self.target_lab
        md = np.einsum("ikl,il->ik", self.metric, d)
        e1 = float(np.sum(d * md) / self.n)
        grad = linear_to_lab_vjp(pred, (2.0 * E1_WEIGHT_SCALE / self.n) * md)
        nan = float("nan")
        return LossResult(value=E1_WEIGHT_SCALE * e1, e1=e1, e2=nan, e3=nan, grad=grad, lab=lab)


def check_gradient(make=None, seed: int = 3, n: int = 40, h: float = 1e-6) -> float:
    """Largest relative difference between the gradient of the colour term ``make(target_rgb, pos_vox)`` (default
    ``De2000WeightedLoss``) and central differences of its value at random colours (grey and saturated targets, three
    texels on their target); raises if above 1e-5."""
    rng = np.random.default_rng(seed)
    target = rng.uniform(0.0, 1.0, (n, 3))
    target[:4] = 0.3  # grey targets
    loss = (make or De2000WeightedLoss)(target, rng.uniform(0, 10, (n, 3)))
    pred = np.clip(target + rng.normal(0, 0.1, (n, 3)), 0.01, 1.0)
    pred[4:7] = target[4:7]  # texels on their target
    grad = loss(pred).grad
    num = np.zeros_like(pred)
    for i in range(n):
        for k in range(3):
            up, dn = pred.copy(), pred.copy()
            up[i, k] += h
            dn[i, k] -= h
            num[i, k] = (loss(up).value - loss(dn).value) / (2 * h)
    err = float(np.max(np.abs(grad - num)) / np.max(np.abs(num)))
    if err > 1e-5:
        raise RuntimeError(f"the colour term's gradient is off by {err:g} (relative)")
    return err


def score(vol, texels, target, points: np.ndarray, spp: int, threads: int) -> dict:
    """Mean ΔE76 (raw and noise-corrected) and ΔE2000 [mean, standard error] of ``vol`` on the sampled texels
    ``points`` at ``spp`` with ``EVAL_SEED``, and the per-texel values (for paired differences)."""
    from inkopt.render import Renderer

    r = Renderer(vol, threads).render(texels.subset(points), spp, EVAL_SEED)
    tl = linear_to_lab(np.asarray(target, np.float64)[points])
    lab = linear_to_lab(r.rgb)
    e76 = delta_e76(lab, tl)
    values = {
        "de76": e76,
        "de76_corrected": e76 - NoiseModel.of(r.rgb, r.var_mean, tl).per_texel(),
        "de2000": delta_e2000(tl, lab),
    }
    return values


def mean_se(x: np.ndarray) -> list:
    return [float(x.mean()), float(x.std(ddof=1) / np.sqrt(len(x)))]


def optimise(scene, cfg, weighted: bool, threads: int):
    """One arm: the run from ``cfg.init`` for ``cfg.iterations`` iterations with the default or the weighted colour
    term, finished (the finishing smoothing) as ``optimize`` does; returns (volume, seconds)."""
    t0 = time.perf_counter()
    run = Optimization(scene, cfg, threads=threads)
    if weighted:
        run.loss = De2000WeightedLoss(run.target, scene.texels.pos_vox)
        run.loss.release_operators()  # colour only: the window and Sobel operators are never read
    run.run()
    run.finish()
    vol = run.volume()
    run.release_renderer()
    return vol, time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--name", required=True)
    ap.add_argument("--iterations", type=int, default=17)
    ap.add_argument("--texels", type=int, default=1500)
    ap.add_argument("--spp", type=int, default=512)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    grad_err = check_gradient()
    print(f"gradient check: largest relative difference {grad_err:.2e}")
    report = json.loads((a.run / "report.json").read_text())
    spec = MeshSpec(report["mesh_path"], height_mm=report["height_mm"])
    scene = build_scene(spec, InkTable.parse("vero-cmykw"))
    recorded = np.load(a.run / "scene.npz")["target_rgb"]
    if recorded.shape != scene.target_rgb.shape or not np.allclose(recorded, scene.target_rgb, atol=1e-6):
        raise RuntimeError(f"the rebuilt scene differs from {a.run / 'scene.npz'}")
    start = a.run / "coarse" / "fine_start.npz"
    cfg = OptimizeConfig(init=str(start), iterations=a.iterations).for_scene("mesh")
    points = np.sort(np.random.default_rng(0).choice(len(scene.texels), a.texels, replace=False))
    entry = {**provenance(), "run": str(a.run), "init": str(start), "iterations": a.iterations, "spp": a.spp}
    entry |= {"texels_sampled": a.texels, "population": len(scene.texels), "gradient_check": grad_err}
    values = {}
    for arm, weighted in (("delta_e76_squared", False), ("de2000_weighted", True)):
        vol, seconds = optimise(scene, cfg, weighted, a.threads)
        values[arm] = score(vol, scene.texels, scene.target_rgb, points, a.spp, a.threads)
        entry[arm] = {k: mean_se(v) for k, v in values[arm].items()} | {"seconds": seconds}
        del vol
        print(arm, {k: [round(x, 3) for x in v] for k, v in entry[arm].items() if k != "seconds"}, f"{seconds:.0f} s")
    w, d = values["de2000_weighted"], values["delta_e76_squared"]
    diff = {k: mean_se(w[k] - d[k]) for k in w}
    entry["weighted - default"] = diff
    print("weighted - default", {k: [round(x, 3) for x in v] for k, v in diff.items()})
    entry.update(machine())
    add_study_entry("loss_de2000.json", a.name, entry)


if __name__ == "__main__":
    main()
