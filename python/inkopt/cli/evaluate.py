"""``inkopt evaluate DIR``: ΔE76, ΔE2000 and SSIM of the continuous result, the quantized (printed) result and the
naive baselines against the target; writes DIR/evaluation.json and DIR/evaluation_<face>.png
(``inkopt.evaluation.evaluate``).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..evaluation.colour_table import DEFAULT_PATCH_MM
from ..evaluation.evaluate import DEFAULT_SPP, evaluate_run, table_lines
from ..evaluation.noise import MAX_SPP, PILOT_SPP, TARGET_NOISE_DE76
from ..evaluation.sample import AUTO_SAMPLE_TEXELS, DEFAULT_SAMPLE_TEXELS, DEFAULT_SAMPLE_WINDOWS
from ..model import Quantization
from ..printing.quantize import check_quantization
from .common import add_lighting_args, check_budget, lighting_from_args


def _evaluate_cmd(args) -> int:
    if args.method is not None:
        check_quantization(Quantization(args.method))
    check_budget(args.max_spp, args.time_budget)
    log = None if args.json else (lambda msg: print(msg, file=sys.stderr, flush=True))
    ev = evaluate_run(
        args.dir,
        spp=args.spp,
        seed=args.seed,
        method=args.method,
        threads=args.threads,
        baselines=not args.no_baselines,
        refine=not args.nearest,
        patch_mm=args.patch_mm,
        lighting=lighting_from_args(args),
        log=log,
        translucency=False if args.no_translucency else None,
        translucency_compare=args.translucency_compare,
        max_spp=args.max_spp,
        time_budget=args.time_budget,
        out=args.out,
        texel_sample=args.texel_sample,
        sample_windows=args.sample_windows,
    )
    if args.json:
        print(json.dumps(ev.to_json()))
    else:
        for line in table_lines(ev):
            print(line)
        how = "adaptive, " if ev.spp_adaptive else ""
        rotate = ev.lighting.get("lighting_rotate_deg")
        print(f"lighting: {ev.lighting['lighting']}" + (f", turned {rotate:g} degrees" if rotate else ""))
        print(
            f"{ev.spp} spp per scene texel ({how}continuous result), {ev.seconds:.0f} s; wrote "
            f"{args.out or f'{args.dir}/evaluation.json'}"
            + "".join(f", {Path(args.dir) / p}" for p in ev.pictures or [])
        )
    return 0


def register_cli(sub) -> None:
    p = sub.add_parser(
        "evaluate",
        help="colour error and SSIM of a run, its printed version and the baselines",
        description="Render a run's continuous and quantized results and two naive baselines "
        "(surface colouring, extrusion) and compare them with the target.",
    )
    p.add_argument("dir", help="run directory holding volume.npz and scene.npz")
    p.add_argument(
        "--spp",
        type=int,
        default=DEFAULT_SPP,
        help=f"samples per scene texel, used exactly; printer texels share them (default: adaptive, "
        f"a {PILOT_SPP}-spp pilot and then as many as make the Monte Carlo noise add at most "
        f"{TARGET_NOISE_DE76:g} to each result's mean dE76 and keep SSIM's and the mottle's noise "
        f"correction accurate, up to {MAX_SPP})",
    )
    p.add_argument(
        "--max-spp",
        type=int,
        default=MAX_SPP,
        metavar="N",
        help=f"cap of the adaptive samples per scene texel of each result (default {MAX_SPP})",
    )
    p.add_argument(
        "--time-budget",
        type=float,
        metavar="SECONDS",
        help="time for the adaptive renders together, shared out among the results (default: none); each "
        "further pass is logged with its expected time",
    )
    p.add_argument(
        "--out",
        metavar="FILE.json",
        help="write the evaluation here instead of DIR/evaluation.json (its pictures are named after it in DIR), "
        "keeping earlier evaluations",
    )
    p.add_argument(
        "--texel-sample",
        type=int,
        metavar="N",
        help=f"figures from a random sample of N scene texels (and --sample-windows SSIM windows), each with its "
        f"standard error; 0 renders every texel (default: {DEFAULT_SAMPLE_TEXELS} above {AUTO_SAMPLE_TEXELS} "
        f"texels, else every texel); no pictures then",
    )
    p.add_argument(
        "--sample-windows",
        type=int,
        metavar="M",
        help=f"SSIM and mottle windows of a texel sample, each a texel with every neighbour its window reaches "
        f"(default {DEFAULT_SAMPLE_WINDOWS})",
    )
    p.add_argument("--seed", type=int, default=0, help="render seed (default 0)")
    p.add_argument("--method", help="quantization method (default: that of DIR/quantized.npz, else blue-noise)")
    p.add_argument("--threads", type=int, help="render threads (default: all cores)")
    p.add_argument(
        "--patch-mm",
        type=float,
        default=DEFAULT_PATCH_MM,
        help=f"thickness of the baselines' colour-chart patches (default {DEFAULT_PATCH_MM} mm)",
    )
    p.add_argument(
        "--nearest",
        action="store_true",
        help="baselines: nearest colour-table entry instead of the blend of the 8 nearest",
    )
    p.add_argument("--no-baselines", action="store_true", help="skip the baselines")
    p.add_argument("--json", action="store_true", help="print the evaluation as one JSON object, no progress")
    p.add_argument(
        "--translucency-compare",
        metavar="DIR2",
        help="also measure the translucency of DIR2 (an unconstrained run of the same target) on DIR's "
        "translucent regions, beside DIR's own",
    )
    p.add_argument(
        "--no-translucency",
        action="store_true",
        help="skip the translucency figures (transmittance, lateral spread) of a constrained run",
    )
    add_lighting_args(p, "evaluate")
    p.set_defaults(func=_evaluate_cmd)
