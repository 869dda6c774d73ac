"""``inkopt render FILE``: render a volume file in texel space (and, with --adjoint, its gradient)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..io import load_array
from ..rundir import RunDir
from .common import UsageError, add_lighting_args, add_seed_arg, add_threads_arg, lighting_from_args, stderr_log


def _render(args) -> int:
    from ..io import save_npz
    from ..model import Texels, Volume
    from ..render import Renderer

    vol = Volume.load(args.file)
    if (Path(args.file).parent / RunDir.SPECTRAL_INKS).is_file():  # a spectral run's volume keeps an RGB table
        stderr_log(
            f"note: {args.file} is a spectral run's volume; render uses the RGB ink table stored in it "
            "(inkopt evaluate RUN --illuminants renders it spectrally under lights)"
        )
    texels = Texels.for_volume(vol, [args.face] if args.face else None)
    if len(texels) == 0:
        raise UsageError("the volume has no texels on the chosen face(s)")
    adjoint = None
    if args.adjoint:
        adjoint = load_array(args.adjoint, "adjoint")
        if adjoint.shape != (len(texels), 3):
            raise UsageError(f"adjoint has shape {adjoint.shape}, expected ({len(texels)}, 3) (texels x RGB)")
        if not np.all(np.isfinite(adjoint)):
            raise UsageError("adjoint contains NaN or infinite values")
        if not args.out:
            raise UsageError("--adjoint needs --out G.npz to write the gradient to")
    rnd = Renderer(vol, threads=args.threads, lighting=lighting_from_args(args))
    progress = not args.json
    if adjoint is None:
        res = rnd.render(texels, spp=args.spp, seed=args.seed, include_specular=not args.no_specular, progress=progress)
        grads = None
    else:
        gs, ga, res = rnd.gradient(
            texels,
            adjoint,
            spp=args.spp,
            seed=args.seed,
            method=args.method,
            include_specular=not args.no_specular,
            progress=progress,
        )
        grads = {"grad_sigma_s": gs, "grad_sigma_a": ga}
    if args.out:
        out = {
            "rgb": res.rgb,
            "rgb_var_mean": res.var_mean,
            "position_mm": texels.position_mm(vol.voxel_mm),
            "normal": texels.normal,
            **texels.to_arrays(),
        }
        if grads:
            out.update(grads)
        save_npz(args.out, out)
    summary = {
        "mean_rgb": [float(x) for x in res.mean_rgb],
        "mean_rgb_stderr": [float(x) for x in res.mean_rgb_stderr],
        **res.stats(),
        "seed": args.seed,
        "threads": rnd.threads,
        **rnd.lighting.describe(),
        "events_per_second": res.events / max(res.seconds, 1e-9),
    }
    if grads:
        summary["gradient_method"] = args.method
    if args.json:
        print(json.dumps(summary))
    else:
        m, e = summary["mean_rgb"], summary["mean_rgb_stderr"]
        print(
            f"{summary['texels']} texels x {args.spp} spp in {res.seconds:.2f} s "
            f"({summary['events_per_second'] / 1e6:.1f} M events/s, {rnd.threads} threads)"
        )
        print("mean linear RGB: " + "  ".join(f"{a:.4f} ± {b:.4f}" for a, b in zip(m, e)))
        if args.out:
            print(f"wrote {args.out}")
    return 0


def register_cli(sub) -> None:
    r = sub.add_parser(
        "render",
        help="render a volume file (.npz) in texel space",
        description="Render a volume file: mean radiance of every surface texel under uniform "
        "white light or an environment map (--lighting). With --adjoint, also the "
        "gradient of sum(adjoint * rgb).",
    )
    r.add_argument("file", help="volume .npz (see inkopt.model.volume for the format)")
    r.add_argument("--spp", type=int, default=16, help="samples per texel and channel (default 16)")
    add_seed_arg(r, "render seed")
    r.add_argument("--face", help="only texels of this face: top, bottom, left, right, front, back (or +z, -x, ...)")
    r.add_argument("--json", action="store_true", help="print one JSON object on stdout, no progress bar")
    r.add_argument("--out", help="write per-texel positions, normals, linear RGB (and gradients) to this .npz")
    r.add_argument("--adjoint", help="(I, 3) .npy of de/dc in the texel order of --out: compute the gradient")
    r.add_argument(
        "--method",
        choices=("replay", "li1"),
        default="replay",
        help="gradient estimator: unbiased path replay (default) or the biased one-pass L_i = 1",
    )
    r.add_argument("--no-specular", action="store_true", help="exclude the specular reflection of the environment")
    add_threads_arg(r)
    add_lighting_args(r)
    r.set_defaults(func=_render)
