"""Turn vibrofocus errors into a clear one-line message and exit code 2 for the CLI."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import typer
from rich.console import Console

from ..errors import VibrofocusError

err_console = Console(stderr=True)


@contextlib.contextmanager
def user_errors() -> Iterator[None]:
    """Context manager: print a VibrofocusError as ``error: ...`` and exit with code 2."""
    try:
        yield
    except VibrofocusError as exc:
        err_console.print(f"[bold red]error:[/] {exc}")
        raise typer.Exit(code=2) from None
