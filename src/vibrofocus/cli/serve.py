"""``vibrofocus serve``: the local web app for running studies."""

from __future__ import annotations

import os
from pathlib import Path

import typer

from ._errors import err_console, user_errors
from .main import app

_LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")


@app.command()
def serve(
    db: Path = typer.Option(Path("vibrofocus-studies.sqlite"), "--db", help="Study database (SQLite); created if missing."),
    host: str = typer.Option("127.0.0.1", "--host", help="Address to bind. Keep 127.0.0.1 unless you know why not."),
    port: int = typer.Option(8000, "--port", min=0, max=65535, help="TCP port."),
    rig: str = typer.Option("simulated", "--rig", help="Default rig: simulated, audio or nidaq."),
    no_browser: bool = typer.Option(False, "--no-browser", help="Do not open the experimenter page."),
    pace: str = typer.Option("normal", "--pace", help="Trial timing: normal, or fast for demonstrations and tests."),
) -> None:
    """Run the experimenter and participant pages (FastAPI + uvicorn) on this computer.

    Prints an experimenter token and the URL that logs in with it. Set
    VIBROFOCUS_TOKEN to reuse a token across restarts.
    """
    with user_errors():
        import secrets
        import threading
        import webbrowser

        import uvicorn

        from .._validation import check_choice
        from ..rigs import RIG_KINDS
        from ..web import PACES, create_app

        check_choice(rig, "rig", RIG_KINDS)
        check_choice(pace, "pace", tuple(PACES))
        token = os.environ.get("VIBROFOCUS_TOKEN") or secrets.token_urlsafe(24)
        if len(token) < 16:
            err_console.print("[bold red]error:[/] VIBROFOCUS_TOKEN must be at least 16 characters")
            raise typer.Exit(code=2)
        if host not in _LOCAL_HOSTS:
            # Participant data and rig control would be reachable from the network.
            err_console.print(
                f"[bold red]WARNING:[/] binding to {host}: anyone who can reach this address can try "
                "to use the study server. The studies are meant to run on localhost (127.0.0.1)."
            )
        web_app = create_app(db, token=token, rig=rig, pace=pace)
        shown = "127.0.0.1" if host in ("0.0.0.0", "::") else host
        base = f"http://{'[' + shown + ']' if ':' in shown else shown}:{port}"
        typer.echo(f"study database: {Path(db).resolve()}")
        typer.echo(f"experimenter token: {token}")
        typer.echo(f"experimenter page: {base}/?token={token}")
        typer.echo("participant pages: linked from the experimenter page (one per session)")
        if not no_browser:
            # A moment later, so that the page does not ask before uvicorn listens.
            threading.Timer(1.5, webbrowser.open, args=(f"{base}/?token={token}",)).start()
        uvicorn.run(web_app, host=host, port=port, log_level="warning")
