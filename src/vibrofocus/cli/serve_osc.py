"""``vibrofocus serve-osc``: taps asked live by other programs over Open Sound Control."""

from __future__ import annotations

from pathlib import Path

import typer

from ._command import command
from ._errors import err_console, user_errors
from ._options import RIG_CONFIG_HELP, SEED_MAX, check_rig_options, lsl_source_id_option

_LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")
_LSL_HELP = ("Send one stimulus-onset marker per played tap to the Lab Streaming Layer outlet "
             "'vibrofocus-markers' (type Markers; the short code tap/<method>, its JSON detail on "
             "'vibrofocus-markers-detail'), stamped with the tap's onset on LSL's clock; needs "
             "pip install 'vibrofocus[lsl]'. The source id comes from the --log file when given "
             "(a restarted server keeps its stream), else --lsl-source-id, else a new one.")


@command("serve-osc", epilog="Example: vibrofocus serve-osc --port 9000 --log taps.csv, then from a client: "
                             "/tap 5, /tap 5 -6 (6 dB below the design), /tap_xy 3.5 -4 (mm), /method contrast, /stop")
def serve_osc(
    port: int = typer.Option(9000, "--port", "-p", min=0, max=65535, help="UDP port to listen on (0: any free one)."),
    host: str = typer.Option("127.0.0.1", "--host", help="Address to bind. Keep 127.0.0.1 unless you know why not."),
    rig: str = typer.Option("simulated", "--rig", help="simulated | audio | nidaq"),
    rig_config: Path | None = typer.Option(None, "--rig-config", help=RIG_CONFIG_HELP),
    calibration: Path | None = typer.Option(None, "--calibration", "-c",
                                            help="Calibration file (.nc) the taps are designed from (required for "
                                                 "audio/nidaq; default on the simulated rig: the arm's own transfer)."),
    skin: str = typer.Option("nominal", "--skin", help="Skin preset of the simulated forearm: nominal | low | high | "
                                                       "voigt-fit."),
    method: str = typer.Option("inverse", "--method", "-m",
                               help="Rendering method at start (/method changes it). A method whose designs take "
                                    "seconds (minimax) is designed ahead at every location and then serves /tap only."),
    seed: int | None = typer.Option(None, "--seed", min=0, max=SEED_MAX,
                                    help="Participant seed of the simulated forearm."),
    max_wait_ms: float = typer.Option(500.0, "--max-wait-ms", min=1.0, max=60_000.0,
                                      help="A tap that waited longer than this behind others is dropped and "
                                           "answered /error stale (ms)."),
    log: Path | None = typer.Option(None, "--log", help="Keep every played tap in this file (.csv, or SQLite: .db, "
                                                       ".sqlite, .sqlite3): id, what was asked, level, method, onset "
                                                       "on the host and device clocks. Each tap is on disk before "
                                                       "its /played is sent; an existing tap log is continued."),
    lsl: bool = typer.Option(False, "--lsl", help=_LSL_HELP),
    lsl_source_id: str | None = lsl_source_id_option(),
) -> None:
    """Play taps that other programs (Unity, Max/MSP, Pure Data, Python) ask for over OSC/UDP.

    Addresses: /tap <location> [level_db], /tap_xy <x_mm> <y_mm> [level_db], /method <name>,
    /stop. The level is in dB re the design (0: as designed; -6: half the amplitude); the
    safety layer still checks the drive. A played tap is answered /played with what was
    asked, then its tap id, onset on the host clock (s), onset on the device clock (s, NaN
    without one), the device clock's name and the level; every problem is answered
    /error <reason> to the sender and plays nothing. Taps queue while one plays; one that waited longer than --max-wait-ms is dropped
    (/error stale). /stop acts at once, ahead of the queued taps: like Ctrl-C (SIGINT) or
    SIGTERM, it cuts the play under way, sets every output to zero and ends the server.
    Needs pip install 'vibrofocus[osc]'.
    """
    with user_errors(interrupt_message="serve-osc stopped; all outputs at zero"):
        import contextlib

        from ..errors import ValidationError

        try:
            import pythonosc  # noqa: F401 - the optional extra, checked before anything starts
        except ImportError:
            raise ValidationError("serve-osc needs python-osc: pip install 'vibrofocus[osc]'") from None
        from ..realtime import OscTapServer, TapDesigner, TapLog
        from ..realtime.limits import check_designs
        from ..rendering import TransferMatrix
        from ..rigs import make_rig
        from ..skin import skin_preset

        check_rig_options(rig, rig_config)
        if calibration is None and rig != "simulated":
            raise ValidationError(f"the {rig} rig needs --calibration (a calibration measured on it)")
        skin_name = skin_preset(skin).name
        if lsl_source_id is not None and not lsl:
            raise ValidationError("--lsl-source-id needs --lsl")
        if lsl:
            from ..io.lsl import check_source_id, import_pylsl, stable_source_id

            # Checked before the rig opens; a log names the stream, so a restarted server keeps it.
            stream_id = (check_source_id(lsl_source_id) if lsl_source_id is not None
                         else stable_source_id(log) if log is not None else None)
            import_pylsl()  # before the rig opens: a missing pylsl is one line, nothing started
        with contextlib.ExitStack() as stack:
            the_rig = stack.enter_context(make_rig(rig, config=rig_config, seed=seed,
                                                   skin=skin_name if rig == "simulated" else None))
            if calibration is not None:
                from .._atomic import protect
                from ..calibration import load_calibration

                protect(calibration, "calibration")
                cal = load_calibration(calibration)
                if abs(cal.fs - the_rig.fs) > 1e-9 * the_rig.fs:
                    raise ValidationError(f"--calibration {calibration} is at {cal.fs:g} Hz but the {rig} rig runs "
                                          f"at {the_rig.fs:g} Hz")
                if cal.layout.n_actuators != the_rig.layout.n_actuators:
                    raise ValidationError(f"--calibration {calibration} has {cal.layout.n_actuators} actuators, the "
                                          f"{rig} rig {the_rig.layout.n_actuators}")
                from ..studies.engine import CalibrationRenderer

                # The window the method's designs fit on this calibration, found as the studies
                # find it (the calibration's own resolution, doubled while a design needs more).
                window = CalibrationRenderer(cal, limit_v=the_rig.limits.peak_v, levels="equal-peak",
                                             bounds=False).prepare([method], cal.layout.location_numbers)
                tm, model = TransferMatrix.from_calibration(cal, window), cal.fit
                source = f"calibration {calibration}"
            else:
                tm, model = TransferMatrix.from_model(the_rig, the_rig.layout, the_rig.fs), the_rig
                source = f"the simulated arm's own transfer (skin {skin_name})"
            # Opened before the designs (seconds): a log that cannot be written is said at once.
            tap_log = stack.enter_context(TapLog(log)) if log is not None else None
            outlet = None
            if lsl:
                from ..io.lsl import MarkerOutlet

                outlet = stack.enter_context(MarkerOutlet(source_id=stream_id))
            from ..rendering import available_methods, method_class

            if method in available_methods() and not method_class(method).live:
                err_console.print(f"designing {method} at the {tm.layout.n_locations} locations ahead "
                                  "(seconds each) ...")
            designer = TapDesigner(tm, model, method=method, limit_v=the_rig.limits.peak_v)
            refused = check_designs(designer, the_rig)  # a tap the limits refuse is said now, not at the tap
            if refused:
                err_console.print(f"[bold yellow]warning:[/] {refused}", highlight=False)
            if model is not None:
                designer.prepare_grid()
            if host not in _LOCAL_HOSTS:
                err_console.print(f"[bold red]WARNING:[/] binding to {host}: anyone who can reach it can play taps.")
            server = OscTapServer(the_rig, designer, host=host, port=port, max_wait_s=max_wait_ms / 1e3,
                                  tap_log=tap_log, marker_sink=None if outlet is None else outlet.push)
            shown_host, shown_port = server.address
            if ":" in str(shown_host):  # an IPv6 address goes in brackets in a URL: osc.udp://[::1]:9124
                shown_host = f"[{shown_host}]"
            typer.echo(f"serve-osc: listening on osc.udp://{shown_host}:{shown_port} ({rig} rig, designs from "
                       f"{source}, method {designer.method}, drive limit {designer.limit_v:g} V)")
            typer.echo(f"taps: /tap 1..{designer.layout.n_locations}"
                       + (f" (no /tap_xy with {designer.method}: a design takes seconds)"
                          if not designer.live else
                          f", /tap_xy in {designer.area.describe()}" if model is not None else
                          " (no /tap_xy: the calibration has no fitted skin model)")
                       + " (each with an optional level, dB re the design); /method <name>; /stop", )
            kept = ([f"taps logged to {log}" + (f" after tap {tap_log.last_tap_id}" if tap_log.last_tap_id else "")]
                    if tap_log is not None else [])
            kept += [f"LSL markers on 'vibrofocus-markers' (source_id {outlet.source_id})"] if outlet is not None else []
            if kept:
                typer.echo("recording: " + "; ".join(kept))
            try:
                who = server.serve()
            finally:
                server.close()
            if server.log_error is not None:
                from ..errors import OutputError

                raise OutputError(f"serve-osc stopped: tap {server.records[-1].tap_id} played but could not be "
                                  f"written to {log} ({server.log_error}); all outputs at zero")
        typer.echo(f"serve-osc stopped by {who}; all outputs at zero")
