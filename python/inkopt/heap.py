"""The process heap: freed memory given back to the operating system where the C library can.

glibc keeps freed blocks below its mmap threshold (up to 32 MB) in the heap of the thread that freed them, so a
stage's many working arrays can stay in the process under the next stage's peak, or be placed beside the next
call's instead of reused. ``trim`` asks glibc to return them (``malloc_trim``); elsewhere (macOS, Windows, musl
builds without it) it does nothing. Where it pays is measured at its callers (``run.release_freed_memory``,
``optim.smooth``).
"""

from __future__ import annotations

import ctypes


def trim() -> None:
    """Return the heap's free memory to the operating system (glibc's ``malloc_trim(0)``); a no-op elsewhere."""
    try:
        malloc_trim = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError, TypeError):  # not glibc
        return
    malloc_trim(0)
