"""How the noise-corrected SSIM and mottle of a run's result depend on the render's samples: the
evidence behind the adaptive evaluation's SSIM noise ratio (``evaluation/noise.py``, ``SSIM_NOISE_RATIO``).

    .venv/bin/python experiments/ssim_noise_bias.py RUN_DIR [--spp 64,256,1024] [--white] [--baselines] [--name NAME]
        [--threads 2]

For each spp: one render of the run's volume.npz on its scene texels (evaluation seeds), its noise-corrected SSIM
(mean and per normalised L*a*b* channel), mottle and SSIM noise ratio r (the largest channel's mean noise
variance over K2), and the mottle from two independent renders' high-pass product (no noise model: the two
renders' noise is independent, so its expectation is the noise-free figure). ``--white`` does the same for the
97 %-white start of the same object, ``--baselines`` for the surface and extrusion baselines' mixtures (continuous,
not quantized; ``evaluation.baselines``). Writes experiments/results/ssim_noise_bias_NAME.json (NAME: the run
folder's name).
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from common import machine  # noqa: E402
from common import write_study as write

from inkopt.color import linear_to_lab  # noqa: E402
from inkopt.evaluation.metrics import prediction_metrics  # noqa: E402
from inkopt.evaluation.noise import EVAL_SEED_OFFSET, NoiseModel  # noqa: E402
from inkopt.loss import TexelLoss  # noqa: E402
from inkopt.render import Renderer  # noqa: E402
from inkopt.rundir import RunDir  # noqa: E402


def white_start(vol):
    m = np.zeros(vol.mixture.shape, np.float32)
    m[..., :] = 0.03 / (m.shape[-1] - 1)
    m[..., vol.inks.index("white")] = 0.97
    m[~vol.inside_mask()] = 0.0
    return vol.with_mixture(m)


def figures(vol, tex, loss, spp_list, threads) -> dict:
    r = Renderer(vol, threads)
    out = {}
    for spp in spp_list:
        a, b = (r.render(tex, spp, EVAL_SEED_OFFSET + 1000 + k) for k in (0, 1))
        rgb, var = np.asarray(a.rgb, np.float64), np.asarray(a.var_mean, np.float64)
        pm = prediction_metrics(loss, rgb, var).to_json()
        ha, hb = (loss.highpass(linear_to_lab(np.asarray(x.rgb, np.float64))[:, :1])[:, 0] for x in (a, b))
        out[str(spp)] = {
            "ssim": pm["ssim"],
            "ssim_lab": loss.ssim_map(rgb, var).mean(0).tolist(),
            "mottle_l2": pm["mottle_l2"],
            "mottle_l2_two_renders": float((ha * hb)[loss.flat].mean()),
            "ssim_noise_ratio": NoiseModel.of(rgb, var, loss.target_lab).ssim_ratio,
            "delta_e76_mean_corrected": pm["delta_e76_mean_corrected"],
        }
        print(spp, {k: np.round(v, 4).tolist() for k, v in out[str(spp)].items()}, flush=True)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run")
    ap.add_argument("--spp", default="64,256,1024")
    ap.add_argument("--white", action="store_true")
    ap.add_argument("--baselines", action="store_true")
    ap.add_argument("--name")
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    d = RunDir(a.run)
    vol, rec = d.load_volume(), d.load_scene()
    loss = TexelLoss(rec.target_rgb.astype(np.float64), rec.texels.pos_vox, sigma=1.5)
    spp = [int(s) for s in a.spp.split(",")]
    res = {"run": str(a.run), "texels": len(rec.texels), "result": figures(vol, rec.texels, loss, spp, a.threads)}
    if a.white:
        print("white start", flush=True)
        res["white_start"] = figures(white_start(vol), rec.texels, loss, spp, a.threads)
    if a.baselines:
        from inkopt.evaluation.baselines import baseline_mixture

        for kind in ("surface", "extrusion"):
            print(kind, "baseline", flush=True)
            mix = baseline_mixture(kind, vol, rec.texels, rec.target_rgb, rec.fixed_share(vol.inks, vol.shape))
            res[f"{kind}_baseline"] = figures(vol.with_mixture(mix), rec.texels, loss, spp, a.threads)
    write(f"ssim_noise_bias_{a.name or Path(a.run).name}.json", {**res, **machine()})


if __name__ == "__main__":
    main()
