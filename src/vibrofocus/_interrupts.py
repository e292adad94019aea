"""Interrupts around a commit: SIGINT/SIGTERM deferred while a file is renamed into place.

:func:`critical_section` defers the signals for its body (an interrupt then leaves either
the old file or the complete new one); :func:`interrupt_pending` tells whether one was
noted while a library swallowed it, so a save stops before its commit. Part of the
atomic-output family (:mod:`vibrofocus._atomic`).
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator
from typing import Any

__all__ = ["critical_section", "interrupt_pending", "clear_interrupt", "install_signal_handlers"]

_lock = threading.Lock()
_critical_depth = 0
_pending_signal: int | None = None
_HANDLED = (signal.SIGINT, signal.SIGTERM)


def _handler(signum: int, frame: Any) -> None:
    """SIGINT/SIGTERM: note it; raise KeyboardInterrupt unless inside a critical section."""
    global _pending_signal
    _pending_signal = signum
    if _critical_depth == 0:
        raise KeyboardInterrupt(signal.Signals(signum).name)


def interrupt_pending() -> int | None:
    """The signal number of an interrupt noted since :func:`clear_interrupt`, else None.

    Set by the handlers of :func:`install_signal_handlers` (and inside
    :func:`critical_section`), even where a library caught the KeyboardInterrupt.
    """
    return _pending_signal


def clear_interrupt() -> None:
    """Forget a noted interrupt (a command starting)."""
    global _pending_signal
    _pending_signal = None


def install_signal_handlers() -> Callable[[], None]:
    """Route SIGINT and SIGTERM to a handler that notes them and raises KeyboardInterrupt.

    Only in the main thread (elsewhere nothing is changed).

    Returns
    -------
    callable
        Restores the previous handlers.
    """
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = {}
    for sig in _HANDLED:
        try:
            previous[sig] = signal.signal(sig, _handler)
        except (ValueError, OSError):  # pragma: no cover - not settable here
            pass

    def restore() -> None:
        for sig, old in previous.items():
            with contextlib.suppress(ValueError, OSError, TypeError):
                signal.signal(sig, old if old is not None else signal.SIG_DFL)

    return restore


@contextlib.contextmanager
def critical_section() -> Iterator[None]:
    """Defer SIGINT/SIGTERM for the body; a deferred one takes effect right after it.

    Under the handlers of :func:`install_signal_handlers` (the CLI) a deferred signal
    is raised as KeyboardInterrupt when the outermost section ends. Elsewhere (the
    Python API) the handlers are ours only for the body, and a signal that arrived is
    raised again once the caller's handlers are back (so SIGTERM still terminates,
    after the commit). In a thread other than the main thread the body simply runs
    (signals are handled in the main thread).
    """
    global _critical_depth
    if threading.current_thread() is not threading.main_thread():
        # The KeyboardInterrupt is raised in the main thread, never in this one, so there
        # is nothing to defer; counting this section would hold back (and lose) a Ctrl-C
        # meant for the main thread's work.
        yield
        return
    restore = None
    with contextlib.suppress(ValueError, OSError):
        if signal.getsignal(signal.SIGINT) is not _handler or signal.getsignal(signal.SIGTERM) is not _handler:
            restore = install_signal_handlers()
    with _lock:
        _critical_depth += 1
    try:
        yield
    finally:
        with _lock:
            _critical_depth -= 1
        depth = _critical_depth
        if restore is not None:
            restore()
            if depth == 0 and _pending_signal is not None:
                sig = _pending_signal
                clear_interrupt()
                signal.raise_signal(sig)
        elif depth == 0 and _pending_signal is not None:
            raise KeyboardInterrupt(signal.Signals(_pending_signal).name)
