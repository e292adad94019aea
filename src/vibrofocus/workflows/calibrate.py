"""Calibrate a participant: plan, record, estimate, judge, save, register."""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ContextManager

from ..errors import ValidationError
from .progress import Progress, QuietProgress, WorkflowCancelled

__all__ = ["CalibrationOutcome", "calibrate_participant", "check_calibration_out"]

#: ``aim(label, xy)``: ask the person to aim a single-spot vibrometer at point ``label``
#: (``xy`` in m, origin at the array centre) and return once it is aimed.
AimFn = Callable[[str, Any], None]
#: ``save_with(save, path) -> path``: call ``save(path)``, or save elsewhere when it fails.
SaveWithFn = Callable[[Callable[[Path], Path], Path], Path]


@dataclass(frozen=True)
class CalibrationOutcome:
    """What :func:`calibrate_participant` measured and where it went.

    Attributes
    ----------
    calibration : Calibration
        The measured calibration (its ``quality`` holds the verdicts).
    path : Path
        The file written (``out``, or the other path ``save_with`` chose).
    kept : Path or None
        Where the calibration replaced at ``path`` was kept (``<stem>.1.nc``), or None.
    figure : Path or None
        The figure written beside the file, or None.
    calibration_id : int or None
        Its id in the study database when registered there, else None.
    n_errors : int
        The error verdicts of its quality report.
    """

    calibration: Any
    path: Path
    kept: Path | None = None
    figure: Path | None = None
    calibration_id: int | None = None
    n_errors: int = 0


def check_calibration_out(out: Path, participant_id: str, *, force: bool = False) -> None:
    """Refuse a calibration file name before any measurement.

    Parameters
    ----------
    out : Path
        The ``.nc`` file to write; its folder must exist.
    participant_id : str
        The participant (1-64 letters, digits, ``_ . -``, the study database's rule).
    force : bool
        Allow replacing another participant's calibration or a file of another kind.

    Raises
    ------
    ValidationError, OutputError
        A bad participant id or name, a missing folder, or a file the rules keep
        (:func:`vibrofocus.calibration.replacing.check_calibration_target`).
    """
    from ..calibration.replacing import check_calibration_target
    from ..studies.storage import check_participant_id

    check_participant_id(participant_id)  # the same rule as the study database's
    if out.suffix.lower() != ".nc":
        raise ValidationError(f"--out {out}: use a .nc file name (the calibration is a netCDF4/HDF5 file)")
    if not out.parent.exists():
        raise ValidationError(f"--out {out}: the folder {out.parent} does not exist")
    # Before the measurement: another participant's calibration (or another kind of
    # file) at ``out`` is refused now, not after an hour of a person's time.
    check_calibration_target(out, participant_id, force=force)


def calibrate_participant(
    rig: Any,
    participant_id: str,
    out: Path,
    *,
    method: str | None = None,
    repeats: int | None = None,
    sweep_s: float | None = None,
    amplitude_v: float = 5.0,
    points: int | None = None,
    progress: Progress | None = None,
    aim: AimFn | None = None,
    checkpoint: bool = False,
    resume: bool = False,
    refuse_errors: bool = False,
    force: bool = False,
    figure: bool = False,
    before_saving: Callable[[], None] | None = None,
    save_with: SaveWithFn | None = None,
    store: Any = None,
    store_lock: ContextManager | None = None,
) -> CalibrationOutcome:
    """Measure a participant's transfer matrix on a rig, judge it, save it and register it.

    The steps, in order: plan (:func:`~vibrofocus.calibration.plan_calibration`), check
    that ``out`` can take the file, read the strap forces (a rig with strap sensors),
    record and estimate (:func:`~vibrofocus.calibration.calibrate`, holding the rig with
    ``rig.reserve``), judge (the quality verdicts; ``refuse_errors`` stops here), call
    ``before_saving`` (the point of no return), save
    (:func:`~vibrofocus.calibration.files.save_calibration_keeping`), draw the figure,
    and register the file in ``store``.

    Parameters
    ----------
    rig : Rig
        An open rig (the caller opens and closes it).
    participant_id : str
        The participant measured.
    out : Path
        The ``.nc`` file to write; its folder must exist.
    method, repeats, sweep_s, amplitude_v, points
        As :func:`vibrofocus.calibration.calibrate` (``points`` is its ``measure``):
        the method (default ``mimo``), recordings per point and actuator, sweep length
        in s, sweep peak in V, and the number of points measured (None: every point).
    progress : Progress, optional
        Where steps and lines go, and the cancel check (default: :class:`QuietProgress`).
    aim : callable, optional
        ``aim(label, xy)``, called before each point on a rig that records one point at
        a time (a single-spot vibrometer); ``xy`` in m.
    checkpoint : bool
        On such a rig, keep every completed point in ``out``'s partial file
        (:func:`vibrofocus.calibration.checkpoint.partial_path`), deleted once ``out`` is
        written.
    resume : bool
        Continue from that partial file (it must exist).
    refuse_errors : bool
        Refuse to save a calibration with error verdicts (:class:`ValidationError`).
    force : bool
        Replace another participant's calibration or a file of another kind at ``out``.
    figure : bool
        Draw |H| and coherence beside the file (``.png``).
    before_saving : callable, optional
        Called once every recording, the estimate and the judgement are over, just
        before saving: a front-end's point of no return (it may raise to save nothing).
    save_with : callable, optional
        ``save_with(save, out) -> path``: call ``save(out)``, or save elsewhere when
        ``out`` cannot be written (the command line asks for another path).
    store : StudyStore, optional
        Register the file as the participant's calibration (``add_calibration``).
    store_lock : context manager, optional
        Held around the use of ``store``.

    Returns
    -------
    CalibrationOutcome

    Raises
    ------
    WorkflowCancelled
        ``progress.cancelled()`` turned true before saving: nothing is saved.
    ValidationError
        A bad plan, ``resume`` without a partial file, or error verdicts with
        ``refuse_errors``.
    OutputError
        ``out`` (or the figure) cannot be written.
    """
    from .._atomic import check_writable
    from ..calibration import calibrate, plan_calibration
    from ..calibration.checkpoint import partial_path
    from ..io.calibration_nc import estimate_calibration_bytes
    from ..rigs.force import check_straps, has_strap_sensors

    progress = progress if progress is not None else QuietProgress()
    method = method if method is not None else "mimo"
    plan = plan_calibration(rig, method=method, repeats=repeats, sweep_s=sweep_s, amplitude_v=amplitude_v,
                            measure=points)
    # Before the first sweep: a read-only folder or a full disk is found now, not after
    # the whole measurement.
    n_record = int(round((plan.settings.take_s + 0.5) * rig.fs))
    check_writable(out, what="calibration", expected_bytes=estimate_calibration_bytes(
        rig.layout.n_points, rig.layout.n_actuators, plan.settings.repeats, n_record, 4096,
        all_at_once=method == "mimo"))
    if figure:
        check_writable(out.with_suffix(".png"), what="figure")
    if has_strap_sensors(rig):
        # Read before the first sweep, so loose straps are seen now; calibrate() stores
        # its own reading with the calibration.
        reading = check_straps(rig)
        progress.note(f"strap forces: {reading.message}", straps=reading)
    single_spot = getattr(rig, "max_points_per_recording", None) is not None
    partial = partial_path(out) if single_spot and checkpoint else None
    if resume and (partial is None or not partial.exists()):
        raise ValidationError(f"--resume: there is no partial calibration {partial_path(out)} to continue"
                              + ("" if single_spot else f" (the {getattr(rig, 'kind', 'this')} rig records every point at once)"))
    progress.note(f"plan: {plan.describe()}", plan=plan)

    def on_step(done: int, total: int, message: str) -> None:
        progress.step(done, total, message)
        if progress.cancelled():
            raise WorkflowCancelled("cancelled")

    def on_aim(label: str, xy: Any) -> None:
        if aim is not None:
            aim(label, xy)
        if progress.cancelled():
            raise WorkflowCancelled("cancelled")

    try:
        with rig.reserve(f"the calibration of {participant_id}"):  # one job on the hardware
            cal = calibrate(rig, participant_id=participant_id, method=method, repeats=repeats, sweep_s=sweep_s,
                            amplitude_v=amplitude_v, prompt=on_aim if single_spot else None, progress=on_step,
                            checkpoint=partial, resume=resume, measure=points, plan=plan)
    except BaseException:
        if partial is not None and partial.exists():
            progress.note(f"the completed points are kept in {partial}; continue with --resume")
        raise
    progress.judged(cal)
    n_errors = sum(issue.severity == "error" for issue in cal.quality.issues)
    if n_errors and refuse_errors:
        # An error verdict and a file on disk would disagree: the file would be used.
        kept_partial = f"; its takes stay in {partial} (--resume --force writes it)" if partial is not None and \
            partial.exists() else ""
        raise ValidationError(
            f"{n_errors} error verdict(s) above: the calibration was not written; fix the setup and measure "
            f"again (or keep it anyway with --force){kept_partial}"
        )
    if progress.cancelled():
        raise WorkflowCancelled("cancelled")
    if before_saving is not None:
        before_saving()  # the point of no return
    path, kept = _save(cal, out, force=force, save_with=save_with)
    progress.note(f"wrote {path}", path=path)
    if kept is not None:
        progress.note(f"kept the previous calibration as {kept}", path=kept)
    if partial is not None:
        partial.unlink(missing_ok=True)  # the whole calibration is on disk now
    png = _draw(cal, path, kept, progress) if figure else None
    cal_id = None
    if store is not None:
        with store_lock if store_lock is not None else contextlib.nullcontext():
            cal_id = store.add_calibration(participant_id, path)
    return CalibrationOutcome(calibration=cal, path=path, kept=kept, figure=png, calibration_id=cal_id,
                              n_errors=n_errors)


def _save(cal: Any, out: Path, *, force: bool, save_with: SaveWithFn | None) -> tuple[Path, Path | None]:
    """Save ``cal`` at ``out`` (or where ``save_with`` puts it): the path, and the previous file kept."""
    from ..calibration.files import save_calibration_keeping

    # The measurement stays in memory until it is on disk somewhere.
    kept: dict[str, Path | None] = {}

    def save(path: Path) -> Path:
        written, kept["nc"] = save_calibration_keeping(cal, path, force=force)
        return written

    path = save_with(save, out) if save_with is not None else save(out)
    return path, kept.get("nc")


def _draw(cal: Any, path: Path, kept: Path | None, progress: Progress) -> Path:
    """Draw the figure beside ``path``; the previous figure goes with the previous calibration."""
    from ..calibration.figures import plot_calibration

    png = path.with_suffix(".png")
    if kept is not None and png.is_file():
        # The previous figure goes with the previous calibration (P01.1.nc, P01.1.png).
        old_png = kept.with_suffix(".png")
        if not old_png.exists():
            try:
                os.link(png, old_png)
            except OSError:
                shutil.copy2(png, old_png)
            progress.note(f"kept the previous figure as {old_png}", path=old_png)
    plot_calibration(cal, png)
    progress.note(f"wrote {png}", path=png)
    return png
