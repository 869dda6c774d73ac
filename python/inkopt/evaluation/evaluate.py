"""Evaluation of a run directory (docs/run-dir.md): how close do the continuous result, the printed (quantized)
result and the naive baselines come to the target?

``evaluate_run(DIR)`` renders, on the same render seed:

- ``continuous``: DIR/volume.npz on the scene texels at ``spp`` samples per texel;
- ``quantized``: DIR/quantized.npz (made with default settings first if missing) on its own printer-grid
  texels (the scene's textured faces of the printer grid; meshes: one texel per printer surface voxel), at
  ``spp_printer = ceil(spp * I_scene / I_printer)`` so each scene texel's average carries about ``spp``
  samples. Each printer texel is assigned to the scene texel of the same face whose face centre is nearest in mm
  (meshes: the nearest scene texel), i.e. the scene texel whose footprint contains it, and the printer texels of
  a scene texel are averaged (a scene texel that gets none takes its nearest printer texel);
- ``baselines``: ``surface`` and ``extrusion`` (``inkopt.baselines``) quantized exactly like ours (same method,
  seed, DPI, upsampling) and rendered like ``quantized``.

Each result is compared with the scene's ``target_rgb``: ΔE76 mean and 95th percentile, CIEDE2000 mean, mean
SSIM (``TexelLoss(...).ssim_mean``, sigma 1.5 voxels, on the scene texels), and ``delta_e76_noise``, the mean
over texels of the Monte Carlo standard error of a texel's CIELAB colour (ΔE), and ``delta_e76_rms`` with
``delta_e76_rms_denoised``: the RMS ΔE76 and an unbiased estimate of it without the render noise
(sqrt(mean(ΔE² - se²))). At 64 spp a texel's colour has a standard error of several ΔE (dark colours most),
which inflates every ΔE mean; compare results rendered at the same spp, or use the denoised RMS.

Writes DIR/evaluation.json and, for slabs, DIR/evaluation_<face>.png per textured face: target | optimized |
quantized | surface | extrusion (sRGB).
"""
from __future__ import annotations

import io
import json
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from .baselines import (DEFAULT_PATCH_MM, ColourTable, colour_table, extrusion_baseline, lab_stderr,
                        surface_baseline)
from .cli_quantize import load_run_volume, quantization_settings, quantize_volume, run_dir
from .loss import TexelLoss, delta_e76, delta_e2000, linear_to_lab, linear_to_srgb
from .volume import Texels, Volume, atomic_write_bytes

DEFAULT_SPP = 64
PANEL_MIN_WIDTH = 256


# ----------------------------------------------------------------------------------------------- metrics
def texel_metrics(rgb, target_rgb, loss: TexelLoss, var_mean=None) -> dict:
    """ΔE76 mean / p95, CIEDE2000 mean, SSIM of predictions rgb (I, 3) linear vs target_rgb (I, 3) linear; with
    the predictions' variances var_mean (I, 3) also the noise level and the RMS ΔE76 with the noise removed,
    and SSIM with the noise removed from its statistics (an estimate for the noise-free prediction)."""
    lab_p, lab_t = linear_to_lab(rgb), linear_to_lab(target_rgb)
    de = delta_e76(lab_p, lab_t)
    out = {"delta_e76_mean": float(de.mean()), "delta_e76_p95": float(np.percentile(de, 95)),
           "delta_e2000_mean": float(delta_e2000(lab_p, lab_t).mean()), "ssim": loss.ssim_mean(rgb, var_mean)}
    if var_mean is not None:
        se = lab_stderr(np.asarray(rgb, np.float64), np.asarray(var_mean, np.float64))
        out["delta_e76_noise"] = float(se.mean())
        out["delta_e76_rms"] = float(np.sqrt(np.mean(de * de)))
        # E|c + n - t|^2 = |c - t|^2 + tr(cov n) (to first order in Lab): an unbiased estimate of the noise-free
        # mean squared ΔE76
        out["delta_e76_rms_denoised"] = float(np.sqrt(max(0.0, np.mean(de * de - se * se))))
    return out


# ----------------------------------------------------------------------------------------------- texel maps
def map_texels(printer: Texels, voxel_mm_printer, scene: Texels, voxel_mm_scene, per_face: bool = True):
    """Scene texel (int64 (Ip,)) of each printer texel, and for every scene texel the printer texel that stands in
    for it when none maps to it (int64 (I,), -1 where some do). Nearest face centre in mm, within the same face
    id if ``per_face`` (slabs), else over all texels (meshes)."""
    ps, pp = scene.position_mm(voxel_mm_scene), printer.position_mm(voxel_mm_printer)
    to_scene = np.full(len(printer), -1, np.int64)
    stand_in = np.full(len(scene), -1, np.int64)
    groups = np.unique(scene.face) if per_face else [None]
    for f in groups:
        s_idx = np.flatnonzero(scene.face == f) if f is not None else np.arange(len(scene))
        p_idx = np.flatnonzero(printer.face == f) if f is not None else np.arange(len(printer))
        if len(p_idx) == 0:
            raise ValueError(f"the quantized volume has no texels on face {int(f)} of the scene")
        _, near = cKDTree(ps[s_idx]).query(pp[p_idx], workers=-1)
        to_scene[p_idx] = s_idx[near]
        cnt = np.bincount(near, minlength=len(s_idx))
        empty = np.flatnonzero(cnt == 0)
        if len(empty):
            _, back = cKDTree(pp[p_idx]).query(ps[s_idx[empty]], workers=-1)
            stand_in[s_idx[empty]] = p_idx[back]
    if np.any(to_scene < 0):
        raise ValueError("the quantized volume has texels on faces the scene does not texture")
    return to_scene, stand_in


def average_to_scene(rgb_p, var_p, to_scene, stand_in, n_scene: int):
    """Per-scene-texel mean (I, 3) of printer texel colours, and the variance of that mean (I, 3)."""
    cnt = np.bincount(to_scene, minlength=n_scene).astype(np.float64)
    rgb = np.stack([np.bincount(to_scene, rgb_p[:, c], n_scene) for c in range(3)], 1)
    var = np.stack([np.bincount(to_scene, var_p[:, c], n_scene) for c in range(3)], 1)
    has = cnt > 0
    rgb[has] /= cnt[has, None]
    var[has] /= (cnt[has] ** 2)[:, None]
    miss = np.flatnonzero(~has)
    rgb[miss], var[miss] = rgb_p[stand_in[miss]], var_p[stand_in[miss]]
    return rgb, var


def printer_texels(qvol: Volume, scene: Texels, kind: str) -> Texels:
    if kind == "mesh":
        return Texels.for_volume(qvol)
    return Texels.for_volume(qvol, sorted({int(f) for f in np.unique(scene.face)}))


def render_printed(qvol: Volume, scene: Texels, voxel_mm_scene, kind: str, spp: int, seed: int, threads=None,
                   progress: bool = False):
    """Render a labels volume on its printer texels and average onto the scene texels.

    Returns (rgb (I, 3), var_mean (I, 3), spp_printer, seconds, printer texel count)."""
    from .render import Renderer

    t0 = time.perf_counter()
    ptex = printer_texels(qvol, scene, kind)
    to_scene, stand_in = map_texels(ptex, qvol.voxel_mm, scene, voxel_mm_scene, per_face=kind != "mesh")
    spp_p = max(1, int(np.ceil(spp * len(scene) / len(ptex))))
    res = Renderer(qvol, threads).render(ptex, spp_p, seed, progress=progress)
    rgb, var = average_to_scene(res.rgb.astype(np.float64), res.var_mean.astype(np.float64), to_scene, stand_in,
                                len(scene))
    return rgb, var, spp_p, time.perf_counter() - t0, len(ptex)


# ----------------------------------------------------------------------------------------------- pictures
def face_picture(panels, pix) -> "Image.Image":
    """Side-by-side labelled panels: panels = [(label, rgb (I, 3) linear)], pix (H, W) texel index per pixel
    (row 0 = top; negative = no texel). Nearest-neighbour upscaling to >= 256 px panel width."""
    from PIL import Image, ImageDraw

    pix = np.asarray(pix, np.int64)
    h, w = pix.shape
    s = max(1, int(np.ceil(PANEL_MIN_WIDTH / w)))
    gap, band = 8, 20
    pw, ph = w * s, h * s
    canvas = Image.new("RGB", (len(panels) * pw + (len(panels) + 1) * gap, ph + band + gap), (255, 255, 255))
    draw = ImageDraw.Draw(canvas)
    for j, (label, rgb) in enumerate(panels):
        srgb = np.clip(linear_to_srgb(np.asarray(rgb, np.float64)), 0.0, 1.0)
        img = np.round(srgb[np.maximum(pix, 0)] * 255).astype(np.uint8)
        img[pix < 0] = 128
        img = np.repeat(np.repeat(img, s, 0), s, 1)
        x0 = gap + j * (pw + gap)
        canvas.paste(Image.fromarray(img), (x0, band))
        draw.text((x0, 4), label, fill=(0, 0, 0))
    return canvas


def write_face_pictures(d: Path, scene, results: dict) -> list[str]:
    """DIR/evaluation_<face>.png for every face in the scene's ``faces``; returns the file names."""
    names = []
    panels_rgb = [("target", results["target"]), ("optimized", results["continuous"]),
                  ("quantized", results["quantized"])]
    panels_rgb += [(k, results[k]) for k in ("surface", "extrusion") if k in results]
    for face in [str(f) for f in np.asarray(scene["faces"]).reshape(-1)]:
        key = f"pix_{face}"
        if key not in scene:
            continue
        buf = io.BytesIO()
        face_picture(panels_rgb, scene[key]).save(buf, format="PNG")
        name = f"evaluation_{face}.png"
        atomic_write_bytes(d / name, buf.getvalue())
        names.append(name)
    return names


# ----------------------------------------------------------------------------------------------- the stage
def load_scene(d: Path) -> dict:
    path = d / "scene.npz"
    if not path.is_file():
        raise ValueError(f"{path} does not exist (run 'inkopt slab' or 'inkopt optimize' first)")
    try:
        with np.load(path, allow_pickle=False) as z:
            scene = dict(z)
    except Exception as exc:
        raise ValueError(f"{path} is not a readable .npz file ({type(exc).__name__})") from None
    for k in ("texel_voxel", "texel_face", "texel_normal", "target_rgb"):
        if k not in scene:
            raise ValueError(f"{path} lacks array '{k}'")
    return scene


def evaluate_run(path, spp: int = DEFAULT_SPP, seed: int = 0, method: str | None = None, threads=None,
                 baselines: bool = True, refine: bool = True, patch_mm: float = DEFAULT_PATCH_MM,
                 table: ColourTable | None = None, write: bool = True, log=None) -> dict:
    """Evaluate run directory ``path`` (module docstring); returns the evaluation dict (also written to
    DIR/evaluation.json with the face pictures when ``write``). ``method``: quantization method of ours (when
    quantized.npz is missing) and of the baselines; None = that of quantized.npz, else blue-noise.
    table: the baselines' colour table (default ``colour_table(inks, g, ior, patch_mm)``, cached).
    ``log``: callable taking one progress line (default: silent)."""
    from .render import Renderer

    say = log or (lambda msg: None)
    if spp < 1:
        raise ValueError(f"spp must be at least 1, got {spp}")
    d = run_dir(path)
    vol = load_run_volume(d)
    scene = load_scene(d)
    stex = Texels.from_arrays(scene)
    target = np.asarray(scene["target_rgb"], np.float64)
    if target.shape != (len(stex), 3) or len(stex) == 0:
        raise ValueError(f"scene target_rgb has shape {target.shape}, expected ({len(stex)}, 3) with texels")
    kind = str(scene.get("kind", "slab"))
    t_all = time.perf_counter()
    loss = TexelLoss(target, stex.pos_vox, sigma=1.5)
    out = {"spp": int(spp), "seed": int(seed), "texels": len(stex), "kind": kind}
    colours = {"target": target}

    t0 = time.perf_counter()
    res = Renderer(vol, threads).render(stex, spp, seed, progress=log is not None)
    colours["continuous"] = res.rgb.astype(np.float64)
    out["continuous"] = {**texel_metrics(res.rgb, target, loss, res.var_mean), "spp": int(spp),
                         "seconds": time.perf_counter() - t0, "method": None}
    say(f"continuous: {len(stex)} texels x {spp} spp in {out['continuous']['seconds']:.1f} s")

    qpath = d / "quantized.npz"
    if qpath.is_file():
        qvol = Volume.load(qpath)
        if qvol.form != "labels":
            raise ValueError(f"{qpath} holds a {qvol.form} volume, not printer labels")
        qs = quantization_settings(qvol)
        if method is not None and method != qs["method"]:
            raise ValueError(f"{qpath} was quantized with '{qs['method']}', not '{method}'; rerun 'inkopt quantize "
                             f"{d} --method {method}' or omit --method")
    else:
        t0 = time.perf_counter()
        qvol = quantize_volume(vol, method=method or "blue-noise")
        qvol.save(qpath)
        qs = quantization_settings(qvol)
        say(f"quantized {vol.shape} -> {qvol.shape} ({qs['method']}) in {time.perf_counter() - t0:.1f} s; "
            f"wrote {qpath}")
    out["quantization"] = qs
    qkw = dict(method=qs["method"], seed=qs["seed"], upsample=qs["upsample"],
               dpi=tuple(qs["dpi"]) if qs["dpi"] else tuple(25.4 / qvol.voxel_mm))

    def printed(name: str, q: Volume) -> dict:
        rgb, var, spp_p, secs, n_p = render_printed(q, stex, vol.voxel_mm, kind, spp, seed, threads,
                                                    progress=log is not None)
        colours[name] = rgb
        say(f"{name}: {n_p} printer texels x {spp_p} spp in {secs:.1f} s")
        out["printer_texels"] = n_p
        return {**texel_metrics(rgb, target, loss, var), "spp": int(spp), "spp_printer": spp_p,
                "seconds": secs, "method": qs["method"]}

    out["quantized"] = printed("quantized", qvol)
    del qvol
    if baselines:
        t0 = time.perf_counter()
        if table is None:
            table = colour_table(vol.inks, vol.g, vol.ior, patch_mm=patch_mm, threads=threads,
                                 progress=log is not None)
        say(f"colour table: {len(table.lab)} patches of {table.patch_mm:g} mm, step 1/{table.step}, "
            + ("(cached)" if table.cached else f"built in {table.seconds:.0f} s"))
        out["colour_table"] = {"entries": len(table.lab), "patch_mm": table.patch_mm, "step": table.step,
                               "max_stderr": float(table.stderr.max()), "refine": bool(refine),
                               "key": table.key, "cached": table.cached, "build_seconds": table.seconds,
                               "seconds": time.perf_counter() - t0}
        out["baselines"] = {}
        for name, fn in (("surface", surface_baseline), ("extrusion", extrusion_baseline)):
            mix = fn(vol, scene, table, refine=refine)
            qb = quantize_volume(vol.with_mixture(mix), **qkw)
            out["baselines"][name] = printed(name, qb)
    out["seconds"] = time.perf_counter() - t_all
    if write:
        if kind == "slab" and "faces" in scene:
            out["pictures"] = write_face_pictures(d, scene, colours)
        atomic_write_bytes(d / "evaluation.json", (json.dumps(out, indent=1) + "\n").encode())
    return out


def table_lines(ev: dict) -> list[str]:
    """A plain-text table of an evaluation dict."""
    rows = [("continuous", ev["continuous"]), ("quantized", ev["quantized"])]
    rows += [(f"{k} baseline", v) for k, v in ev.get("baselines", {}).items()]
    nan = float("nan")
    lines = [f"{'result':<20}{'dE76 mean':>10}{'dE76 p95':>10}{'dE2000':>9}{'SSIM':>8}{'noise':>8}"
             f"{'rms w/o noise':>15}{'s':>7}"]
    for name, m in rows:
        lines.append(f"{name:<20}{m['delta_e76_mean']:>10.2f}{m['delta_e76_p95']:>10.2f}"
                     f"{m['delta_e2000_mean']:>9.2f}{m['ssim']:>8.3f}{m.get('delta_e76_noise', nan):>8.2f}"
                     f"{m.get('delta_e76_rms_denoised', nan):>15.2f}{m['seconds']:>7.1f}")
    return lines
