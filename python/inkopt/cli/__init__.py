"""The ``inkopt`` command line: one thin module per subcommand (``inkopt.cli.<name>.register_cli``), each parsing
its arguments and calling the library. No library module imports from here.

Errors in the input (bad files, shapes, values) end with one line ``inkopt: error: ...`` on stderr and exit
status 2; nothing half-written is left behind (outputs are written atomically).
"""

from __future__ import annotations

import argparse
import importlib
import sys

from .. import __version__
from ..errors import ParameterError
from .common import UsageError, flag_of

SUBCOMMANDS = (
    "render",
    "slab",
    "optimize",
    "quantize",
    "export",
    "inspect",
    "evaluate",
    "report",
    "demo",
    "select_inks",
    "calibration_chart",
    "calibrate",
)

__all__ = ["UsageError", "build_parser", "main"]


class _Parser(argparse.ArgumentParser):
    """argparse whose usage errors (a missing argument, a value its type refuses) are one line too, like every other
    error: ``inkopt CMD: error: ... (see inkopt CMD --help)``, exit status 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="inkopt", description="Gradient-based appearance optimization for full-colour inkjet 3D prints.")
    p.add_argument("--version", action="version", version=f"inkopt {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    for name in SUBCOMMANDS:
        importlib.import_module(f"{__name__}.{name}").register_cli(sub)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("inkopt: interrupted", file=sys.stderr)
        return 130
    except (ValueError, OSError, KeyError) as exc:
        text = exc.render(flag_of) if isinstance(exc, ParameterError) else str(exc)
        msg = " ".join(text.split()) or type(exc).__name__
        print(f"inkopt: error: {msg}", file=sys.stderr)
        return 2
    except MemoryError:
        print("inkopt: error: out of memory (the volume is too large for this machine)", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
