"""``vibrofocus calibrate``: measure a participant's transfer matrix into one file."""

from __future__ import annotations

from pathlib import Path

import typer

from ._errors import user_errors
from ._options import (
    AMPLITUDE_V_MIN,
    REPEATS_MAX,
    RIG_CONFIG_HELP,
    SEED_MAX,
    SWEEP_S_MIN,
    check_rig_options,
    force_option,
)
from ._command import command


#: The options' help, kept out of the signature so the command reads in one screen.
_HELP = {
    "participant": "Participant id stored in the file (1-64 letters, digits, _ . -).",
    "out": "Calibration file to write (a .nc name; netCDF4/HDF5).",
    "seed": "Participant seed of the simulated forearm; by default each participant id gets its own arm.",
    "skin": "Skin preset of the simulated forearm: nominal | low | high | voigt-fit.",
    "method": "mimo (all actuators at once with Hadamard-signed exponential sweeps, MIMO H1: about 1/3 of h1's time "
              "for a lower H error) | h1 (one actuator at a time, exponential sweeps, repeats, coherence) | paper "
              "(one linear sweep per actuator, FFT ratio).",
    "repeats": "Recordings per point and actuator (default 8 for h1 and mimo, 1 for paper; mimo: a multiple of 4 for "
               "3-4 actuators).",
    "sweep_s": "Sweep length, s (default 2; 2.5 for mimo; at most the rig's longest drive, 30 s on the simulated "
               "rig).",
    "amplitude_v": "Sweep peak at the actuator, V (at most the rig's peak limit).",
    "points": "Measure only this many points, spread over the array (reference layout: 5 = location 5 and the four "
              "guards, 7 adds locations 2 and 4, 9 adds 6 and 8), fit the skin model to them and predict H at the "
              "others. The file marks each point measured or predicted (point_measured); the quality table shows "
              "the predicted ones. Saves one vibrometer aim per point on a single-spot rig.",
    "layout": "Array layout file (layout.json of vibrofocus design-layout): where the actuators, locations and "
              "guards are; the calibration keeps it, so render, the studies and the web app use it (default the "
              "reference setup's 2x2).",
    "yes": "Do not ask before each point (only for rigs that record every point at once).",
    "figure": "Save |H| and coherence next to the file (.png).",
    "resume": "Continue an interrupted calibration from OUT.partial.npz (same command, same rig): its completed "
              "points are kept.",
    "force": "Write the file even with error verdicts, and replace an existing file of another kind.",
}


@command("calibrate", epilog="Example: vibrofocus calibrate --rig simulated --participant P01 --out P01.nc --yes")
def calibrate_command(
    participant: str = typer.Option(..., "--participant", "-p", help=_HELP["participant"]),
    out: Path = typer.Option(..., "--out", "-o", help=_HELP["out"]),
    rig: str = typer.Option("simulated", "--rig", help="simulated | audio | nidaq"),
    rig_config: Path | None = typer.Option(None, "--rig-config", help=RIG_CONFIG_HELP),
    seed: int | None = typer.Option(None, "--seed", min=0, max=SEED_MAX, show_default="derived from --participant",
                                    help=_HELP["seed"]),
    skin: str | None = typer.Option(None, "--skin", show_default="nominal", help=_HELP["skin"]),
    method: str = typer.Option("mimo", "--method", help=_HELP["method"]),
    repeats: int | None = typer.Option(None, "--repeats", min=1, max=REPEATS_MAX, help=_HELP["repeats"]),
    sweep_s: float | None = typer.Option(None, "--sweep-s", min=SWEEP_S_MIN, help=_HELP["sweep_s"]),
    amplitude_v: float = typer.Option(5.0, "--amplitude-v", min=AMPLITUDE_V_MIN, help=_HELP["amplitude_v"]),
    points: int | None = typer.Option(None, "--points", min=2, show_default="every point", help=_HELP["points"]),
    layout: Path | None = typer.Option(None, "--layout", help=_HELP["layout"]),
    yes: bool = typer.Option(False, "--yes", "-y", help=_HELP["yes"]),
    figure: bool = typer.Option(True, "--figure/--no-figure", help=_HELP["figure"]),
    resume: bool = typer.Option(False, "--resume", help=_HELP["resume"]),
    force: bool = typer.Option(False, "--force", help=_HELP["force"]),
) -> None:
    """Play sweeps on the actuators, record the skin, estimate H and judge its quality.

    Prints the plan and the real duration of its sweeps before the first one. A
    single-spot vibrometer asks you to aim it at each point (coordinates in mm, origin
    at the array centre, x toward the thumb, y toward the wrist). Writes OUT, a figure
    beside it, and prints a verdict per point and actuator.

    OUT is checked for room and write permission before the first sweep. If it still
    cannot be written at the end, the measurement is not lost: you are asked for another
    path (at a terminal) or it is saved to a fallback file that the error names.

    With --points K only K points are measured; the skin model fitted to them predicts
    H at the others (docs/method.md, "Calibrating fewer points").

    On a single-spot rig every completed point is kept in OUT.partial.npz as it is
    measured: after an interruption, the same command with --resume continues from the
    next point. The partial file is deleted once OUT is written.
    """
    with user_errors():
        from rich.console import Console

        from .._atomic import allow_overwrite
        from ..defaults import participant_seed
        from ..errors import ValidationError
        from ..rigs import make_rig
        from ..studies.storage import check_participant_id
        from ..workflows import calibrate_participant, check_calibration_out
        from ._save import save_or_offer_another_path

        console = Console()
        allow_overwrite(force)
        check_participant_id(participant)  # the same rule as the study database's
        check_rig_options(rig, rig_config)
        check_calibration_out(out, participant, force=force)
        if seed is None and rig == "simulated":
            seed = participant_seed(participant)
        with make_rig(rig, config=rig_config, seed=seed, skin=skin, layout=layout) as r:
            if getattr(r, "skin", None):
                console.print(f"simulated forearm: skin {r.skin}, seed {seed}", highlight=False)
            if r.max_points_per_recording is not None and yes:
                raise ValidationError(
                    f"--yes: the {rig} rig records {r.max_points_per_recording} point at a time and its vibrometer "
                    "must be aimed at every point; run without --yes"
                )
            with _BarProgress(console) as bar:
                calibrate_participant(
                    r, participant, out, method=method, repeats=repeats, sweep_s=sweep_s, amplitude_v=amplitude_v,
                    points=points, progress=bar, aim=bar.aim, checkpoint=True, resume=resume,
                    refuse_errors=not force, force=force, figure=figure,
                    save_with=lambda save, path: save_or_offer_another_path(save, path, what="calibration"))


class _BarProgress:
    """The workflow's :class:`~vibrofocus.workflows.Progress` as the command line shows it.

    Lines print as they come; the recordings show a bar (``rich``) with a second bar
    filling while a take plays; the quality table and verdicts print once judged.
    """

    def __init__(self, console):
        self.console = console
        self.bar = None
        self.task = None
        self.take = None

    def __enter__(self) -> "_BarProgress":
        return self

    def __exit__(self, *exc) -> None:
        self._close()

    def _close(self) -> None:
        if self.bar is not None:
            self.take.ended()
            self.bar.stop()
            self.bar = None

    def note(self, message: str, **details) -> None:
        plan = details.get("plan")
        if "path" in details and message.startswith("wrote "):
            self.console.print(message)  # as before: "wrote" lines are highlighted
        else:
            self.console.print(message, highlight=False)
        if plan is not None:
            self._open(plan.settings.take_s)

    def _open(self, take_s: float) -> None:
        from ._progress import ProgressLines, progress_bar

        self.bar = progress_bar(self.console, transient=True)
        self.bar.start()
        self.task = self.bar.add_task("calibrating", total=None)
        # The take's own bar only at a terminal: as lines it would repeat every take.
        self.take = _TakeClock(self.bar, take_s) if not isinstance(self.bar, ProgressLines) else _NoTakeClock()

    def step(self, done: int, total: int, message: str) -> None:
        if self.bar is None:
            return
        self.bar.update(self.task, completed=done, total=total, description=message)
        self.take.started() if message.endswith(": playing") else self.take.ended()

    def aim(self, label: str, xy) -> None:
        if self.bar is not None:
            self.bar.stop()
        typer.prompt(f"Aim the vibrometer at point {label} (x {xy[0] * 1e3:+.1f} mm, "
                     f"y {xy[1] * 1e3:+.1f} mm), then press Enter", default="", show_default=False)
        if self.bar is not None:
            self.bar.start()

    def judged(self, cal) -> None:
        self._close()
        self.console.print(cal.summary_table())
        for line in cal.quality.lines():
            # Indented: the one ``error:`` line of a refused run is the command's own.
            self.console.print(f"  {line}", highlight=False)

    def cancelled(self) -> bool:
        return False


class _NoTakeClock:
    """No second bar (progress printed as lines)."""

    def started(self) -> None:
        pass

    def ended(self) -> None:
        pass


class _TakeClock:
    """A second progress bar that fills while a take plays (a take lasts seconds)."""

    def __init__(self, progress, take_s: float):
        import threading

        self.progress, self.take_s = progress, take_s
        self.task = progress.add_task("this take", total=take_s, visible=False)
        self._stop = threading.Event()
        self._thread = None

    def started(self) -> None:
        import threading
        import time

        self.ended()
        self._stop.clear()
        t0 = time.monotonic()
        self.progress.update(self.task, completed=0, visible=True)

        def tick() -> None:
            while not self._stop.wait(0.1):
                self.progress.update(self.task, completed=min(time.monotonic() - t0, self.take_s))

        self._thread = threading.Thread(target=tick, daemon=True)
        self._thread.start()

    def ended(self) -> None:
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
            self._thread = None
        self.progress.update(self.task, visible=False)
