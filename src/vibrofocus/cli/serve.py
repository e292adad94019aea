"""``vibrofocus serve``: the local web app for running studies."""

from __future__ import annotations

import os
from pathlib import Path

import typer

from ._errors import err_console, user_errors
from ._options import lsl_option, lsl_source, lsl_source_id_option, lsl_wait_option
from ._command import command

_LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")


@command()
def serve(
    db: Path = typer.Option(Path("vibrofocus-studies.sqlite"), "--db", help="Study database (SQLite); created if missing."),
    host: str = typer.Option("127.0.0.1", "--host", help="Address to bind. Keep 127.0.0.1 unless you know why not."),
    port: int = typer.Option(8000, "--port", min=0, max=65535, help="TCP port."),
    rig: str = typer.Option("simulated", "--rig", help="The rig: simulated, audio or nidaq (the simulated forearm stays available for rehearsals)."),
    rig_config: Path | None = typer.Option(None, "--rig-config", help="Hardware settings file of the audio or nidaq rig (see examples/rigs/)."),
    no_browser: bool = typer.Option(False, "--no-browser", help="Do not open the experimenter page."),
    pace: str = typer.Option("normal", "--pace", help="Trial timing: normal, or fast for demonstrations and tests."),
    skin: str = typer.Option("nominal", "--skin", help="Skin preset of the simulated forearm: nominal | low | high | voigt-fit."),
    allow_host: list[str] = typer.Option([], "--allow-host", help="Another host name the pages may be opened at (e.g. this computer's name on the lab network); repeatable."),
    max_connections: int = typer.Option(1000, "--max-connections", min=4, max=1_000_000, help="Most connections open at once; beyond it the longest-idle one is closed, or the new one refused when all are busy."),
    header_timeout: float = typer.Option(10.0, "--header-timeout", min=0.1, max=600.0, help="Seconds a connection may take to send a request's headers before it is closed."),
    keep_alive: float = typer.Option(5.0, "--keep-alive", min=0.1, max=3600.0, help="Seconds an idle connection is kept open between requests."),
    head_grace: float = typer.Option(0.5, "--head-grace", min=0.01, max=60.0, help="Seconds a new connection has to start its request before it may be closed as idle when the connections are full (raise it for clients on slow networks)."),
    body_timeout: float = typer.Option(10.0, "--body-timeout", min=0.1, max=600.0, help="Seconds a request may take to send its body once its headers are in; then it gets 408 and its connection is closed."),
    trusted_proxy: str | None = typer.Option(None, "--trusted-proxy", metavar="ADDR", help="Address of a reverse proxy in front of this server whose X-Forwarded-For header names the real client (comma-separated for several). Without it, forwarding headers are ignored."),
    lsl: bool = lsl_option(),
    lsl_source_id: str | None = lsl_source_id_option(),
    lsl_wait: float = lsl_wait_option(),
    participant_audio_elsewhere: bool = typer.Option(
        False, "--participant-audio-elsewhere",
        help="With an audio rig whose interface is this computer's default output: the participant page "
             "plays its beep on another computer or device, never on this one (the beep is outside every "
             "safety check)."),
) -> None:
    """Run the experimenter and participant pages (FastAPI + uvicorn) on this computer.

    Prints a one-time login link (opened in the browser) and the experimenter token,
    which the login page also accepts. Set VIBROFOCUS_TOKEN to reuse a token across
    restarts. 'vibrofocus stop --db DB' (same user) stops every output of this server,
    also when its port or page does not answer.

    The database must be yours, in a folder other users cannot write in; a second server
    of one database is refused (docs/security.md).
    """
    with user_errors(exit_by_signal=True):  # 143 on SIGTERM, as supervisors expect
        import contextlib
        import threading
        import webbrowser

        from ..skin import skin_preset
        from ..studies.markers import lsl_markers
        from ..web import create_app
        from ..web.emergency import ServerGuard
        from ..web.serving import ServerLimits, listen, run

        _check_options(rig, rig_config, pace, db, participant_audio_elsewhere)
        markers = contextlib.ExitStack()
        # A bad id or no pylsl: one error line before anything starts.
        outlet = markers.enter_context(lsl_markers(lsl, source_id=lsl_source(lsl, lsl_source_id, db), wait_s=lsl_wait))
        skin = skin_preset(skin).name
        token = _token(host)
        # Participant data: everything this server writes (database, calibrations,
        # exports, reports) is readable by this user only.
        os.umask(0o077)
        extra_hosts = tuple(allow_host) + (() if host in _LOCAL_HOSTS + ("0.0.0.0", "::") else (host,))
        web_app = create_app(db, token=token, rig=rig, pace=pace, allowed_hosts=extra_hosts,
                             rig_config=rig_config if rig != "simulated" else None, rig_factory=_rig_factory(skin),
                             body_timeout_s=body_timeout)
        # The one server of this database: a second one is refused here, naming the first.
        guard = ServerGuard(web_app.state.web)
        guard.claim(port or None)
        try:
            sock = listen(host, port)  # a busy port is one error line, before any link is printed
            port = sock.getsockname()[1]
            guard.record_port(port)
            # 'vibrofocus stop' must work before it is offered: no socket, no server.
            guard.open_stop_socket()
            login = _print_links(web_app, db, host, port, token, skin, outlet)
            if not no_browser:
                # A moment later, so that the page does not ask before uvicorn listens.
                threading.Timer(1.5, webbrowser.open, args=(login,)).start()
            with markers:
                run(web_app, host=host, port=port, sock=sock, trusted_proxy=trusted_proxy, limits=ServerLimits(
                    max_connections=max_connections, header_timeout_s=header_timeout, keep_alive_s=keep_alive,
                    body_timeout_s=body_timeout, head_grace_s=head_grace))
        finally:
            guard.close()  # after the server's shutdown: 'vibrofocus stop' answers until its end


def _token(host: str) -> str:
    """The experimenter token (VIBROFOCUS_TOKEN, or a new one), with a warning when the server is public."""
    import secrets

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
    return token


def _check_options(rig: str, rig_config: Path | None, pace: str, db: Path, participant_audio_elsewhere: bool) -> None:
    """The rig, its settings, the pace and the database, checked before anything starts."""
    from .._validation import check_choice
    from ..rigs import RIG_KINDS
    from ..web import PACES

    check_choice(rig, "rig", RIG_KINDS)
    _check_rig_config(rig, rig_config, participant_audio_elsewhere)
    check_choice(pace, "pace", tuple(PACES))
    _check_database(db)


def _check_rig_config(rig: str, rig_config: Path | None, participant_audio_elsewhere: bool) -> None:
    """A hardware rig's settings file, read and checked now (not at the first calibration)."""
    if rig == "simulated":
        return
    from ..errors import ValidationError
    from ..rigs.config import load_rig_config

    if rig_config is None:
        raise ValidationError(f"the {rig} rig needs its settings: add --rig-config FILE (see examples/rigs/{rig}.toml)")
    cfg = load_rig_config(rig_config)
    if cfg.kind != rig:
        raise ValidationError(f"--rig-config {rig_config} is for a {cfg.kind} rig, but --rig is {rig}")
    if rig == "audio":
        _check_page_beep_output(cfg, participant_audio_elsewhere)


def _rig_factory(skin: str):
    """Rigs for the web app: the simulated forearm gets the chosen skin; hardware rigs measure a real arm."""
    from ..rigs import make_rig

    def rig_factory(kind: str, *, seed: int | None = None, **kwargs):
        return make_rig(kind, seed=seed, skin=skin if kind == "simulated" else None, **kwargs)

    return rig_factory


def _print_links(web_app, db: Path, host: str, port: int, token: str, skin: str, outlet) -> str:
    """The server's lines for its user (pages, login link, token, stop); returns the login link."""
    shown = "127.0.0.1" if host in ("0.0.0.0", "::") else host
    base = f"http://{'[' + shown + ']' if ':' in shown else shown}:{port}"
    login = f"{base}/login/{web_app.state.web.new_login_code()}"
    typer.echo(f"study database: {Path(db).resolve()}")
    typer.echo(f"rig: {web_app.state.web.rig_label} (simulated forearm: skin {skin})")
    typer.echo(f"experimenter page: {base}/")
    typer.echo(f"one-time login link (valid 15 minutes, works once): {login}")
    typer.echo(f"experimenter token (for the login page): {token}")
    typer.echo("participant pages: linked from the experimenter page (one per session)")
    typer.echo(f"emergency stop from a terminal: vibrofocus stop --db {Path(db).resolve()}")
    if outlet is not None:
        typer.echo(f"LSL markers: outlet vibrofocus-markers (type Markers, source id {outlet.source_id})")
    return login


def _check_database(db: Path) -> None:
    """Refuse, before the server touches it (it tightens the file's mode), a --db that is no study database.

    A device, FIFO or folder (:func:`vibrofocus._atomic.output_target`), a file of
    another kind (a calibration), or a missing folder: one error line, nothing changed.
    """
    from .._atomic import file_kind, output_target
    from ..errors import ValidationError

    if db.exists() or db.is_symlink():
        output_target(db, "study database")
        kind = file_kind(db)
        if kind not in (None, "SQLite database"):
            raise ValidationError(f"--db {db}: it holds a {kind}, not a study database; give a .sqlite file or a new name")
    elif not db.parent.is_dir():
        raise ValidationError(f"--db {db}: the folder {db.parent} does not exist")


def _check_page_beep_output(cfg, audio_elsewhere: bool) -> None:
    """Refuse an audio rig whose interface is the default output the participant page would beep on."""
    from ..errors import ValidationError
    from ..rigs.audio import _sounddevice, default_output_risk, resolve_audio_device

    sd = _sounddevice()
    rig_index = resolve_audio_device(cfg.device.name, cfg.device.hostapi, outputs=max(cfg.channels.actuators))
    rig_name = str(sd.query_devices(rig_index)["name"])
    if "jack" in str(sd.query_hostapis(int(sd.query_devices(rig_index)["hostapi"]))["name"]).lower():
        # The browser never plays through PortAudio: PortAudio's default says nothing there.
        from ..rigs.page_beep import check_page_beep_on_jack

        warning = None if audio_elsewhere else check_page_beep_on_jack(rig_name, cfg.channels.actuators)
        if warning:
            err_console.print(f"[bold yellow]warning:[/] {warning}", highlight=False)
        return
    try:
        default = sd.query_devices(kind="output")
    except sd.PortAudioError:  # no default output: the page has nowhere to beep here
        return
    risk = default_output_risk(rig_name, str(default["name"]), same_index=int(default["index"]) == rig_index)
    if risk == "same" and not audio_elsewhere:
        raise ValidationError(
            f"this computer's default audio output ({default['name']}) is the interface that drives the "
            f"actuators ({rig_name}): the participant page's beep would play on them, outside every safety "
            "check. Make the participant's headphones the default output, or, if the participant page runs on "
            "another computer, add --participant-audio-elsewhere (docs/hardware.md)")
    if risk is not None:
        err_console.print(
            f"[bold yellow]warning:[/] the default audio output ({default['name']}) may reach the actuator "
            f"interface ({rig_name}); the participant page's beep plays on it. Route it to headphones "
            "(docs/hardware.md).", highlight=False)
