"""``inkopt quantize DIR``: the run's continuous mixture (DIR/volume.npz) -> one ink per printer voxel
(DIR/quantized.npz + DIR/quantized_labels.layers, a labels volume at printer resolution; docs/run-dir.md). The stage
is ``inkopt.evaluation.halftone_choice.quantize_run_as``: ``inkopt.printing.stream.quantize_run`` (layer by layer;
``inkopt.printing.quantize``), twice where the run chooses the compensation (``--compensate-auto``, the default);
the other arguments become one ``model.Quantization``. The run folder's lock (``RunDir.lock``) is held while it
writes."""

from __future__ import annotations

from ..evaluation.halftone_choice import DEFAULT_COMPENSATE, quantize_run_as
from ..model import Quantization
from ..printing.dithers import DITHERS, INK_ORDERS
from ..printing.grid import DEFAULT_LAYER_UM, UPSAMPLERS
from ..rundir import RunDir
from ..units import parse_dpi
from .common import add_seed_arg, stderr_log


def quantization_of(args) -> Quantization:
    """The settings the arguments give but the compensation (``args.compensate``: ``halftone_choice.COMPENSATE``),
    checked by ``printing.quantize.check_quantization``."""
    dpi = None if args.dpi is None else parse_dpi(args.dpi)
    return Quantization(args.method, args.seed, dpi, args.upsample, args.ink_order, args.layer_um, args.refine)


def _quantize_cmd(args) -> int:
    d = RunDir(args.dir)
    q = quantization_of(args)
    with d.lock(stderr_log):
        lines = quantize_run_as(d, q, args.compensate, log=stderr_log)
    for line in lines:
        print(line)
    print(f"wrote {d.quantized_path} and {d.quantized_labels_path}")
    return 0


def register_cli(sub) -> None:
    p = sub.add_parser(
        "quantize",
        help="one ink per printer voxel: DIR/volume.npz -> DIR/quantized.npz (+ quantized_labels.layers)",
        description="Quantize a run's optimised mixture to one ink per printer voxel (600 x 300 "
        "DPI, 27 um layers by default) and write DIR/quantized.npz.",
    )
    p.add_argument("dir", help="run directory holding volume.npz")
    default = Quantization()
    methods = [f"{name} ({cls.help}{', default' if name == default.method else ''})" for name, cls in DITHERS.items()]
    p.add_argument("--method", default=default.method, help=", ".join(methods[:-1]) + " or " + methods[-1])
    p.add_argument("--dpi", help="printer resolution XxY or XxYxZ dots per inch (default 600x300)")
    p.add_argument("--layer-um", type=float, help=f"layer thickness in um (default {DEFAULT_LAYER_UM:g})")
    add_seed_arg(p, "random draws / blue-noise tile offset")
    upsample = [name + " (default)" if name == default.upsample else name for name in UPSAMPLERS]
    p.add_argument("--upsample", default=default.upsample, help=" or ".join(upsample) + " mixture upsampling")
    p.add_argument(
        "--refine",
        type=int,
        default=default.refine,
        metavar="N",
        help=f"N final iterations with the loss taken on the dithered labels' render (default {default.refine}; "
        "each costs about one print render at 16 spp and a gradient pass; docs/quality.md)",
    )
    p.add_argument(
        "--ink-order",
        choices=list(INK_ORDERS),
        default=default.ink_order,
        help=f"the inks' order in blue noise's bands (default {default.ink_order}: lightest first; tint-first: the "
        "second lightest ink, yellow, before white, its voxels spread more evenly where it mixes with darker inks; "
        "index: the ink set's order; docs/quality.md)",
    )
    p.add_argument(
        "--compensate",
        dest="compensate",
        action="store_const",
        const="on",
        default=DEFAULT_COMPENSATE,
        help="give the dither each ink's share pre-compensated for the halftone (a dithered ink looks lighter than "
        "its mixture; the default inks' factors ship with inkopt, another ink set or printer grid is measured once "
        "on flat patches, about two minutes, then cached; docs/quality.md)",
    )
    p.add_argument("--no-compensate", dest="compensate", action="store_const", const="off", help="dither plain")
    p.add_argument(
        "--compensate-auto",
        dest="compensate",
        action="store_const",
        const="auto",
        help=f"{'(default) ' if DEFAULT_COMPENSATE == 'auto' else ''}quantize both ways and keep the compensated "
        "labels only where the run's printed prediction on a texel sample is closer to its target in dE76 beyond "
        "two standard errors and not further in dE2000 beyond them (two quantizations and two sample renders; "
        "plain where the inks' factors are not shipped or cached, and for runs seen under other lights)",
    )
    p.set_defaults(func=_quantize_cmd)
