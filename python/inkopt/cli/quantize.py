"""``inkopt quantize DIR``: the run's continuous mixture (DIR/volume.npz) -> one ink per printer voxel
(DIR/quantized.npz + DIR/quantized_labels.npy, a labels volume at printer resolution; docs/run-dir.md). The stage
is ``inkopt.printing.stream.quantize_run`` (layer by layer; ``inkopt.printing.quantize``)."""

from __future__ import annotations

import numpy as np

from ..printing.quantize import DEFAULT_DPI, DEFAULT_LAYER_UM, check_quantization
from ..printing.stream import quantize_run
from ..rundir import RunDir
from ..units import parse_dpi


def _quantize_cmd(args) -> int:
    d = RunDir(args.dir)
    check_quantization(args.method, args.upsample)
    if args.dpi is not None and args.layer_um is not None and len(parse_dpi(args.dpi)) == 3:
        raise ValueError("give the layer thickness once: --dpi XxYxZ or --layer-um, not both")
    dpi = parse_dpi(args.dpi) if args.dpi is not None else DEFAULT_DPI
    layer = DEFAULT_LAYER_UM if args.layer_um is None else float(args.layer_um)
    if not (np.isfinite(layer) and layer > 0):
        raise ValueError(f"--layer-um must be positive, got {args.layer_um}")
    for line in quantize_run(d, method=args.method, dpi=dpi, layer_um=layer, seed=args.seed, upsample=args.upsample):
        print(line)
    print(f"wrote {d.quantized_path} and {d.quantized_labels_path}")
    return 0


def register_cli(sub) -> None:
    p = sub.add_parser(
        "quantize",
        help="one ink per printer voxel: DIR/volume.npz -> DIR/quantized.npz (+ quantized_labels.npy)",
        description="Quantize a run's optimised mixture to one ink per printer voxel (600 x 300 "
        "DPI, 27 um layers by default) and write DIR/quantized.npz.",
    )
    p.add_argument("dir", help="run directory holding volume.npz")
    p.add_argument(
        "--method",
        default="blue-noise",
        help="blue-noise (ordered dithering, default), random (the paper's independent draws) or "
        "error-diffusion (deterministic 3D vector error diffusion)",
    )
    p.add_argument("--dpi", help="printer resolution XxY or XxYxZ dots per inch (default 600x300)")
    p.add_argument("--layer-um", type=float, help=f"layer thickness in um (default {DEFAULT_LAYER_UM:g})")
    p.add_argument("--seed", type=int, default=0, help="random draws / blue-noise tile offset (default 0)")
    p.add_argument("--upsample", default="nearest", help="nearest (default) or linear mixture upsampling")
    p.set_defaults(func=_quantize_cmd)
