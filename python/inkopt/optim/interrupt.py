"""Ctrl-C held back while a step changes the run's state in place, so that an interrupted run stops either before
a step's update or after it, never half-way (``Optimization.step``)."""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager


@contextmanager
def interrupt_deferred():
    """Run the block with SIGINT recorded instead of acted on, then, if one came, send it again under the handler
    that was set before (the default one raises KeyboardInterrupt). Only in the main thread, the one whose Python
    handlers signals run in; elsewhere the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    before = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, before)
        if caught:
            signal.raise_signal(signal.SIGINT)
