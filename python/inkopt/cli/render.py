"""``inkopt render FILE``: render a volume file in texel space (and, with --adjoint, its gradient).

With a spectral ink table (``--inks X@spectral`` or a spectral ink file, or a spectral run's own table when a light
is asked) the volume's bands are rendered (``spectral.render.SpectralRenderer``, ``--spp`` samples per texel and
band, the band groups sharing one geometry) and shown under each light asked
(``--illuminant`` / ``--illuminants``, default D65) as linear sRGB adapted to D65 (``spectral.viewing``); without
one, the RGB render of the ink table stored in the volume, as it always was.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..io import load_array
from ..rundir import RunDir
from .common import UsageError, add_lighting_args, add_seed_arg, add_threads_arg, lighting_from_args, stderr_log
from .lights import add_light_args


def _viewing(args):
    """The render's ``spectral.viewing.Viewing``: the spectral table of ``--inks``, else a spectral run's own table
    (spectral_inks.json beside FILE) when a light is asked, else none (the RGB path; any light but D65 is then
    refused in one line naming the flag)."""
    from ..model import InkTable
    from ..model.inks import read_ink_file
    from ..model.spectral import load_ink_table, spectral_from_data
    from .lights import viewing_from_args

    table, asked = None, bool(args.illuminant or args.illuminants)
    run_inks = Path(args.file).parent / RunDir.SPECTRAL_INKS
    if args.inks is not None:
        table = load_ink_table(args.inks)
        if isinstance(table, InkTable):
            raise UsageError(
                f"--inks {args.inks} is an RGB ink table: render reads the volume with the RGB table stored in it; "
                "--inks takes a spectral table (vero-cmykw@spectral or a spectral ink file)"
            )
    elif asked and run_inks.is_file():
        table = spectral_from_data(read_ink_file(run_inks), run_inks)
    elif run_inks.is_file():  # a spectral run's volume keeps an RGB table
        stderr_log(
            f"note: {args.file} is a spectral run's volume; render uses the RGB ink table stored in it "
            "(--illuminant LIGHT renders its spectral ink table under that light)"
        )
    return replace(viewing_from_args(args, table), weighted=False)  # --spp samples of every band


def _adjoint(args, texels, channels: int) -> np.ndarray | None:
    """``--adjoint``'s (I, C) array (C: 3 on the RGB path, the bands of a spectral table), checked."""
    if not args.adjoint:
        return None
    adjoint = load_array(args.adjoint, "adjoint")
    what = "texels x RGB" if channels == 3 else "texels x bands"
    if adjoint.shape != (len(texels), channels):
        raise UsageError(f"adjoint has shape {adjoint.shape}, expected ({len(texels)}, {channels}) ({what})")
    if not np.all(np.isfinite(adjoint)):
        raise UsageError("adjoint contains NaN or infinite values")
    if not args.out:
        raise UsageError("--adjoint needs --out G.npz to write the gradient to")
    return adjoint


def _render(args) -> int:
    from ..io import save_npz
    from ..model import Texels, Volume
    from ..render import Renderer

    vol = Volume.load(args.file)
    viewing = _viewing(args)
    texels = Texels.for_volume(vol, [args.face] if args.face else None)
    if len(texels) == 0:
        raise UsageError("the volume has no texels on the chosen face(s)")
    adjoint = _adjoint(args, texels, viewing.table.bands if viewing.spectral else 3)
    rnd = viewing.renderer_factory(Renderer, shared=True)(vol, args.threads, lighting_from_args(args))
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
    cmaps = viewing.colours() if viewing.spectral else ()
    shown = _under_lights(cmaps, res)
    first = next(iter(shown.values())) if shown else res
    if args.out:
        out = {
            "rgb": first.rgb,
            "rgb_var_mean": first.var_mean,
            "position_mm": texels.position_mm(vol.voxel_mm),
            "normal": texels.normal,
            **texels.to_arrays(),
        }
        if shown:
            out.update(_band_arrays(viewing.table, res, shown, cmaps))
        if grads:
            out.update(grads)
        save_npz(args.out, out)
    summary = {
        "mean_rgb": [float(x) for x in first.mean_rgb],
        "mean_rgb_stderr": [float(x) for x in first.mean_rgb_stderr],
        **res.stats(),
        "seed": args.seed,
        "threads": rnd.threads,
        **rnd.lighting.describe(),
        "events_per_second": res.events / max(res.seconds, 1e-9),
    }
    if shown:
        summary.update(_band_summary(viewing.table, res, shown, cmaps))
    if grads:
        summary["gradient_method"] = args.method
    if args.json:
        print(json.dumps(summary))
    else:
        _print_summary(args, summary, rnd.threads, res.seconds)
    return 0


def _under_lights(cmaps, res) -> dict:
    """{light name: band render ``res`` shown under it as linear sRGB (``spectral.viewing.display_result``)} for
    each of the lights' colour maps ``cmaps`` ({} on the RGB path: no maps)."""
    from ..spectral.viewing import display_result

    return {c.name: display_result(c, res) for c in cmaps}


def _band_arrays(table, res, shown: dict, cmaps) -> dict:
    """--out's arrays of a spectral render: the band values (I, B) and their variances, the band centres (nm), the
    lights' names (L,) and per light (L, I, 3) the linear sRGB shown, its variance and the CIELAB relative to the
    light's white."""
    return {
        "bands": res.rgb,
        "bands_var_mean": res.var_mean,
        "wavelengths_nm": np.asarray(table.wavelengths_nm, np.float64),
        "illuminants": np.array(list(shown)),
        "rgb_by_light": np.stack([r.rgb for r in shown.values()]),
        "rgb_var_mean_by_light": np.stack([r.var_mean for r in shown.values()]),
        "lab_by_light": np.stack([c.lab(res.rgb).astype(np.float32) for c in cmaps]),
    }


def _band_summary(table, res, shown: dict, cmaps) -> dict:
    """The summary's spectral fields: bands, band centres, the lights, the texels' mean band values with their
    standard errors, and per light the mean linear sRGB shown (± standard error) and the CIELAB of the mean band
    values relative to the light's white (``mean_rgb`` above is the first light's)."""
    mean = res.mean_rgb
    return {
        "colour": "spectral",
        "bands": int(table.bands),
        "wavelengths_nm": [float(w) for w in table.wavelengths_nm],
        "illuminants": list(shown),
        "mean_bands": [float(x) for x in mean],
        "mean_bands_stderr": [float(x) for x in res.mean_rgb_stderr],
        "by_light": {
            name: {
                "mean_rgb": [float(x) for x in r.mean_rgb],
                "mean_rgb_stderr": [float(x) for x in r.mean_rgb_stderr],
                "mean_lab": [float(x) for x in c.lab(mean)],
            }
            for (name, r), c in zip(shown.items(), cmaps)
        },
    }


def _print_summary(args, summary: dict, threads: int, seconds: float) -> None:
    """The human-readable summary: counts and speed, then the mean colour (per light for a spectral render)."""
    bands = f", {summary['bands']} bands" if "bands" in summary else ""
    print(
        f"{summary['texels']} texels x {args.spp} spp in {seconds:.2f} s "
        f"({summary['events_per_second'] / 1e6:.1f} M events/s, {threads} threads{bands})"
    )
    for name, v in summary.get("by_light", {"": summary}).items():
        m, e = v["mean_rgb"], v["mean_rgb_stderr"]
        rgb = "  ".join(f"{a:.4f} ± {b:.4f}" for a, b in zip(m, e))
        if not name:
            print("mean linear RGB: " + rgb)
            continue
        lab = ", ".join(f"{x:.2f}" for x in v["mean_lab"])
        print(f"under {name}: mean linear sRGB (adapted to D65) {rgb}; CIELAB of the mean {lab}")
    if args.out:
        print(f"wrote {args.out}")


def register_cli(sub) -> None:
    r = sub.add_parser(
        "render",
        help="render a volume file (.npz) in texel space",
        description="Render a volume file: mean radiance of every surface texel under uniform "
        "white light or an environment map (--lighting). With --adjoint, also the "
        "gradient of sum(adjoint * rgb). With a spectral ink table (--inks, or a spectral run's own when "
        "--illuminant is given), its bands and their colour under each light.",
    )
    r.add_argument("file", help="volume .npz (see inkopt.model.volume for the format)")
    r.add_argument(
        "--spp",
        type=int,
        default=16,
        help="samples per texel and channel (default 16; a spectral table: per texel and band)",
    )
    add_seed_arg(r, "render seed")
    r.add_argument("--face", help="only texels of this face: top, bottom, left, right, front, back (or +z, -x, ...)")
    r.add_argument("--json", action="store_true", help="print one JSON object on stdout, no progress bar")
    r.add_argument("--out", help="write per-texel positions, normals, linear RGB (and gradients) to this .npz")
    r.add_argument(
        "--adjoint",
        help="(I, 3) .npy of de/dc in the texel order of --out (a spectral table: (I, B) of de/d band value): "
        "compute the gradient",
    )
    r.add_argument(
        "--method",
        choices=("replay", "li1"),
        default="replay",
        help="gradient estimator: unbiased path replay (default) or the biased one-pass L_i = 1",
    )
    r.add_argument("--no-specular", action="store_true", help="exclude the specular reflection of the environment")
    r.add_argument(
        "--inks",
        metavar="X@spectral|FILE",
        help="a spectral ink table of the volume's inks (vero-cmykw@spectral, a spectral ink file) to render its "
        "bands with (default: a spectral run's own table when --illuminant is given; else the volume's RGB table)",
    )
    add_light_args(
        r,
        combine=False,
        what="the light to show a spectral render under (D65 by default; a file: rows of nm, relative power); with "
        "a spectral run's volume it renders the run's spectral table (docs/spectral.md)",
    )
    add_threads_arg(r)
    add_lighting_args(r)
    r.set_defaults(func=_render)
