"""The lights a print is seen under on the command line (``--illuminant``, ``--illuminants``, ``--combine``) for
``slab`` and ``optimize``, the run's ``spectral.viewing.Viewing`` built from them, and the line of a spectral run's
figures under each light (``slab``, ``optimize``, ``evaluate``)."""

from __future__ import annotations

#: how the loss under several lights combines unless ``--combine`` says: the worst light's, which lowers the worst
#: light's mean ΔE2000 more than the mean of the lights' losses does (docs/spectral.md, "Two lights")
DEFAULT_COMBINE = "worst"


def add_light_args(p, combine: bool = True, what: str | None = None) -> None:
    """``--illuminant NAME|FILE.csv`` or ``--illuminants A,B``: the lights the print is seen under
    (``spectral.lights``, ``spectral.viewing``), and ``--combine`` unless ``combine`` is False (a command that
    takes no loss); ``what``: the two flags' help in place of an optimisation's."""
    from ..spectral.lights import NAMED

    g = p.add_mutually_exclusive_group()
    names = "|".join(NAMED)
    g.add_argument(
        "--illuminant",
        metavar=f"{names}|FILE.csv",
        help=what
        or "the light the print is seen under (CIE 1931 2° observer; a file: rows of nm, relative power). "
        "Default D65, the white of linear sRGB: with an RGB ink table the run is the RGB one; another light needs "
        "a spectral ink table (docs/spectral.md)",
    )
    g.add_argument(
        "--illuminants",
        metavar="D65,A",
        help="several lights: the loss is the worst (or --combine mean: the mean) of the loss under each (a spectral "
        "ink table; docs/spectral.md)"
        if what is None
        else "several lights, as --illuminant",
    )
    if not combine:
        return
    p.add_argument(
        "--combine",
        choices=("mean", "worst"),
        default=DEFAULT_COMBINE,
        help="how the loss under several lights (--illuminants) combines: the worst light's (default: each iteration "
        "steps on the light whose loss is largest, which lowers the worst light's error most) or their mean",
    )


def viewing_from_args(args, table=None):
    """The run's ``spectral.viewing.Viewing`` from ``--illuminant`` / ``--illuminants`` and the spectral ink table
    ``table`` of ``--inks`` (None: an RGB table; the RGB path when no light or D65 is asked)."""
    from ..spectral.lights import load_light, parse_lights
    from ..spectral.viewing import Viewing

    if getattr(args, "illuminants", None):
        return Viewing(table, lights=parse_lights(args.illuminants), combine=getattr(args, "combine", DEFAULT_COMBINE))
    if getattr(args, "illuminant", None):
        return Viewing(table, lights=(load_light(args.illuminant),))
    return Viewing(table)


def under_lights(v: dict) -> str:
    """The line of a spectral run's figures under each light (``evaluation.lights.light_figures``'s dict)."""
    each = ", ".join(f"{n} {m['delta_e2000_mean']:.2f}" for n, m in v["by_light"].items())
    moves = "".join(f"; colour inconstancy {k} {d:.2f} ΔE2000" for k, d in v["inconstancy_delta_e2000_mean"].items())
    return f"figures under {v['headline']}; mean ΔE2000 under each light: {each} (worst {v['worst_light']}){moves}"
