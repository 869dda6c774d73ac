"""Ink-set search (``inkopt select-inks``): which candidate inks to load into a printer's few material slots,
by brute force or successive halving over independent optimisation runs, executed serially, in a local process
pool or on Ray (``backends``). A layer above ``run`` and below ``cli``."""

from .backends import RAY_INSTALL_HINT, Pool, Ray, Serial, make_backend, run_candidate
from .search import STRATEGIES, Selection, load_selection, run_selection, set_name

__all__ = [
    "RAY_INSTALL_HINT",
    "Pool",
    "Ray",
    "Serial",
    "make_backend",
    "run_candidate",
    "STRATEGIES",
    "Selection",
    "load_selection",
    "run_selection",
    "set_name",
]
