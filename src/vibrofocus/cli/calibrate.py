"""``vibrofocus calibrate``: measure a participant's transfer matrix into one file."""

from __future__ import annotations

from pathlib import Path

import typer

from ._errors import user_errors
from ._command import command


@command("calibrate", epilog="Example: vibrofocus calibrate --rig simulated --participant P01 --out P01.nc --yes")
def calibrate_command(
    participant: str = typer.Option(..., "--participant", "-p", help="Participant id stored in the file."),
    out: Path = typer.Option(..., "--out", "-o", help="Calibration file to write (.nc, netCDF4/HDF5)."),
    rig: str = typer.Option("simulated", "--rig", help="simulated | audio | nidaq"),
    rig_config: Path | None = typer.Option(None, "--rig-config", help="Hardware settings file for audio/nidaq."),
    seed: int | None = typer.Option(
        None, "--seed", min=0, show_default="derived from --participant",
        help="Participant seed of the simulated forearm; by default each participant id gets its own arm.",
    ),
    skin: str | None = typer.Option(None, "--skin", show_default="nominal",
                                    help="Skin preset of the simulated forearm: nominal | low | high | voigt-fit."),
    method: str = typer.Option(
        "mimo", "--method",
        help="mimo (all actuators at once with Hadamard-signed exponential sweeps, MIMO H1: about 1/3 of h1's time "
             "for a lower H error) | h1 (one actuator at a time, exponential sweeps, repeats, coherence) | paper "
             "(one linear sweep per actuator, FFT ratio)."),
    repeats: int | None = typer.Option(None, "--repeats", min=1, help="Recordings per point and actuator "
                                                                       "(default 8 for h1 and mimo, 1 for paper; "
                                                                       "mimo: a multiple of 4 for 3-4 actuators)."),
    sweep_s: float | None = typer.Option(None, "--sweep-s", help="Sweep length, s (default 2; 2.5 for mimo)."),
    amplitude_v: float = typer.Option(5.0, "--amplitude-v", help="Sweep peak at the actuator, V."),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask before each point (only for rigs that "
                                                        "record every point at once)."),
    figure: bool = typer.Option(True, "--figure/--no-figure", help="Save |H| and coherence next to the file (.png)."),
) -> None:
    """Play sweeps on the actuators, record the skin, estimate H and judge its quality.

    Prints the plan and the real duration of its sweeps before the first one. A
    single-spot vibrometer asks you to aim it at each point (coordinates in mm, origin
    at the array centre, x toward the thumb, y toward the wrist). Writes OUT, a figure
    beside it, and prints a verdict per point and actuator.

    OUT is checked for room and write permission before the first sweep. If it still
    cannot be written at the end, the measurement is not lost: you are asked for another
    path (at a terminal) or it is saved to a fallback file that the error names.
    """
    with user_errors():
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        from .._atomic import check_writable
        from ..calibration import calibrate, plan_calibration, save_calibration
        from ..io.calibration_nc import estimate_calibration_bytes
        from ..defaults import participant_seed
        from ..errors import ValidationError
        from ..rigs import make_rig
        from ._save import save_or_offer_another_path

        console = Console()
        if not out.parent.exists():
            raise ValidationError(f"--out {out}: the folder {out.parent} does not exist")
        if seed is None and rig == "simulated":
            seed = participant_seed(participant)
        with make_rig(rig, config=rig_config, seed=seed, skin=skin) as r:
            if getattr(r, "skin", None):
                console.print(f"simulated forearm: skin {r.skin}, seed {seed}", highlight=False)
            # Before the first sweep: a read-only folder or a full disk is found now, not
            # after the whole measurement.
            plan = plan_calibration(r, method=method, repeats=repeats, sweep_s=sweep_s, amplitude_v=amplitude_v)
            n_record = int(round((plan.settings.take_s + 0.5) * r.fs))
            check_writable(out, what="calibration", expected_bytes=estimate_calibration_bytes(
                r.layout.n_points, r.layout.n_actuators, plan.settings.repeats, n_record, 4096,
                all_at_once=method == "mimo"))
            if figure:
                check_writable(out.with_suffix(".png"), what="figure")
            if getattr(r, "read_strap_forces", None) is not None:
                from ..rigs.force import check_straps

                console.print(f"strap forces: {check_straps(r).message}", highlight=False)
            single_spot = r.max_points_per_recording is not None
            if single_spot and yes:
                raise ValidationError(
                    f"--yes: the {rig} rig records {r.max_points_per_recording} point at a time and its vibrometer "
                    "must be aimed at every point; run without --yes"
                )
            console.print(f"plan: {plan.describe()}", highlight=False)
            with Progress(TextColumn("[progress.description]{task.description}"), BarColumn(),
                          MofNCompleteColumn(), TimeElapsedColumn(), console=console, transient=True) as progress:
                task = progress.add_task("calibrating", total=None)

                def on_progress(done: int, total: int, message: str) -> None:
                    progress.update(task, completed=done, total=total, description=message)

                def prompt(label: str, xy) -> None:
                    progress.stop()
                    typer.prompt(f"Aim the vibrometer at point {label} (x {xy[0] * 1e3:+.1f} mm, "
                                 f"y {xy[1] * 1e3:+.1f} mm), then press Enter", default="", show_default=False)
                    progress.start()

                cal = calibrate(r, participant_id=participant, method=method, repeats=repeats, sweep_s=sweep_s,
                                amplitude_v=amplitude_v, prompt=None if not single_spot else prompt,
                                progress=on_progress)
        # The measurement stays in memory until it is on disk somewhere.
        out = save_or_offer_another_path(lambda path: save_calibration(cal, path), out, what="calibration")
        console.print(cal.summary_table())
        for line in cal.quality.lines():
            console.print(line, highlight=False)
        console.print(f"wrote {out}")
        if figure:
            from ..calibration.figures import plot_calibration

            png = out.with_suffix(".png")
            plot_calibration(cal, png)
            console.print(f"wrote {png}")
