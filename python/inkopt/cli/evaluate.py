"""``inkopt evaluate DIR``: ΔE76, ΔE2000 and SSIM of the continuous result, the quantized (printed) result and the
naive baselines against the target; writes DIR/evaluation.json and DIR/evaluation_<face>.png
(``inkopt.evaluation.evaluate``). An existing file at ``--out`` is replaced only if it is an evaluation
(``RunDir.evaluation_target``); it holds the run folder's lock (``RunDir.lock``) while it works.
"""

from __future__ import annotations

import json
from pathlib import Path

from ..evaluation.colour_table import DEFAULT_PATCH_MM
from ..evaluation.evaluate import evaluate_run
from ..evaluation.noise import MAX_SPP, PILOT_SPP, TARGET_NOISE_DE76
from ..evaluation.options import EvaluateOptions
from ..evaluation.outputs import picture_names, table_lines
from ..evaluation.sample import DEFAULT_SAMPLE_WINDOWS
from ..evaluation.spectral import evaluate_lights, run_viewing
from ..evaluation.translucency import table_lines as translucency_lines
from ..rundir import RunDir
from .common import UsageError, add_lighting_args, add_seed_arg, add_threads_arg, lighting_from_args, stderr_log
from .lights import under_lights

#: the options of ``inkopt evaluate`` after DIR, in the order of its help: (flag, add_argument keywords)
OPTIONS = (
    (
        "--spp",
        dict(
            type=int,
            help=f"samples per scene texel, used exactly; printer texels share them (default: adaptive, a {PILOT_SPP}-"
            f"spp pilot and then as many as make the Monte Carlo noise add at most {TARGET_NOISE_DE76:g} to each "
            f"result's mean dE76 and keep SSIM's and the mottle's noise correction accurate, up to {MAX_SPP})",
        ),
    ),
    (
        "--max-spp",
        dict(
            type=int,
            default=MAX_SPP,
            metavar="N",
            help=f"cap of the adaptive samples per scene texel of each result (default {MAX_SPP})",
        ),
    ),
    (
        "--time-budget",
        dict(
            type=float,
            metavar="SECONDS",
            help="time for the adaptive renders together, shared out among the results (default: none); each "
            "further pass is logged with its expected time",
        ),
    ),
    (
        "--out",
        dict(
            metavar="FILE.json",
            help="write the evaluation here instead of DIR/evaluation.json (its pictures are named after it in "
            "DIR), keeping earlier evaluations",
        ),
    ),
    (
        "--texel-sample",
        dict(
            type=int,
            metavar="N",
            help="figures from a random sample of N scene texels (and --sample-windows SSIM windows), each with its "
            "standard error, and no pictures or predictions.npz (a spectral run: predictions_sample.npz, the "
            "sample's values); 0 renders every texel (default: whichever a short "
            "pilot predicts to be clearly faster at the same accuracy of the mean dE76, logged and recorded as "
            "sampling_choice; the sample then has the texels whose standard error is that accuracy)",
        ),
    ),
    (
        "--sample-windows",
        dict(
            type=int,
            metavar="M",
            help=f"SSIM and mottle windows of a texel sample, each a texel with every neighbour its window reaches "
            f"(default {DEFAULT_SAMPLE_WINDOWS})",
        ),
    ),
    ("--method", dict(help="quantization method (default: that of DIR/quantized.npz, else count-adaptive)")),
    (
        "--patch-mm",
        dict(
            type=float,
            default=DEFAULT_PATCH_MM,
            help=f"thickness of the baselines' colour-chart patches (default {DEFAULT_PATCH_MM} mm)",
        ),
    ),
    (
        "--nearest",
        dict(action="store_true", help="baselines: nearest colour-table entry instead of the blend of the 8 nearest"),
    ),
    ("--no-baselines", dict(action="store_true", help="skip the baselines")),
    ("--json", dict(action="store_true", help="print the evaluation as one JSON object, no progress")),
    (
        "--translucency-compare",
        dict(
            metavar="DIR2",
            help="also measure the translucency of DIR2 (an unconstrained run of the same target) on DIR's "
            "translucent regions, beside DIR's own",
        ),
    ),
    (
        "--no-translucency",
        dict(
            action="store_true",
            help="skip the translucency figures (transmittance, lateral spread) of a constrained run",
        ),
    ),
)


def options_from_args(args) -> EvaluateOptions:
    """The ``EvaluateOptions`` of the parsed arguments (checked there: a bad value names its flag)."""
    return EvaluateOptions(
        spp=args.spp,
        max_spp=args.max_spp,
        time_budget=args.time_budget,
        seed=args.seed,
        threads=args.threads,
        lighting=lighting_from_args(args),
        method=args.method,
        baselines=not args.no_baselines,
        patch_mm=args.patch_mm,
        refine=not args.nearest,
        translucency=False if args.no_translucency else None,
        translucency_compare=args.translucency_compare,
        texel_sample=args.texel_sample,
        sample_windows=args.sample_windows,
        out=args.out,
    )


def _evaluate_cmd(args) -> int:
    options = options_from_args(args)
    log = None if args.json else stderr_log
    d = RunDir(args.dir)
    if args.illuminants is not None or (d.report_path.is_file() and run_viewing(d) is not None):
        return _evaluate_lights(args, d, options, log)
    d.evaluation_target(args.out)  # before any render: another kind of file at --out is never replaced
    d.evaluation_picture_targets(args.out, picture_names(d.load_scene()))  # nor a picture named after it
    with d.lock(stderr_log):  # its pictures and predictions.npz go into the run folder whatever --out says
        ev = evaluate_run(args.dir, options, log)
    if args.json:
        print(json.dumps(ev.to_json()))
        return 0
    for line in table_lines(ev):
        print(line)
    how = "adaptive, " if ev.spp_adaptive else ""
    rotate = ev.lighting.get("lighting_rotate_deg")
    print(f"lighting: {ev.lighting['lighting']}" + (f", turned {rotate:g} degrees" if rotate else ""))
    print(
        f"{ev.spp} spp per scene texel ({how}continuous result), {ev.seconds:.0f} s; wrote "
        f"{args.out or f'{args.dir}/evaluation.json'}" + "".join(f", {Path(args.dir) / p}" for p in ev.pictures or [])
    )
    return 0


def _evaluate_lights(args, d: RunDir, options: EvaluateOptions, log) -> int:
    """A spectral run: its results under each light (``evaluation.spectral``)."""
    if args.out is not None:
        raise UsageError("--out: a spectral run's evaluation is DIR/evaluation_lights.json")
    with d.lock(stderr_log):
        out = evaluate_lights(args.dir, options, args.illuminants, log)
    if args.json:
        print(json.dumps(out))
        return 0
    headline = out["viewing"]["headline"]
    results = [r for r in ("continuous", "quantized", "surface", "extrusion") if r in out]
    for r in results:
        print(f"{r}: {under_lights({**out[r], 'headline': headline})}")
    for light, beats in out["print_beats_baselines"].items():
        q = out["quantized"]["by_light"][light]["delta_e2000_mean"]
        vs = ", ".join(f"{'beats' if won else 'does not beat'} {_versus(out, light, b)}" for b, won in beats.items())
        print(f"under {light}: the print (mean ΔE2000 {q:.2f}) {vs}")
    if "gamut_floor" in out:
        floors = ", ".join(f"{light} {f['delta_e76_mean']:.2f}" for light, f in out["gamut_floor"].items())
        table = out["colour_table"]
        how = f"spectral, looked up under {','.join(table['lights'])}" if table["spectral"] else "RGB"
        print(
            f"gamut floor: mean dE76 from the target to the nearest colour the inks reach in a {table['patch_mm']:g} "
            f"mm patch, under each light: {floors} (colour table: {how})"
        )
    if "translucency" in out:  # its lines carry the first light's figures; the JSON has every light's
        print(f"translucency under {out['translucency']['lights'][0]} (luminance Y under the light):")
        print("\n".join(translucency_lines(out["translucency"])))
    spp, secs = out["continuous"]["spp"], out["seconds"]
    more = f", {d.sample_predictions_path}" if "texel_sample" in out else ""
    print(f"{spp} spp per scene texel (continuous result), {secs:.0f} s; wrote {d.evaluation_lights_path}{more}")
    return 0


def _versus(out: dict, light: str, baseline: str) -> str:
    """A baseline's mean ΔE2000 under ``light`` and, with a texel sample, the print's paired difference to it."""
    text = f"{baseline} ({out[baseline]['by_light'][light]['delta_e2000_mean']:.2f}"
    diff = (out.get("differences") or {}).get(light, {}).get(f"quantized - {baseline}", {}).get("delta_e2000_mean")
    if diff and diff.get("value") is not None and diff.get("stderr") is not None:
        text += f"; paired difference {diff['value']:+.2f} ± {diff['stderr']:.2f}"
    return text + ")"


def register_cli(sub) -> None:
    p = sub.add_parser(
        "evaluate",
        help="colour error and SSIM of a run, its printed version and the baselines",
        description="Render a run's continuous and quantized results and two naive baselines "
        "(surface colouring, extrusion) and compare them with the target.",
    )
    p.add_argument("dir", help="run directory holding volume.npz and scene.npz")
    for flag, kw in OPTIONS:
        p.add_argument(flag, **kw)
    add_seed_arg(p, "render seed")
    add_threads_arg(p, "render threads")
    add_lighting_args(p, "evaluate")
    p.add_argument(
        "--illuminants",
        metavar="D65,A",
        help="a spectral run: its figures under these lights (default: the run's), the worst light and the colour "
        "inconstancy between the first and each other (evaluation_lights.json; docs/spectral.md)",
    )
    p.set_defaults(func=_evaluate_cmd)
