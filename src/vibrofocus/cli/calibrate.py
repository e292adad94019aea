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


@command("calibrate", epilog="Example: vibrofocus calibrate --rig simulated --participant P01 --out P01.nc --yes")
def calibrate_command(
    participant: str = typer.Option(..., "--participant", "-p",
                                    help="Participant id stored in the file (1-64 letters, digits, _ . -)."),
    out: Path = typer.Option(..., "--out", "-o", help="Calibration file to write (a .nc name; netCDF4/HDF5)."),
    rig: str = typer.Option("simulated", "--rig", help="simulated | audio | nidaq"),
    rig_config: Path | None = typer.Option(None, "--rig-config", help=RIG_CONFIG_HELP),
    seed: int | None = typer.Option(
        None, "--seed", min=0, max=SEED_MAX, show_default="derived from --participant",
        help="Participant seed of the simulated forearm; by default each participant id gets its own arm.",
    ),
    skin: str | None = typer.Option(None, "--skin", show_default="nominal",
                                    help="Skin preset of the simulated forearm: nominal | low | high | voigt-fit."),
    method: str = typer.Option(
        "mimo", "--method",
        help="mimo (all actuators at once with Hadamard-signed exponential sweeps, MIMO H1: about 1/3 of h1's time "
             "for a lower H error) | h1 (one actuator at a time, exponential sweeps, repeats, coherence) | paper "
             "(one linear sweep per actuator, FFT ratio)."),
    repeats: int | None = typer.Option(None, "--repeats", min=1, max=REPEATS_MAX,
                                       help="Recordings per point and actuator "
                                                                       "(default 8 for h1 and mimo, 1 for paper; "
                                                                       "mimo: a multiple of 4 for 3-4 actuators)."),
    sweep_s: float | None = typer.Option(None, "--sweep-s", min=SWEEP_S_MIN,
                                         help="Sweep length, s (default 2; 2.5 for mimo; at most the rig's longest "
                                              "drive, 30 s on the simulated rig)."),
    amplitude_v: float = typer.Option(5.0, "--amplitude-v", min=AMPLITUDE_V_MIN,
                                      help="Sweep peak at the actuator, V (at most the rig's peak limit)."),
    points: int | None = typer.Option(
        None, "--points", min=2, show_default="every point",
        help="Measure only this many points, spread over the array (reference layout: 5 = location 5 and the four "
             "guards, 7 adds locations 2 and 4, 9 adds 6 and 8), fit the skin model to them and predict H at the "
             "others. The file marks each point measured or predicted (point_measured); the quality table shows "
             "the predicted ones. Saves one vibrometer aim per point on a single-spot rig."),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask before each point (only for rigs that "
                                                        "record every point at once)."),
    figure: bool = typer.Option(True, "--figure/--no-figure", help="Save |H| and coherence next to the file (.png)."),
    resume: bool = typer.Option(False, "--resume", help="Continue an interrupted calibration from OUT.partial.npz "
                                                        "(same command, same rig): its completed points are kept."),
    force: bool = typer.Option(False, "--force", help="Write the file even with error verdicts, and replace an "
                                                     "existing file of another kind."),
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
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        from .._atomic import allow_overwrite, check_writable
        from ..calibration import calibrate, plan_calibration
        import os

        from ..calibration.files import save_calibration_keeping
        from ..calibration.checkpoint import partial_path
        from ..io.calibration_nc import estimate_calibration_bytes
        from ..defaults import participant_seed
        from ..errors import ValidationError
        from ..rigs import make_rig
        from ..studies.storage import check_participant_id
        from ._save import save_or_offer_another_path

        console = Console()
        allow_overwrite(force)
        check_participant_id(participant)  # the same rule as the study database's
        check_rig_options(rig, rig_config)
        if out.suffix.lower() != ".nc":
            raise ValidationError(f"--out {out}: use a .nc file name (the calibration is a netCDF4/HDF5 file)")
        if not out.parent.exists():
            raise ValidationError(f"--out {out}: the folder {out.parent} does not exist")
        from ..calibration.replacing import check_calibration_target

        # Before the measurement: another participant's calibration (or another kind of
        # file) at --out is refused now, not after an hour of a person's time.
        check_calibration_target(out, participant, force=force)
        if seed is None and rig == "simulated":
            seed = participant_seed(participant)
        with make_rig(rig, config=rig_config, seed=seed, skin=skin) as r:
            if getattr(r, "skin", None):
                console.print(f"simulated forearm: skin {r.skin}, seed {seed}", highlight=False)
            # Before the first sweep: a read-only folder or a full disk is found now, not
            # after the whole measurement.
            plan = plan_calibration(r, method=method, repeats=repeats, sweep_s=sweep_s, amplitude_v=amplitude_v,
                                    measure=points)
            n_record = int(round((plan.settings.take_s + 0.5) * r.fs))
            check_writable(out, what="calibration", expected_bytes=estimate_calibration_bytes(
                r.layout.n_points, r.layout.n_actuators, plan.settings.repeats, n_record, 4096,
                all_at_once=method == "mimo"))
            if figure:
                check_writable(out.with_suffix(".png"), what="figure")
            from ..rigs.force import check_straps, has_strap_sensors

            if has_strap_sensors(r):
                console.print(f"strap forces: {check_straps(r).message}", highlight=False)
            single_spot = r.max_points_per_recording is not None
            if single_spot and yes:
                raise ValidationError(
                    f"--yes: the {rig} rig records {r.max_points_per_recording} point at a time and its vibrometer "
                    "must be aimed at every point; run without --yes"
                )
            partial = partial_path(out) if single_spot else None
            if resume and (partial is None or not partial.exists()):
                raise ValidationError(f"--resume: there is no partial calibration {partial_path(out)} to continue"
                                      + ("" if single_spot else f" (the {rig} rig records every point at once)"))
            console.print(f"plan: {plan.describe()}", highlight=False)
            with Progress(TextColumn("[progress.description]{task.description}"), BarColumn(),
                          MofNCompleteColumn(), TimeElapsedColumn(), console=console, transient=True) as progress:
                task = progress.add_task("calibrating", total=None)
                take = _TakeClock(progress, plan.settings.take_s)

                def on_progress(done: int, total: int, message: str) -> None:
                    progress.update(task, completed=done, total=total, description=message)
                    take.started() if message.endswith(": playing") else take.ended()

                def prompt(label: str, xy) -> None:
                    progress.stop()
                    typer.prompt(f"Aim the vibrometer at point {label} (x {xy[0] * 1e3:+.1f} mm, "
                                 f"y {xy[1] * 1e3:+.1f} mm), then press Enter", default="", show_default=False)
                    progress.start()

                try:
                    with r.reserve(f"the calibration of {participant}"):  # one job on the hardware
                        cal = calibrate(r, participant_id=participant, method=method, repeats=repeats,
                                        sweep_s=sweep_s, amplitude_v=amplitude_v,
                                        prompt=None if not single_spot else prompt, progress=on_progress,
                                        checkpoint=partial, resume=resume, measure=points)
                except BaseException:
                    if partial is not None and partial.exists():
                        console.print(f"the completed points are kept in {partial}; continue with --resume",
                                      highlight=False)
                    raise
                finally:
                    take.ended()
        console.print(cal.summary_table())
        for line in cal.quality.lines():
            # Indented: the one ``error:`` line of a refused run is the command's own.
            console.print(f"  {line}", highlight=False)
        n_errors = sum(issue.severity == "error" for issue in cal.quality.issues)
        if n_errors and not force:
            # An error verdict and a file on disk would disagree: the file would be used.
            kept = f"; its takes stay in {partial} (--resume --force writes it)" if partial is not None and \
                partial.exists() else ""
            raise ValidationError(
                f"{n_errors} error verdict(s) above: the calibration was not written; fix the setup and measure "
                f"again (or keep it anyway with --force){kept}"
            )
        # The measurement stays in memory until it is on disk somewhere.
        kept: dict[str, Path | None] = {}

        def save(path: Path) -> Path:
            written, kept["nc"] = save_calibration_keeping(cal, path, force=force)
            return written

        out = save_or_offer_another_path(save, out, what="calibration")
        console.print(f"wrote {out}")
        if kept.get("nc") is not None:
            console.print(f"kept the previous calibration as {kept['nc']}", highlight=False)
        if partial is not None:
            partial.unlink(missing_ok=True)  # the whole calibration is on disk now
        if figure:
            from ..calibration.figures import plot_calibration

            png = out.with_suffix(".png")
            if kept.get("nc") is not None and png.is_file():
                # The previous figure goes with the previous calibration (P01.1.nc, P01.1.png).
                old_png = kept["nc"].with_suffix(".png")
                if not old_png.exists():
                    import shutil

                    try:
                        os.link(png, old_png)
                    except OSError:
                        shutil.copy2(png, old_png)
                    console.print(f"kept the previous figure as {old_png}", highlight=False)
            plot_calibration(cal, png)
            console.print(f"wrote {png}")


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
