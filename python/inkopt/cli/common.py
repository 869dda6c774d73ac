"""What the subcommands share: the usage error, the flags of the library's parameters (``flag_of``), and every
option that more than one subcommand takes, declared once here (``--inks``, ``--threads``, ``--seed``, the display
lighting, a mesh's placement, translucency, ``--ray``). The options of an optimisation run are ``runargs``'."""

from __future__ import annotations

import sys

from ..errors import ParameterError


class UsageError(ValueError):
    """A problem with the user's input; reported as one line, exit status 2."""


#: Library parameters whose flag is not ``--`` + the name with dashes (``inkopt.errors.ParameterError``).
FLAGS = {"grad_method": "--gradient", "out_inks": "--out", "log_every_s": "--log-every", "materials": "--material"}


def flag_of(name: str) -> str:
    """The command line's flag of a library parameter (``eval_spp`` -> ``--eval-spp``)."""
    return FLAGS.get(name) or "--" + name.replace("_", "-")


def stderr_log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def add_lighting_args(p, what: str = "render") -> None:
    """``--lighting uniform|FILE`` and ``--lighting-rotate DEG`` (``inkopt.lighting``)."""
    p.add_argument(
        "--lighting",
        default="uniform",
        metavar="uniform|FILE",
        help=f"display lighting to {what} under: uniform (radiance 1 from every direction, the default) "
        "or an equirectangular environment map of linear radiance (.hdr, .exr, or .npy (H, 2H, 3)); "
        "row 0 looks up (+z), column 0 starts at +x, longitude grows towards +y",
    )
    p.add_argument(
        "--lighting-rotate",
        type=float,
        default=0.0,
        metavar="DEG",
        help="turn the map about z by DEG degrees, from +x towards +y (default 0)",
    )


def add_mesh_args(p, what: str = "") -> None:
    """The inputs of a mesh scene (``scenes.spec.MeshSpec``): ``--height-mm`` or ``--scale``, ``--up``,
    ``--shell-mm`` and ``--dpi``; ``what`` prefixes their help (e.g. "mesh: ")."""
    from ..model.fixed import DEFAULT_CORE
    from ..scenes.mesh import UP_AXES

    p.add_argument("--height-mm", type=float, metavar="H", help=f"{what}scale the object to this height (mm)")
    p.add_argument("--scale", type=float, metavar="S", help=f"{what}or scale it by S mm per model unit")
    p.add_argument("--up", choices=UP_AXES, default="y", help=f"{what}the file's up axis (default y, as OBJ/glTF)")
    p.add_argument(
        "--shell-mm",
        type=float,
        metavar="D",
        help=f"{what}optimise only voxels less than D mm below the surface; deeper ones are printed as --core "
        "(default: every voxel of the object is optimised; optimize takes a 1 mm band over a white core when that "
        "does not fit the memory, --memory-gb; 0: every voxel, always)",
    )
    p.add_argument(
        "--core",
        default=DEFAULT_CORE,
        metavar="white|start|INK=SHARE,...",
        help=f"{what}the fixed mixture of the voxels below --shell-mm: white, start (97 %% white, the rest split "
        f"over the other inks, as the optimiser's start) or ink shares summing to 1, e.g. white=0.9,black=0.1 "
        f"(default {DEFAULT_CORE})",
    )
    add_dpi_arg(p)
    p.add_argument(
        "--texture",
        metavar="FILE",
        help=f"{what}the texture image, looked up through the mesh's uv coordinates (replaces the one its "
        "material names; for an OBJ without or with a broken MTL file)",
    )
    p.add_argument(
        "--constant-color",
        action="store_true",
        help=f"{what}accept a mesh without texture, vertex or face colours: the target is its material's "
        "colour (white without one); without this flag such a mesh is refused",
    )


def add_translucency_args(p, mesh: bool = False, both: bool = False) -> None:
    """``--translucency`` and ``--translucency-depth-mm`` (``inkopt.scenes.translucency``) of a slab, a mesh or
    (``both``) either."""
    if both:
        p.add_argument(
            "--translucency",
            metavar="MASK|alpha",
            help="translucent regions: a grey mask image (slab: of the picture's size; mesh: in texture "
            "space; grey level 0..1 = required share of transparent ink) or, for a mesh, 'alpha' "
            "(share = 1 - the texture's alpha); needs a transparent ink in --always",
        )
    elif mesh:
        p.add_argument(
            "--translucency",
            metavar="alpha|MASK",
            help="translucent regions: 'alpha' (share of transparent ink = 1 - the texture's alpha) or a "
            "grey mask image in texture space (grey level 0..1 = share); needs a transparent ink",
        )
    else:
        p.add_argument(
            "--translucency",
            metavar="MASK",
            help="translucent regions: a grey mask image of the top picture's size (grey level 0..1 = "
            "required share of transparent ink under that pixel); needs a transparent ink "
            "(e.g. --inks vero-cmykwt)",
        )
    p.add_argument(
        "--translucency-depth-mm",
        type=float,
        metavar="D",
        help="how deep below the surface the translucent regions reach (default: through the whole "
        + ("object)" if mesh or both else "slab)"),
    )


def lighting_from_args(args):
    from ..lighting import load_lighting

    return load_lighting(args.lighting, args.lighting_rotate)


def add_ray_arg(
    p, what: str = "render texel shards on Ray workers, one per node, with results identical to a single-machine run"
) -> None:
    """``--ray auto|ADDRESS`` (``inkopt.distributed``); ``p`` may be a group of exclusive options."""
    p.add_argument(
        "--ray",
        metavar="auto|ADDRESS",
        help=f"{what}: 'auto' starts a local instance, ADDRESS joins a cluster (pip install 'inkopt[ray]')",
    )


def ray_from_args(args) -> str | None:
    """``--ray``, checked before any work: a one-line error if Ray is not installed."""
    if args.ray:
        from ..distributed import import_ray

        import_ray()
    return args.ray


def add_dpi_arg(p) -> None:
    """``--dpi``: the optimisation grid's resolution (cubic voxels)."""
    from ..units import OPT_DPI

    p.add_argument("--dpi", type=float, default=OPT_DPI, help=f"optimisation grid resolution (default {OPT_DPI:g})")


def add_inks_arg(p, hidden: bool = False, required: bool = False) -> None:
    """``--inks``: a preset, a comma list of ink names or an ink file (``model.spectral.load_ink_table``: RGB, or
    spectral with ``<preset>@spectral`` or a spectral ink file), vero-cmykw unless
    ``required``; ``hidden``: taken but not shown (a subcommand that refuses it in words of its own)."""
    import argparse

    what = (
        "ink set: a preset (vero-cmykw, vero-cmykw+orange, vero-cmykwt), its spectral form (vero-cmykw@spectral, "
        f"{SPECTRAL_COMMANDS} only), a comma list of ink names, or a JSON/TOML (RGB or spectral) "
    )
    p.add_argument(
        "--inks",
        default=None if hidden or required else "vero-cmykw",
        required=required,
        help=argparse.SUPPRESS
        if hidden
        else what + ("file of inks" if required else "file of inks (default vero-cmykw)"),
    )


#: the commands that take a spectral ink table (``--inks X@spectral`` or a spectral ink file)
SPECTRAL_COMMANDS = "slab and optimize"


def rgb_inks(spec: str, command: str):
    """The RGB ``model.InkTable`` of ``--inks`` ``spec`` for ``command``, which cannot use a spectral table: a
    spectral one is refused in one line naming the commands that can."""
    from ..model import InkTable
    from ..model.spectral import load_ink_table

    table = load_ink_table(spec)
    if not isinstance(table, InkTable):
        raise ParameterError(
            f"`inks` {spec} is a spectral ink table, which {command} does not take; {SPECTRAL_COMMANDS} do"
        )
    return table


def thread_count(text: str) -> int:
    """``--threads``' type: a whole number checked by ``threads.check_threads`` while the arguments are parsed,
    before any work (argparse reports a bad one after the flag's name)."""
    import argparse

    from ..threads import check_threads

    try:
        return check_threads(int(text))
    except ParameterError as exc:  # out of range: the message without its subject, which argparse names
        raise argparse.ArgumentTypeError(exc.render(lambda name: "").strip()) from None
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number of threads, got {text!r}") from None


def add_threads_arg(p, what: str = "worker threads") -> None:
    """``--threads N``: the renderer's threads (results do not depend on them; 1 to 4 per core)."""
    p.add_argument(
        "--threads", type=thread_count, metavar="N", help=f"{what} (default: all cores; results do not depend on it)"
    )


def add_seed_arg(p, what: str) -> None:
    """``--seed N`` (default 0): ``what`` says which random numbers it seeds."""
    p.add_argument("--seed", type=int, default=0, metavar="N", help=f"{what} (default 0)")
