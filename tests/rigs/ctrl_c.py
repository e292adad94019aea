"""Press Ctrl-C from a test: a real SIGINT to the main thread after a delay."""

from __future__ import annotations

import signal
import threading


def ctrl_c_after(seconds: float) -> threading.Timer:
    """Start a timer that sends SIGINT to the main thread after ``seconds``; returns it.

    A real signal, as a terminal's Ctrl-C is, and delivered to the main thread so that
    its C handler runs there and the interpreter checks for it at once. (``_thread.
    interrupt_main`` called from another thread sets the flag without waking the main
    thread's check; under a loaded parallel test run it was seen to arrive only after a
    5 s play had ended.)
    """
    main = threading.main_thread().ident
    timer = threading.Timer(seconds, signal.pthread_kill, args=(main, signal.SIGINT))
    timer.daemon = True
    timer.start()
    return timer
