"""``vibrofocus stop``: the emergency stop of a running ``vibrofocus serve``, from a terminal."""

from __future__ import annotations

from pathlib import Path

import typer

from ._command import command
from ._errors import user_errors


@command()
def stop(
    db: Path = typer.Option(Path("vibrofocus-studies.sqlite"), "--db", help="The study database the server was started with."),
) -> None:
    """Emergency stop of the 'vibrofocus serve' of a database: every output to 0 V, calibrations cancelled, running sessions paused.

    Works when the server's port is flooded or its page does not answer: it talks to the
    server through a socket only the user running the server can open (see docs/security.md).
    It believes only a socket that is yours (or root's), closed to others and answered by a
    program of yours; otherwise, or when the server does not answer, it says 'not stopped'
    (exit 2): then switch the amplifier off. Resume the paused sessions from the
    experimenter page.
    """
    with user_errors():
        from .._stop_client import request_stop

        done = request_stop(db)
        typer.echo("stopped: " + ("; ".join(done) if done else "nothing was running"))
