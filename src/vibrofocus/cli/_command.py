"""Marking a function as a command, without touching the app (registration is one-way).

A command module decorates its functions with :func:`command`, which only records the
name and options on the function. :mod:`.commands` imports the command modules in a
fixed order and registers what they mark on the app of :mod:`.main`; no command module
imports :mod:`.main`, so the order of ``vibrofocus --help`` never depends on which
module happened to be imported first.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

__all__ = ["command", "marked_commands"]

F = TypeVar("F", bound=Callable[..., Any])
_MARK = "__vibrofocus_command__"


def command(name: str | None = None, **options: Any) -> Callable[[F], F]:
    """Mark a function as a CLI command; :func:`typer.Typer.command` options are kept for registration.

    Parameters
    ----------
    name : str, optional
        Command name (default: from the function name, as typer does).
    **options
        Other options of ``typer.Typer.command`` (``epilog``, ``help``, ...).

    Returns
    -------
    callable
        A decorator that returns the function unchanged.
    """
    def mark(fn: F) -> F:
        setattr(fn, _MARK, (name, options))
        return fn

    return mark


def marked_commands(module: Any) -> list[tuple[Callable[..., Any], str | None, dict[str, Any]]]:
    """The functions ``module`` marks with :func:`command`, in the order they are defined.

    Parameters
    ----------
    module : module
        A command module.

    Returns
    -------
    list of tuple
        ``(function, name, options)`` per command.
    """
    found = []
    for value in vars(module).values():
        mark = getattr(value, _MARK, None)
        if mark is not None and getattr(value, "__module__", None) == module.__name__:
            found.append((value, mark[0], mark[1]))
    return found
