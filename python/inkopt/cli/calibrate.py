"""``inkopt calibrate MEASURED.txt --out INKS.json``: fit the ink table to a measured calibration chart and write
an ink file that ``--inks`` takes, with INKS.report.json (every patch's residual, the held-out patches' ΔE2000)
and INKS.swatches.png (``inkopt.calibration``, docs/calibration.md)."""

from __future__ import annotations

from ..calibration import calibrate
from ..calibration.calibrate import CalibrateOptions, output_paths
from .common import add_seed_arg


def _calibrate_cmd(args) -> int:
    options = CalibrateOptions(
        args.start,
        args.illuminant,
        float(args.holdout),
        int(args.seed),
        not args.fixed_g,
        spectral=not args.rgb,
        band_nm=float(args.band_nm),
    )
    options.validate()
    paths = output_paths(args.out)
    rep = calibrate(args.measured, args.out, options, chart_file=args.chart)
    print(f"fit: mean ΔE2000 {rep.fit_mean_delta_e2000:.2f}, p95 {rep.fit_p95_delta_e2000:.2f} over {len(rep.patches)}")
    if rep.holdout_count:
        print(
            f"held out ({rep.holdout_count} patches, fitted without them): mean ΔE2000 "
            f"{rep.holdout_mean_delta_e2000:.2f}, p95 {rep.holdout_p95_delta_e2000:.2f}"
        )
    kind = f"a spectral ink table, {len(rep.wavelengths_nm)} bands" if rep.model == "spectral" else "an RGB ink table"
    print(f"wrote {paths['inks']} ({kind}), {paths['report']}, {paths['picture']}")
    return 0


def register_cli(sub) -> None:
    p = sub.add_parser(
        "calibrate",
        help="fit the ink table to a measured calibration chart (docs/calibration.md)",
        description="Read a chart file with measurements (CIELAB, XYZ or spectral) and fit every ink's scattering "
        "and absorption and the shared g: per wavelength band to spectral measurements (a spectral ink table), per "
        "R, G, B channel to CIELAB ones (an RGB ink table); write the ink file with a report and a picture.",
    )
    p.add_argument("measured", metavar="MEASURED.txt", help="the chart file (CGATS.17) with measurements filled in")
    p.add_argument("--out", required=True, metavar="INKS.json", help="the ink file to write")
    p.add_argument(
        "--chart",
        metavar="CHART.txt",
        help="the chart file, when MEASURED.txt is an instrument's file with only SAMPLE_ID and measurements",
    )
    p.add_argument(
        "--start", default="vero-cmykw", help="starting ink table (preset, list or file; default vero-cmykw)"
    )
    p.add_argument(
        "--illuminant",
        default="D50",
        metavar="D50|D65|A|F11|LED-B3|FILE.csv",
        help="the light the figures (and an RGB fit) are under: D50 (default, as instruments report) or D65; with "
        "spectral measurements also A, F11, LED-B3 or a light file of nm, relative power rows (docs/spectral.md)",
    )
    p.add_argument("--holdout", type=float, default=0.2, help="share of patches held out to test the fit (default 0.2)")
    add_seed_arg(p, "draw of the held-out patches")
    p.add_argument("--fixed-g", action="store_true", help="keep g at the starting table's value")
    p.add_argument(
        "--rgb",
        action="store_true",
        help="fit an RGB ink table to the measurements' CIELAB under --illuminant even when they are spectral",
    )
    p.add_argument(
        "--band-nm",
        type=float,
        default=20.0,
        choices=(20.0, 10.0),
        help="band width of a spectral fit over 400-700 nm: 20 (16 bands, default) or 10 (31 bands)",
    )
    p.set_defaults(func=_calibrate_cmd)
