"""Calibrations to and from their files: the domain objects built on the plain records of
:mod:`vibrofocus.io.calibration_nc`.

The file format reads and writes arrays and JSON-like dicts only; this module turns a
:class:`~.calibrate.Calibration` into that record and back, and checks what only the domain
knows: the stored points and actuators against the layout, the skin-model fit's parameter
names.
"""

from __future__ import annotations

import contextlib

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CalibrationFileError, ValidationError
from ..io.calibration_nc import read_calibration_file, write_calibration_file
from ..io.calibration_record import CalibrationFileRecord, FitRecord, QualityRecord
from ..io.sofa import read_sofa_tf, write_sofa_tf
from ..layout import ArrayLayout
from .calibrate import Calibration
from .excitation import SweepSettings
from .fitmodel import FIT_LAWS, FittedSkin, parameter_names
from .quality import QualityIssue, QualityReport, QualityThresholds

__all__ = ["save_calibration", "load_calibration", "calibration_record", "calibration_from_record", "export_sofa",
           "import_sofa"]

# QualityReport's array fields, stored as they are.
_QUALITY_ARRAYS = ("snr_db", "noise_rms_m", "band_gain", "low_coherence_share", "coherent_to_hz", "clipped",
                   "repeats_used", "dropouts", "polarity", "input_condition", "input_correlation")


def calibration_record(cal: Calibration) -> CalibrationFileRecord:
    """The file record of a calibration (:class:`~vibrofocus.io.calibration_record.CalibrationFileRecord`).

    Parameters
    ----------
    cal : Calibration

    Returns
    -------
    CalibrationFileRecord
        Arrays, numbers, strings and JSON-like dicts; no vibrofocus object.
    """
    if not isinstance(cal, Calibration):
        raise ValidationError(f"cal must be a Calibration, got {type(cal).__name__}")
    lay, q, fit = cal.layout, cal.quality, cal.fit
    quality = QualityRecord(issues=[i.to_dict() for i in q.issues], thresholds=q.thresholds.to_dict(),
                            **{name: getattr(q, name) for name in _QUALITY_ARRAYS})
    return CalibrationFileRecord(
        H=cal.H, freqs=cal.freqs, coherence=cal.coherence, drives=cal.drives, recordings=cal.recordings,
        fs=cal.fs, band=tuple(cal.band), n_fft=cal.n_fft, method=cal.method, participant_id=cal.participant_id,
        created=cal.created, software_version=cal.software_version, schema_version=cal.schema_version,
        layout=lay.to_dict(), point_labels=list(lay.point_labels),
        point_kinds=["location"] * lay.n_locations + ["guard"] * lay.n_guards,
        actuator_names=list(lay.actuator_names), points_xy=lay.points_xy, actuators_xy=lay.actuators_xy,
        rig=cal.rig, sweep=cal.sweep.to_dict(), quality=quality, codes=cal.codes,
        multiple_coherence=cal.multiple_coherence, straps=cal.straps, recorded_s=cal.recorded_s,
        measured=cal.measured, fit=None if fit is None else FitRecord(
            names=fit.names, values=fit.values, std=fit.std, log_covariance=fit.log_covariance,
            residual=fit.residual, band=fit.band, fs=fit.fs, fixed=fit.fixed, info=fit.info))


def _fail(path: Path | None, what: str) -> CalibrationFileError:
    return CalibrationFileError(f"{path}: {what}" if path is not None else what)


def _check_against_layout(rec: CalibrationFileRecord | dict[str, Any], layout: ArrayLayout,
                          path: Path | None) -> None:
    if isinstance(rec, CalibrationFileRecord):
        rec = {name: getattr(rec, name) for name in ("point_labels", "points_xy", "actuator_names", "actuators_xy")}
    labels = list(rec["point_labels"])
    if labels != list(layout.point_labels):
        absent = [lab for lab in layout.point_labels if lab not in labels]
        extra = [lab for lab in labels if lab not in layout.point_labels]
        detail = []
        if absent:
            detail.append(f"point(s) {', '.join(absent)} of the layout are missing from the data")
        if extra:
            detail.append(f"point(s) {', '.join(extra)} are not in the layout")
        raise _fail(path, "points do not match the layout: " + ("; ".join(detail) or
                    f"order {labels} differs from {list(layout.point_labels)}"))
    if not np.allclose(rec["points_xy"], layout.points_xy, atol=1e-9):
        raise _fail(path, "point positions (point_x, point_y) differ from the layout's")
    names = list(rec["actuator_names"])
    if names != list(layout.actuator_names):
        raise _fail(path, f"actuators {names} do not match the layout's {list(layout.actuator_names)}")
    if not np.allclose(rec["actuators_xy"], layout.actuators_xy, atol=1e-9):
        raise _fail(path, "actuator positions (actuator_x, actuator_y) differ from the layout's")


def calibration_from_record(rec: CalibrationFileRecord | dict[str, Any],
                            path: str | os.PathLike | None = None) -> Calibration:
    """Build a :class:`Calibration` from a record read by :func:`~vibrofocus.io.calibration_nc.read_calibration_file`.

    Parameters
    ----------
    rec : CalibrationFileRecord or dict
        The record (a dict keyed as :data:`~vibrofocus.io.calibration_nc.RECORD_KEYS` is
        made into one first).
    path : path-like, optional
        The file it came from, named in errors.

    Raises
    ------
    CalibrationFileError
        The descriptions do not make a layout, sweep or quality report; points or
        actuators differ from the layout; the fit's parameters are not the model's.
    """
    path = None if path is None else Path(path)
    try:
        rec = CalibrationFileRecord.from_mapping(rec)
    except ValidationError as exc:
        raise _fail(path, str(exc)) from None
    q = rec.quality
    try:
        layout = ArrayLayout.from_dict(rec.layout)
        sweep = SweepSettings.from_dict(rec.sweep)
        issues = [QualityIssue.from_dict(d) for d in q.issues]
        thresholds = QualityThresholds(**q.thresholds)
    except (ValueError, TypeError, KeyError, AttributeError) as exc:
        raise _fail(path, f"has an unreadable description attribute ({exc})") from exc
    _check_against_layout(rec, layout, path)
    quality = QualityReport(issues=issues, thresholds=thresholds,
                            **{name: getattr(q, name) for name in _QUALITY_ARRAYS})
    return Calibration(
        H=rec.H, freqs=rec.freqs, fs=rec.fs, coherence=rec.coherence, layout=layout, band=rec.band,
        participant_id=rec.participant_id, method=rec.method, quality=quality, drives=rec.drives,
        recordings=rec.recordings, rig=rec.rig, sweep=sweep, created=rec.created,
        software_version=rec.software_version, schema_version=rec.schema_version, straps=rec.straps,
        codes=rec.codes, multiple_coherence=rec.multiple_coherence, recorded_s=rec.recorded_s,
        fit=_fitted_skin(rec.fit, layout, path),
        measured=None if rec.measured is None or rec.measured.all() else rec.measured,
    )


def _fitted_skin(stored: FitRecord | None, layout: ArrayLayout, path: Path | None) -> FittedSkin | None:
    """The skin model of a stored fit, checked against the model's parameters (None for None)."""
    if stored is None:
        return None
    law = dict(stored.fixed).get("law", "homogeneous") if isinstance(stored.fixed, dict) else None
    if law not in FIT_LAWS:
        raise _fail(path, f"has a skin-model fit of an unknown law {law!r} (known: {', '.join(FIT_LAWS)})")
    expected = list(parameter_names(layout.actuator_names, law))
    if list(stored.names) != expected:
        raise _fail(path, f"fit parameters {list(stored.names)} differ from the model's {expected}")
    try:
        return FittedSkin(layout=layout, fs=float(stored.fs), band=tuple(stored.band), values=stored.values,
                          log_covariance=stored.log_covariance, residual=stored.residual, fixed=stored.fixed,
                          info=stored.info)
    except (ValueError, TypeError, KeyError, ValidationError) as exc:
        raise _fail(path, f"has an unreadable skin-model fit ({exc})") from exc


def save_calibration(cal: Calibration, path: str | os.PathLike, *, force: bool = False,
                     keep_previous: bool = True) -> Path:
    """Write a calibration to one netCDF4/HDF5 file, atomically, never losing one already there.

    Its record (:func:`calibration_record`) goes to
    :func:`vibrofocus.io.calibration_nc.write_calibration_file`; on an ``OutputError``
    (full disk, read-only folder, ...) a previous file at ``path`` is unchanged and
    ``cal`` is untouched, so the caller can save it elsewhere. What may be replaced
    (:mod:`vibrofocus.calibration.replacing`): a file of another kind (a study database)
    or another participant's calibration only with ``force``; a calibration replaced is
    kept as ``<stem>.1.nc`` (the next free number).

    Parameters
    ----------
    cal : Calibration
    path : str or PathLike
        Destination ``*.nc``; its folder must exist. Returned as a Path.
    force : bool
        Replace a file of another kind or another participant's calibration.
    keep_previous : bool
        Keep a calibration replaced under the next free numbered name (default).

    Raises
    ------
    OutputError
        The file cannot be written, or is one the rules above keep.
    """
    return save_calibration_keeping(cal, path, force=force, keep_previous=keep_previous)[0]


def save_calibration_keeping(cal: Calibration, path: str | os.PathLike, *, force: bool = False,
                             keep_previous: bool = True) -> tuple[Path, Path | None]:
    """:func:`save_calibration`, also returning where the previous calibration was kept (or None)."""
    from .replacing import check_calibration_target
    from .replacing import keep_previous as keep

    check_calibration_target(path, cal.participant_id, force=force)
    kept = keep(path) if keep_previous else None
    try:
        return write_calibration_file(calibration_record(cal), path), kept
    except BaseException:
        if kept is not None:  # the previous file is still at ``path``: drop its second name
            with contextlib.suppress(OSError):
                os.unlink(kept)
        raise


def load_calibration(path: str | os.PathLike) -> Calibration:
    """Read and validate a calibration file.

    Parameters
    ----------
    path : str or PathLike

    Returns
    -------
    Calibration

    Raises
    ------
    CalibrationFileError
        Everything :func:`vibrofocus.io.calibration_nc.read_calibration_file` refuses, and
        points, actuators or fit parameters that do not match the layout. The message names
        the file.
    """
    return calibration_from_record(read_calibration_file(path), path)


def export_sofa(cal: Calibration, path: str | os.PathLike, *, force: bool = False, band_only: bool = False,
                author_contact: str = "", organization: str = "", license: str | None = None) -> Path:
    """Write a calibration's transfer matrix to a SOFA ``GeneralTF-E`` file (:mod:`vibrofocus.io.sofa`).

    Receivers are the skin points, emitters the actuators, with their positions (m);
    ``H`` in m/V (``Units`` ``metre/volt``) on the calibration's frequency grid (Hz);
    ``GLOBAL_DateCreated`` is the calibration's date. pyfar and any SOFA reader open it;
    the measurement's recordings and quality stay in the calibration file.

    Parameters
    ----------
    cal : Calibration
    path : path-like
        Destination, conventionally ``*.sofa``; its folder must exist.
    force : bool
        Replace a file of another kind (a study database, a CSV) or a calibration; an
        earlier SOFA file is replaced without it.
    band_only : bool
        Export only the frequencies inside the calibrated band (``cal.band``, where
        ``H`` is valid), with the calibration's coherence of each transfer function
        beside ``H`` (the custom variable ``Coherence``, same dimensions as ``Data``).
        Without it the whole grid, 0 Hz to fs/2, and no coherence.
    author_contact : str
        ``GLOBAL_AuthorContact``: who to ask about the data.
    organization : str
        ``GLOBAL_Organization``.
    license : str, optional
        ``GLOBAL_License`` (sofar's default, "No license provided, ask the author for
        permission", without it).

    Returns
    -------
    Path

    Raises
    ------
    ValidationError
        A text with a control character, or a band without two frequencies of the grid.
    OutputError
        The file cannot be written, or holds another kind of file or a calibration.
    """
    from .._validation import shorten
    from .replacing import check_calibration_target

    check_calibration_target(path, None, force=force, what="SOFA file")
    rec = calibration_record(cal)
    out = {key: getattr(rec, key) for key in ("H", "freqs", "points_xy", "actuators_xy", "point_labels", "point_kinds",
                                     "actuator_names", "fs", "band", "participant_id", "layout", "created")}
    if band_only:
        low, high = cal.band
        inside = (cal.freqs >= low) & (cal.freqs <= high)
        if inside.sum() < 2:
            raise ValidationError(f"the calibrated band {shorten(tuple(cal.band))} Hz holds fewer than two "
                                  "frequencies of the grid")
        out.update(H=cal.H[inside], freqs=cal.freqs[inside], coherence=np.asarray(cal.coherence)[inside])
    return write_sofa_tf(out, path, title=f"vibrofocus calibration of {cal.participant_id}",
                         author_contact=author_contact, organization=organization, license=license)


def import_sofa(path: str | os.PathLike) -> dict[str, Any]:
    """Read a transfer matrix from a SOFA ``GeneralTF-E`` file (:func:`export_sofa`).

    Parameters
    ----------
    path : path-like

    Returns
    -------
    dict
        ``H`` complex (n_freqs, n_points, n_actuators), m/V; ``freqs`` (n_freqs,), Hz;
        ``fs`` and ``band`` (Hz); ``participant_id``; ``layout``: the
        :class:`~vibrofocus.layout.ArrayLayout`, checked against the stored positions
        and names (None for a file of another tool, which stores no layout);
        ``coherence`` (n_freqs, n_points, n_actuators), or None where the file has none
        (exported without ``band_only``).

    Raises
    ------
    CalibrationFileError
        An unreadable file, another convention, or positions that differ from the layout.
    """
    rec = read_sofa_tf(path)
    layout = None
    if rec["layout"] is not None:
        try:
            layout = ArrayLayout.from_dict(rec["layout"])
        except (ValueError, TypeError, KeyError, AttributeError) as exc:
            raise _fail(Path(path), f"has an unreadable layout ({exc})") from exc
        _check_against_layout(rec, layout, Path(path))
    return {"H": rec["H"], "freqs": rec["freqs"], "fs": rec["fs"], "band": rec["band"],
            "participant_id": rec["participant_id"], "layout": layout, "coherence": rec["coherence"]}
