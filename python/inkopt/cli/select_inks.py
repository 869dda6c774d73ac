"""``inkopt select-inks TARGET``: which candidate inks to load into the printer (``inkopt.inksets``)."""

from __future__ import annotations

from dataclasses import replace

from .common import UsageError, add_inks_arg, add_mesh_args, add_ray_arg, add_translucency_args, stderr_log
from .runargs import add_optimizer_args, config_from_args, mesh_spec_from_args, slab_spec_from_args


def _target(args):
    """The target's spec: a slab (``--size-mm``) or a mesh (``--height-mm`` or ``--scale``)."""
    mesh = args.height_mm is not None or args.scale is not None
    if (args.size_mm is None) == (not mesh):
        raise UsageError(
            "give exactly one of --size-mm WxHxD (TARGET is a picture: a slab) and --height-mm H "
            "(TARGET is a textured mesh; or --scale S)"
        )
    if mesh:
        return mesh_spec_from_args(args, args.target)
    if args.shell_mm is not None:
        raise UsageError("--shell-mm is for a mesh target; a slab is optimised through its whole depth")
    return slab_spec_from_args(args, args.target)


def _select(args) -> int:
    from ..inksets import Selection, make_backend, run_selection

    if args.inks is not None:
        raise UsageError("select-inks takes the inks from --candidates and --always, not --inks")
    if str(args.lighting).lower() != "uniform" or args.lighting_rotate:
        raise UsageError("select-inks ranks ink sets under uniform light only; --lighting is not supported here")
    sel = Selection(
        _target(args),
        args.candidates,
        args.choose,
        args.always,
        # every candidate starts white unless --init says otherwise: a baseline start would build a colour table per
        # candidate set (minutes each)
        replace(config_from_args(args), init=args.init or "white"),
        args.strategy,
        args.eval_spp or 256,
        args.rung_eval_spp,
        None if args.printer == "none" else args.printer,
    )
    sel.validate()  # every input error before any work (or a Ray start)
    backend = make_backend(args.workers, args.ray, args.threads)
    try:
        res = run_selection(sel, args.out, backend, resume=args.resume, log=stderr_log)
    finally:
        backend.close()
    for what, key, sign in (("ΔE76", "delta_e76_mean", 1), ("ΔE2000", "delta_e2000_mean", 1), ("SSIM", "ssim", -1)):
        final = [c for c in res["candidates"] if c["iterations"] == res["candidates"][0]["iterations"]]
        best = min(final, key=lambda c: sign * c[key])
        print(f"best by {what}: {','.join(best['inks'])} ({best[key]:.3f})")
    print(
        f"winner (lowest loss): {','.join(res['winner']['inks'])} (loss {res['winner']['loss']:.5g}); "
        f"{res['texel_samples']:.3g} texel-samples"
    )
    print(f"selection: {args.out}/selection.json, {args.out}/selection.png; winner's run: {args.out}/winner")
    return 0


def register_cli(sub) -> None:
    p = sub.add_parser(
        "select-inks",
        help="choose the inks to load: try subsets of candidate inks",
        description="Optimise TARGET with every subset of --choose of the --candidates inks (plus "
        "the --always inks) and keep the best, by successive halving (default) or "
        "brute force.",
    )
    p.add_argument(
        "target", metavar="TARGET", help="a picture (with --size-mm) or a textured mesh (--height-mm or --scale)"
    )
    p.add_argument("--size-mm", help="slab WxHxD in mm (TARGET is its top picture)")
    p.add_argument("--bottom", metavar="IMAGE", help="picture of the slab's bottom face")
    add_mesh_args(p, "mesh target: ")
    add_translucency_args(p, both=True)
    p.add_argument(
        "--candidates",
        required=True,
        help="comma list of candidate inks, e.g. cyan,cyan2,magenta,magenta2,yellow,yellow2",
    )
    p.add_argument("--choose", type=int, required=True, help="how many candidates each set takes")
    p.add_argument("--always", default="black,white", help="inks in every set (default %(default)s)")
    p.add_argument(
        "--printer",
        default="j750",
        help="printer whose material slots bound the set size (default j750: 6; 'none': no limit)",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="selection directory")
    p.add_argument("--strategy", choices=("halving", "brute"), default="halving")
    p.add_argument(
        "--rung-eval-spp",
        type=int,
        default=16,
        help="halving: spp of the intermediate rungs' evaluation renders (figures and pictures only; default 16)",
    )
    ex = p.add_mutually_exclusive_group()
    ex.add_argument("--workers", type=int, help="runs at once in a local process pool")
    add_ray_arg(ex, "run on Ray")
    add_inks_arg(p, hidden=True)
    add_optimizer_args(p)
    p.set_defaults(func=_select)
