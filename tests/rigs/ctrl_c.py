"""Press Ctrl-C from a test: a real SIGINT to the main thread after a delay."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator


@contextlib.contextmanager
def ctrl_c_after(seconds: float) -> Iterator[None]:
    """SIGINT to the main thread ``seconds`` into the block, as a terminal's Ctrl-C.

    Python's own SIGINT handler is in place for the block: a test run started in the
    background by a non-interactive shell inherits SIGINT ignored, and Python then keeps
    it ignored, so no Ctrl-C could reach the code under test.
    """
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(seconds, signal.pthread_kill, args=(threading.main_thread().ident, signal.SIGINT))
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
