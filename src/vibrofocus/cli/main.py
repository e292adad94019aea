"""The ``vibrofocus`` command line.

Each command lives in its own module of this subpackage and registers itself on ``app``.
Command modules import only typer at module level; heavy dependencies (matplotlib,
pingouin, FastAPI) are imported inside the command so ``vibrofocus --help`` stays fast.
"""

from __future__ import annotations

import typer

from .. import __version__

app = typer.Typer(
    name="vibrofocus",
    help="Focused vibrotactile stimuli on sparse actuator arrays: calibrate, render, run studies, analyse.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
)


def _version_callback(value: bool) -> None:
    if value:
        typer.echo(f"vibrofocus {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_version_callback, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    """Focused vibrotactile stimuli on sparse actuator arrays."""


# Command modules register themselves on import; keep this list explicit.
from . import commands  # noqa: E402,F401
