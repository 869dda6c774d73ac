"""Thread counts: the one check of a thread count wherever one enters the library (the renderer, the optimiser's
kernels, Ray workers, select-inks' backends) and the command line's ``--threads``.

Results never depend on the thread count (renders are bit-identical for any), so a count only has to be one the
machine can run: at least 1 and at most ``THREADS_PER_CORE`` per core. Above that threads only add switching, and
a count of thousands starts as many operating-system threads, which exhausts the machine.
"""

from __future__ import annotations

import os
from numbers import Integral

from .errors import ParameterError

#: the most threads per core a thread count may ask for
THREADS_PER_CORE = 4


def max_threads() -> int:
    """The largest thread count accepted on this machine: ``THREADS_PER_CORE`` per core (``os.cpu_count``)."""
    return THREADS_PER_CORE * (os.cpu_count() or 1)


def check_threads(threads, name: str = "threads") -> int | None:
    """``threads`` as an int (None stays None: all cores); a ``ParameterError`` naming ``name`` unless it is a whole
    number from 1 to ``max_threads()``."""
    if threads is None:
        return None
    if isinstance(threads, bool) or not isinstance(threads, Integral):
        raise ParameterError(f"`{name}` must be a whole number of threads, got {threads!r}")
    top = max_threads()
    if not 1 <= int(threads) <= top:
        raise ParameterError(
            f"`{name}` must be between 1 and {top} ({THREADS_PER_CORE} per core of this machine), got {int(threads)}"
        )
    return int(threads)
