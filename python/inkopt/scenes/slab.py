"""2.5D slabs: a box of voxels with pictures on its top (+z) and optionally bottom (-z) faces.

Picture orientation: the top picture is the slab seen from above (row 0 = largest y, column 0 = smallest x).
The bottom picture is the slab seen from below after turning it over about the y axis, like the back of a page:
row 0 = largest y, column 0 = **largest** x. Pictures are sRGB; they are resampled in linear light to the face's
texel grid (one texel per voxel face, 300 DPI by default) with anti-aliasing.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .loss import linear_to_srgb, srgb_to_linear
from .materials import InkTable
from .volume import Texels, Volume, atomic_write_bytes, save_npz

DPI = 300.0
ASPECT_TOLERANCE = 0.02  # relative mismatch of picture and face aspect ratios allowed (resampling rounding)


def parse_size(text: str) -> tuple[float, float, float]:
    """'WxHxD' in mm -> (W, H, D)."""
    try:
        w, h, d = (float(v) for v in text.lower().split("x"))
    except ValueError:
        raise ValueError(f"--size-mm must look like 15x10x2.5 (width x height x depth in mm), got '{text}'") from None
    if min(w, h, d) <= 0:
        raise ValueError(f"--size-mm sizes must be positive, got '{text}'")
    return w, h, d


def load_picture(path: str | Path) -> np.ndarray:
    """An image file -> (H, W, 3) float32 linear RGB. Alpha is composited over white."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            im = im.convert("RGBA")
            arr = np.asarray(im, np.float32) / 255.0
    except FileNotFoundError:
        raise ValueError(f"picture {path} does not exist") from None
    except (UnidentifiedImageError, OSError) as exc:
        raise ValueError(f"cannot read picture {path}: {exc}") from None
    rgb, alpha = arr[..., :3], arr[..., 3:]
    return srgb_to_linear(rgb * alpha + (1.0 - alpha)).astype(np.float32)


def resample(picture: np.ndarray, ny: int, nx: int) -> np.ndarray:
    from skimage.transform import resize

    return resize(picture, (ny, nx, 3), order=1, anti_aliasing=True, mode="edge").astype(np.float32)


@dataclass
class SlabScene:
    volume: Volume            # mixture form; its mixture is the starting point
    texels: Texels
    target_rgb: np.ndarray    # (I, 3) linear
    faces: list[str]
    pix: dict                 # face -> (H, W) int32 texel index per picture pixel

    def scene_arrays(self) -> dict:
        out = {**self.texels.to_arrays(), "target_rgb": self.target_rgb.astype(np.float32),
               "kind": np.array("slab"), "faces": np.array(self.faces)}
        out.update({f"pix_{f}": p for f, p in self.pix.items()})
        return out


def build_slab(top: np.ndarray, bottom: np.ndarray | None, size_mm, inks: InkTable, dpi: float = DPI) -> SlabScene:
    """top, bottom: (H, W, 3) linear pictures; size_mm (W, H, D)."""
    w_mm, h_mm, d_mm = size_mm
    vox = 25.4 / dpi
    nx, ny, nz = (max(1, int(round(v / vox))) for v in (w_mm, h_mm, d_mm))
    for name, pic in (("top", top), ("bottom", bottom)):
        if pic is None:
            continue
        aspect = pic.shape[1] / pic.shape[0]
        if abs(aspect / (w_mm / h_mm) - 1.0) > ASPECT_TOLERANCE:
            raise ValueError(f"the {name} picture is {pic.shape[1]}x{pic.shape[0]} px (aspect {aspect:.3f}) but "
                             f"--size-mm gives {w_mm:g}x{h_mm:g} mm (aspect {w_mm / h_mm:.3f}); "
                             f"use --size-mm {w_mm:g}x{w_mm / aspect:.4g}x{d_mm:g}")
    faces = ["bottom", "top"] if bottom is not None else ["top"]
    texels = Texels.box_faces((nz, ny, nx), faces)
    # Texel order: bottom face (if any) then top, each C order over (y, x).
    offset = {"bottom": 0, "top": ny * nx if bottom is not None else 0}
    yy, xx = np.meshgrid(np.arange(ny)[::-1], np.arange(nx), indexing="ij")  # row 0 = largest y
    pix = {"top": (offset["top"] + yy * nx + xx).astype(np.int32)}
    if bottom is not None:
        pix["bottom"] = (offset["bottom"] + yy * nx + (nx - 1 - xx)).astype(np.int32)
    target = np.zeros((len(texels), 3), np.float32)
    for f in faces:
        pic = resample(top if f == "top" else bottom, ny, nx)
        target[pix[f].reshape(-1)] = pic.reshape(-1, 3)
    mixture = np.zeros((nz, ny, nx, len(inks)), np.float32)
    mixture[..., inks.index("white") if "white" in inks.names else 0] = 1.0
    vol = Volume(voxel_mm=(vox, vox, vox), mixture=mixture, inks=inks)
    return SlabScene(vol, texels, np.clip(target, 0.0, 1.0), faces, pix)


# ----------------------------------------------------------------------------------------- outputs
def face_picture(rgb: np.ndarray, pix: np.ndarray) -> np.ndarray:
    """Per-texel linear RGB (I, 3) -> (H, W, 3) uint8 sRGB picture of a face."""
    return (np.clip(linear_to_srgb(np.clip(rgb[pix], 0, None)), 0, 1) * 255 + 0.5).astype(np.uint8)


def save_png(path: Path, fig) -> None:
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    atomic_write_bytes(path, buf.getvalue())


def write_face_pngs(out: Path, scene: SlabScene, pred_rgb: np.ndarray, delta_e: np.ndarray) -> list[Path]:
    """DIR/face_F.png: target | prediction | dE76 heat map, per textured face."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    for f in scene.faces:
        p = scene.pix[f]
        fig, ax = plt.subplots(1, 3, figsize=(13, 4.6 * p.shape[0] / p.shape[1] + 0.8))
        ax[0].imshow(face_picture(scene.target_rgb, p), interpolation="nearest")
        ax[0].set_title(f"{f}: target")
        ax[1].imshow(face_picture(pred_rgb, p), interpolation="nearest")
        ax[1].set_title("predicted print")
        im = ax[2].imshow(delta_e[p], cmap="magma", vmin=0, vmax=max(10.0, float(np.percentile(delta_e, 99))),
                          interpolation="nearest")
        ax[2].set_title(f"ΔE76 (mean {delta_e[p].mean():.2f})")
        fig.colorbar(im, ax=ax[2], fraction=0.046, pad=0.04)
        for a in ax:
            a.set_xticks([])
            a.set_yticks([])
        path = out / f"face_{f}.png"
        save_png(path, fig)
        plt.close(fig)
        paths.append(path)
    return paths


def write_loss_png(out: Path, history) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    it = np.arange(1, len(history.loss) + 1)
    ax[0].plot(it, history.loss, lw=1)
    ax[0].set_yscale("log")
    ax[0].set_xlabel("iteration")
    ax[0].set_title("loss E")
    ax[1].plot(it, history.delta_e76, lw=1, color="C1")
    ax[1].set_xlabel("iteration")
    ax[1].set_title("mean ΔE76 (training spp)")
    for a in ax:
        a.grid(alpha=0.3)
    path = out / "loss.png"
    save_png(path, fig)
    plt.close(fig)
    return path


def write_report(out: Path, report: dict) -> Path:
    path = out / "report.json"
    atomic_write_bytes(path, (json.dumps(report, indent=2) + "\n").encode())
    return path


def run_slab(top_path, bottom_path, size_mm, out_dir, inks: InkTable, cfg, resume: bool = False,
             eval_spp: int | None = None, threads: int | None = None, progress: bool = False,
             log=print, dpi: float = DPI) -> dict:
    """The whole `inkopt slab` run; returns the report."""
    from .optimize import Optimization, evaluate_prediction
    from .render import Renderer
    from .loss import delta_e76

    t_start = time.perf_counter()
    out = Path(out_dir)
    top = load_picture(top_path)
    bottom = load_picture(bottom_path) if bottom_path else None
    scene = build_slab(top, bottom, size_mm, inks, dpi)
    nz, ny, nx = scene.volume.shape
    log(f"slab {nx} x {ny} x {nz} voxels ({scene.volume.voxel_mm[0] * 1000:.1f} µm), {len(scene.texels)} texels, "
        f"inks {','.join(inks.names)}")
    run = Optimization(scene.volume, scene.texels, scene.target_rgb, cfg, threads=threads)
    ckpt = run.start(out, resume, log)
    save_npz(out / "scene.npz", scene.scene_arrays())
    run.run(ckpt, progress=progress)
    final = run.volume()
    final.save(out / "volume.npz")

    # Final figures at higher spp with seeds unused by the optimisation.
    eval_spp = eval_spp or max(256, 4 * cfg.spp)
    eval_seed = 2**62 + cfg.seed
    res = Renderer(final, threads).render(scene.texels, eval_spp, eval_seed, cfg.include_specular, progress)
    report = evaluate_prediction(run.loss, res.rgb, res.var_mean)
    res0 = Renderer(run.initial_volume(), threads).render(scene.texels, eval_spp, eval_seed, cfg.include_specular)
    init = evaluate_prediction(run.loss, res0.rgb, res0.var_mean)
    de = delta_e76(run.loss(res.rgb).lab, run.loss.target_lab)
    write_face_pngs(out, scene, res.rgb, de)
    write_loss_png(out, run.history)
    h = run.history
    n = max(len(h.seconds), 1)
    report = {
        "initial_delta_e76_mean": init["delta_e76_mean"], "initial_ssim": init["ssim"], **report,
        "iterations": run.iteration, "spp": cfg.spp, "eval_spp": eval_spp,
        "seconds": time.perf_counter() - t_start,
        "seconds_per_iteration": float(np.sum(h.seconds) / n),
        "time_split": {k: float(np.sum(getattr(h, k)) / n) for k in ("render_s", "gradient_s", "loss_s", "step_s")},
        "voxels": int(np.prod(scene.volume.shape)), "texels": len(scene.texels),
        "size_mm": list(size_mm), "inks": list(inks.names), "gamma": list(cfg.gamma), "lr": cfg.step_size,
        "optimizer": cfg.optimizer, "param": cfg.param, "init": cfg.init, "seed": cfg.seed,
        "gradient": cfg.grad_method,
    }
    write_report(out, report)
    return report
