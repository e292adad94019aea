"""``vibrofocus psychopy``: PsychoPy's Builder experiments that use the tap component."""

from __future__ import annotations

from pathlib import Path

import typer

from ._errors import user_errors
from ._options import force_option

psychopy_app = typer.Typer(
    name="psychopy", help="PsychoPy Builder experiments with the vibrofocus tap component.",
    no_args_is_help=True,
)
#: Sub-apps this module adds to the root app (registered by :mod:`.commands`).
SUB_APPS = {"psychopy": psychopy_app}


@psychopy_app.command("compile")
def compile_command(
    psyexp: Path = typer.Argument(..., help="The Builder experiment (.psyexp)."),
    out: Path | None = typer.Option(None, "--out", help="The script to write (default: FILE.py beside it)."),
    force: bool = force_option(),
) -> None:
    """Compile a Builder experiment to a Python script, with the tap component loaded.

    PsychoPy's own shell compiler (python -m psychopy.scripts.psyexpCompile) does not load
    plugins and silently drops the tap ("# Unknown component ignored: tap"). This command
    activates PsychoPy's plugins first, as the Builder app does, and refuses a script that
    ignores a component. Run it in the Python that has PsychoPy and vibrofocus.
    """
    with user_errors():
        from .._atomic import allow_overwrite
        from ..psychopy.compile import compile_experiment

        allow_overwrite(force)
        written = compile_experiment(psyexp, out)
        typer.echo(f"wrote {written}")
