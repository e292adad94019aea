"""``vibrofocus serve-osc``: taps asked live by other programs over Open Sound Control."""

from __future__ import annotations

from pathlib import Path

import typer

from ._command import command
from ._errors import err_console, user_errors
from ._options import RIG_CONFIG_HELP, SEED_MAX, check_rig_options, lsl_source_id_option

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
        # At once, before the imports (seconds): the start takes about a minute on the simulated rig.
        err_console.print(f"serve-osc: starting on the {rig} rig; each step is said as it begins ...", highlight=False)
        from ..workflows import serve_live_taps

        check_rig_options(rig, rig_config)
        serve_live_taps(port=port, host=host, rig=rig, rig_config=rig_config, calibration=calibration, skin=skin,
                        method=method, seed=seed, max_wait_ms=max_wait_ms, log=log, lsl=lsl,
                        lsl_source_id=lsl_source_id, progress=_Lines())


class _Lines:
    """The live-taps workflow's lines: stdout, or stderr (warnings in colour); its steps as
    a bar on stderr at a terminal, else as lines with the time left (cli/_progress.py)."""

    def __init__(self) -> None:
        self._bar, self._task = None, None

    def step(self, done: int, total: int, message: str) -> None:
        if self._bar is None:
            from ._progress import progress_bar

            self._bar = progress_bar(err_console, transient=True)
            self._bar.start()
            self._task = self._bar.add_task(message, total=total)
        self._bar.update(self._task, completed=done, total=total, description=message)
        if done >= total:
            self._bar.stop()
            self._bar = None

    def note(self, message: str, **details) -> None:
        if details.get("danger"):
            err_console.print(f"[bold red]{message}[/]", highlight=False)
        elif details.get("warning"):
            err_console.print(f"[bold yellow]{message}[/]", highlight=False)
        elif details.get("err"):
            err_console.print(message, highlight=False)
        else:
            typer.echo(message)

    def judged(self, result) -> None:
        pass

    def cancelled(self) -> bool:
        return False
