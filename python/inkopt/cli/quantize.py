"""``inkopt quantize DIR``: the run's continuous mixture (DIR/volume.npz) -> one ink per printer voxel
(DIR/quantized.npz, a labels volume file at printer resolution; docs/run-dir.md).

``quantize_volume`` is the stage as a function (used by ``inkopt evaluate`` for its baselines as well).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .quantize import DEFAULT_DPI, DEFAULT_LAYER_UM, METHODS, MM_PER_INCH, UPSAMPLE, _enclosing, quantize
from .volume import EMPTY, MAX_VOLUME_BYTES, Volume

# Nearest-upsampled shading normals (12 bytes per printer voxel) are kept up to this size; above it the quantized
# volume has none (its texels are then flat voxel faces).
MAX_NORMALS_BYTES = 2 * 2**30


def run_dir(path) -> Path:
    d = Path(path)
    if not d.is_dir():
        raise ValueError(f"run directory {d} does not exist")
    return d


def load_run_volume(d: Path) -> Volume:
    path = d / "volume.npz"
    if not path.is_file():
        raise ValueError(f"{path} does not exist (run 'inkopt slab' or 'inkopt optimize' first)")
    vol = Volume.load(path)
    if vol.form != "mixture":
        raise ValueError(f"{path} holds a {vol.form} volume; quantization needs a mixture volume")
    return vol


def parse_dpi(text: str):
    """'600x300' or '600x300x940' -> tuple of 2 or 3 positive floats."""
    try:
        vals = tuple(float(v) for v in str(text).lower().split("x"))
    except ValueError:
        vals = ()
    if len(vals) not in (2, 3) or not all(np.isfinite(v) and v > 0 for v in vals):
        raise ValueError(f"--dpi must look like 600x300 or 600x300x940 (positive numbers), got '{text}'")
    return vals


def quantize_volume(volume: Volume, *, method: str = "blue-noise", dpi=DEFAULT_DPI,
                    layer_um: float = DEFAULT_LAYER_UM, seed: int = 0, upsample: str = "nearest",
                    normals: bool = True) -> Volume:
    """A labels Volume at printer resolution from a mixture Volume (``inkopt.quantize.quantize``).

    dpi (x, y) or (x, y, z) printer DPI (z None/absent -> ``layer_um`` µm layers). Keeps inks, g, ior, boundary;
    ``inside`` is encoded by label 255. Shading normals (meshes) are upsampled by nearest if ``normals`` and
    they fit ``MAX_NORMALS_BYTES``. ``extra``: method, seed, dpi (3,) float64 (x, y, z), upsample.
    """
    if volume.form != "mixture":
        raise ValueError(f"quantization needs a mixture volume, got a {volume.form} volume")
    if method not in METHODS:
        raise ValueError(f"unknown quantization method '{method}'; use one of {list(METHODS)}")
    if upsample not in UPSAMPLE:
        raise ValueError(f"unknown upsample '{upsample}'; use one of {list(UPSAMPLE)}")
    labels, vp = quantize(volume.mixture, volume.voxel_mm, method=method, dpi=tuple(dpi), layer_um=layer_um,
                          inside=volume.inside, seed=int(seed), upsample=upsample)
    nrm = None
    fits = labels.size * 12 <= MAX_NORMALS_BYTES and labels.size * 13 <= MAX_VOLUME_BYTES
    if normals and volume.normals is not None and fits:
        (nz, ny, nx), vo = volume.shape, volume.voxel_mm
        Z, Y, X = labels.shape
        iz, iy, ix = (_enclosing(Z, vp[2], nz, vo[2]), _enclosing(Y, vp[1], ny, vo[1]),
                      _enclosing(X, vp[0], nx, vo[0]))
        nrm = np.empty(labels.shape + (3,), np.float32)
        for k in range(Z):  # one printer layer at a time (bounded temporaries)
            nrm[k] = volume.normals[iz[k]][iy][:, ix]
    extra = {"method": np.array(method), "seed": np.int64(seed),
             "dpi": (MM_PER_INCH / np.asarray(vp, np.float64)), "upsample": np.array(upsample)}
    return Volume(voxel_mm=vp, labels=labels, inks=volume.inks, g=volume.g, ior=volume.ior, inside=None,
                  normals=nrm, boundary=volume.boundary, extra=extra)


def quantization_settings(qvol: Volume) -> dict:
    """method, seed, dpi (x, y, z), upsample stored in a quantized volume (defaults for missing entries)."""
    ex = qvol.extra
    return {"method": str(ex.get("method", "blue-noise")), "seed": int(ex.get("seed", 0)),
            "dpi": [float(v) for v in np.asarray(ex["dpi"]).reshape(-1)] if "dpi" in ex else None,
            "upsample": str(ex.get("upsample", "nearest"))}


def summary_lines(qvol: Volume, seconds: float, skipped_normals: bool) -> list[str]:
    lab = qvol.labels
    counts = np.zeros(256, np.int64)
    for k in range(lab.shape[0]):
        counts += np.bincount(lab[k].ravel(), minlength=256)
    filled = int(counts[:EMPTY].sum())
    Z, Y, X = lab.shape
    vp = qvol.voxel_mm
    out = [f"printer grid {X} x {Y} x {Z} (x, y, z) voxels of {vp[0] * 1000:.1f} x {vp[1] * 1000:.1f} x "
           f"{vp[2] * 1000:.1f} um ({qvol.extra['dpi'][0]:.0f} x {qvol.extra['dpi'][1]:.0f} DPI, "
           f"{vp[2] * 1000:.1f} um layers)",
           f"{filled} ink voxels ({counts[EMPTY]} empty); method {qvol.extra['method']}, seed "
           f"{int(qvol.extra['seed'])}, upsample {qvol.extra['upsample']}; {seconds:.1f} s",
           "inks: " + ", ".join(f"{n} {counts[i]} ({100.0 * counts[i] / max(filled, 1):.1f} %)"
                                for i, n in enumerate(qvol.inks.names))]
    if skipped_normals:
        out.append(f"note: shading normals not kept (they would need {lab.size * 12 / 2**30:.1f} GiB); "
                   "the quantized volume's texels are flat voxel faces")
    return out


def _quantize_cmd(args) -> int:
    d = run_dir(args.dir)
    vol = load_run_volume(d)
    if args.method not in METHODS:
        raise ValueError(f"unknown quantization method '{args.method}'; use one of {list(METHODS)}")
    if args.upsample not in UPSAMPLE:
        raise ValueError(f"unknown upsample '{args.upsample}'; use one of {list(UPSAMPLE)}")
    if args.dpi is not None and args.layer_um is not None and len(parse_dpi(args.dpi)) == 3:
        raise ValueError("give the layer thickness once: --dpi XxYxZ or --layer-um, not both")
    dpi = parse_dpi(args.dpi) if args.dpi is not None else DEFAULT_DPI
    layer = DEFAULT_LAYER_UM if args.layer_um is None else float(args.layer_um)
    if not (np.isfinite(layer) and layer > 0):
        raise ValueError(f"--layer-um must be positive, got {args.layer_um}")
    t0 = time.perf_counter()
    q = quantize_volume(vol, method=args.method, dpi=dpi, layer_um=layer, seed=args.seed, upsample=args.upsample)
    q.save(d / "quantized.npz")
    skipped = vol.normals is not None and q.normals is None
    for line in summary_lines(q, time.perf_counter() - t0, skipped):
        print(line)
    print(f"wrote {d / 'quantized.npz'}")
    return 0


def register_cli(sub) -> None:
    p = sub.add_parser("quantize", help="one ink per printer voxel: DIR/volume.npz -> DIR/quantized.npz",
                       description="Quantize a run's optimised mixture to one ink per printer voxel (600 x 300 "
                                   "DPI, 27 um layers by default) and write DIR/quantized.npz.")
    p.add_argument("dir", help="run directory holding volume.npz")
    p.add_argument("--method", default="blue-noise",
                   help="blue-noise (ordered dithering, default) or random (the paper's independent draws)")
    p.add_argument("--dpi", help="printer resolution XxY or XxYxZ dots per inch (default 600x300)")
    p.add_argument("--layer-um", type=float, help=f"layer thickness in um (default {DEFAULT_LAYER_UM:g})")
    p.add_argument("--seed", type=int, default=0, help="random draws / blue-noise tile offset (default 0)")
    p.add_argument("--upsample", default="nearest", help="nearest (default) or linear mixture upsampling")
    p.set_defaults(func=_quantize_cmd)
