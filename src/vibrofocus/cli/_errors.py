"""One line per user error, exit codes, interrupts: how every command ends.

- A :class:`~vibrofocus.errors.VibrofocusError` prints ``error: ...`` (one line) and
  exits with code 2; an :class:`OSError` such as a full disk or a read-only folder that
  reached a command is reported the same way.
- Ctrl-C (SIGINT) and SIGTERM stop the command at the next safe point (a save in
  progress is either committed whole or discarded, see :mod:`vibrofocus._atomic`),
  print ``interrupted: ...`` and exit with code 130.
- No traceback is printed for these unless ``vibrofocus --debug`` was given.
- Anything else (a bug, or a case no check foresaw) prints one ``error:`` line naming
  a log file that holds the traceback and exits with code 1
  (:func:`report_unexpected`).
- Messages are cut at :data:`MAX_MESSAGE_CHARS` characters: they never echo an
  unbounded input.
"""

from __future__ import annotations

import contextlib
import errno as _errno
import os
import sys
from collections.abc import Iterator
from pathlib import Path

import typer
from rich.console import Console

from ..errors import VibrofocusError

err_console = Console(stderr=True, highlight=False, soft_wrap=True)

#: Set by ``vibrofocus --debug``: print the traceback under a user error.
DEBUG = False

#: Exit code of a user error (bad input, unwritable output, ...).
EXIT_USER_ERROR = 2
#: Exit code of an unexpected error (a bug): the traceback is in a log file.
EXIT_UNEXPECTED = 1
#: Longest error message printed, characters (the rest is cut, and says so).
MAX_MESSAGE_CHARS = 2000
#: Exit code after SIGINT/SIGTERM (128 + SIGINT, as shells report Ctrl-C).
EXIT_INTERRUPTED = 130

#: OSErrors reported as one-line user errors when they reach a command.
_USER_ERRNOS = {
    _errno.ENOSPC, _errno.EDQUOT, _errno.EACCES, _errno.EPERM, _errno.EROFS, _errno.ENOENT, _errno.ENOTDIR,
    _errno.EISDIR, _errno.EFBIG, _errno.ENAMETOOLONG, _errno.EIO,
}


def set_debug(value: bool) -> None:
    """Show tracebacks under user errors (``--debug``)."""
    global DEBUG
    DEBUG = bool(value)


def _traceback() -> None:
    if DEBUG:
        err_console.print_exception(show_locals=False)


def print_error(message: str) -> None:
    """Print ``error: message`` on stderr as one line: no markup, no control characters, cut at
    :data:`MAX_MESSAGE_CHARS`."""
    text = str(message)
    if len(text) > MAX_MESSAGE_CHARS:
        text = f"{text[:MAX_MESSAGE_CHARS]}... (message cut; {len(text):,} characters)"
    # Control characters (newlines, carriage returns, separators) would break the one
    # line or rewrite the terminal: each becomes a space.
    text = "".join(ch if ch.isprintable() else " " for ch in text)
    err_console.print("[bold red]error:[/] ", end="")
    err_console.print(text, markup=False)


def log_folder() -> Path:
    """Where tracebacks of unexpected errors go: ``$VIBROFOCUS_LOG_DIR``, else a folder of the user's
    own in the temporary folder, ``vibrofocus-logs-<uid>`` (mode 0700)."""
    import tempfile

    env = os.environ.get("VIBROFOCUS_LOG_DIR")
    if env:
        return Path(env)
    own = f"vibrofocus-logs-{os.getuid()}" if hasattr(os, "getuid") else "vibrofocus-logs"
    return Path(tempfile.gettempdir()) / own


def _ready_log_folder() -> tuple[Path, str | None]:
    """The log folder, made if missing, and what is wrong with it (None when it may be written)."""
    from .._safe_folders import private_folder_problem

    folder = log_folder()
    if os.environ.get("VIBROFOCUS_LOG_DIR"):
        folder.mkdir(parents=True, exist_ok=True)  # the user's own choice
        return folder, None
    # In the shared temporary folder: another user may have made it first, or left a link.
    return folder, private_folder_problem(folder)


def report_unexpected() -> int:
    """Report the exception being handled as one ``error:`` line; write its traceback to a log file.

    Called from an ``except`` block. With ``--debug`` the traceback is printed as well.

    Returns
    -------
    int
        The exit code, :data:`EXIT_UNEXPECTED`.
    """
    import datetime as _dt
    import tempfile
    import traceback

    exc = sys.exc_info()[1]
    text = "".join(traceback.format_exception(exc))
    where = "nowhere (the log folder cannot be written)"
    try:
        folder, problem = _ready_log_folder()
        if problem:
            where = f"nowhere (the log folder {folder} {problem}; remove it, or set VIBROFOCUS_LOG_DIR)"
        else:
            stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
            fd, name = tempfile.mkstemp(prefix=f"error-{stamp}-", suffix=".log", dir=folder)
            with os.fdopen(fd, "w", encoding="utf-8") as fh:
                fh.write(f"vibrofocus {' '.join(sys.argv[1:])[:MAX_MESSAGE_CHARS]}\n{text}")
            where = name
    except OSError:
        pass
    if DEBUG:
        err_console.print(text, markup=False, highlight=False)
    summary = str(exc).replace("\n", " ")[:200] or "(no message)"
    print_error(f"unexpected {type(exc).__name__}: {summary} -- this is a bug or a case vibrofocus does not check "
                f"yet; the traceback is in {where} (run with --debug to see it; please report it)")
    return EXIT_UNEXPECTED


def interrupted_exit(detail: str = "", *, code: int = EXIT_INTERRUPTED) -> typer.Exit:
    """Print the one interrupt line; return the Exit(``code``, default 130) to raise."""
    err_console.print(
        "[bold yellow]interrupted[/]" + (f": {detail}" if detail else ": stopped; no file was left half-written"),
        highlight=False,
    )
    return typer.Exit(code=code)


def _interrupt_code(by_signal: bool) -> int:
    """130, or with ``by_signal`` 128 + the number of the signal that came (143 for SIGTERM)."""
    from .. import _atomic

    signum = _atomic.interrupt_pending()
    return 128 + int(signum) if by_signal and signum is not None else EXIT_INTERRUPTED


@contextlib.contextmanager
def user_errors(*, interrupt_message: str = "", exit_by_signal: bool = False) -> Iterator[None]:
    """Run a command body: one ``error:`` line and exit 2 on user errors, exit 130 on interrupts.

    SIGINT and SIGTERM raise KeyboardInterrupt while the body runs (at safe points: file
    commits defer them until the rename is done); an interrupt that a library swallowed
    is still honoured when the body ends.

    Parameters
    ----------
    interrupt_message : str
        What to say after ``interrupted:`` (default: nothing half-written).
    exit_by_signal : bool
        Exit with 128 + the signal's number (130 for SIGINT, 143 for SIGTERM), as process
        supervisors expect of a server; default 130 for both.
    """
    from .. import _atomic

    _atomic.clear_interrupt()
    restore = _atomic.install_signal_handlers()
    guard = _atomic.output_guard()  # outputs never replace what the command reads
    guard.__enter__()
    try:
        yield
        if _atomic.interrupt_pending() is not None:
            raise KeyboardInterrupt
    except VibrofocusError as exc:
        if _atomic.interrupt_pending() is not None:
            raise interrupted_exit(interrupt_message, code=_interrupt_code(exit_by_signal)) from None
        _traceback()
        print_error(str(exc))
        raise typer.Exit(code=EXIT_USER_ERROR) from None
    except KeyboardInterrupt:
        _traceback()
        raise interrupted_exit(interrupt_message, code=_interrupt_code(exit_by_signal)) from None
    except OSError as exc:
        if exc.errno not in _USER_ERRNOS:
            raise
        from .._atomic import describe_os_error

        _traceback()
        where = f" {exc.filename}" if exc.filename else ""
        print_error(f"cannot access{where}: {describe_os_error(exc)}")
        raise typer.Exit(code=EXIT_USER_ERROR) from None
    finally:
        guard.__exit__(None, None, None)
        restore()
        _atomic.clear_interrupt()
