"""The trials file: the CSV contract between the studies and the analysis (docs/file-formats.md, trials file).

One row per answered trial with the columns :data:`TRIALS_COLUMNS`, in that order:
``participant`` (id), ``study`` (1 or 2), ``phase`` (``training`` | ``main``), ``trial``
(1-based within the phase), ``method``, ``target`` (1-9), ``response`` (the chosen
locations, ascending, separated by spaces: ``5``, ``4 5``), ``rt_s`` (seconds).
When some participant is simulated (key ``simulated`` of the rows, as the study
database's rows have), a last column ``simulated`` (``1`` / ``0``) follows: answers of
simulated participants come from a perceptual model, not from people, and the analysis
flags them. A file of real participants only has exactly the columns above.
A study database's export has :data:`SESSION_COLUMNS`, :data:`ONSET_COLUMNS`,
:data:`STIMULUS_COLUMNS`, :data:`PROTOCOL_COLUMNS`, :data:`POINT_COLUMNS`,
:data:`XRUN_COLUMNS` and :data:`BLOCK_COLUMNS` between the contract's columns and
``simulated``; :func:`read_block_cells` is the one reader of a row's block and point cells.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from .._validation import number_text, shorten
from ..errors import StudyError, ValidationError
from ._csv_rows import number_cell, write_rows_csv
from .responses import format_response, parse_response_text

__all__ = ["TRIALS_COLUMNS", "SESSION_COLUMNS", "ONSET_COLUMNS", "STIMULUS_COLUMNS", "PROTOCOL_COLUMNS",
           "POINT_COLUMNS", "BLOCK_COLUMNS", "LEVEL_LIMIT_DB", "POINT_LIMIT_MM", "read_block_cells",
           "XRUN_COLUMNS", "LEGACY_SESSION_COLUMNS", "SIMULATED_COLUMN", "MODEL_COLUMN",
           "write_trials_csv",
           "read_trials_csv", "read_trials_table"]

#: Columns of the trials file, in order.
TRIALS_COLUMNS = ("participant", "study", "phase", "trial", "method", "target", "response", "rt_s")
#: Columns a study database's export adds after :data:`TRIALS_COLUMNS`: the session id,
#: its status (``planned``, ``running``, ``paused``, ``aborted``, ``completed``),
#: ``dry_run`` (1 when the session had no calibration, so nothing was played; else 0) and
#: ``rig`` (the rig the session ran on: ``simulated``, ``audio``, ``nidaq``; empty where the
#: session did not store it). A person's rows on the ``simulated`` rig are a rehearsal:
#: nothing was felt.
SESSION_COLUMNS = ("session", "session_status", "dry_run", "rig")
#: The session columns of an export written before sessions named their rig (still read).
LEGACY_SESSION_COLUMNS = SESSION_COLUMNS[:3]
#: Columns of the stimulus onset a study database's export adds after :data:`SESSION_COLUMNS`:
#: ``onset_host_s`` (host ``time.monotonic()``, s, what reaction times count from),
#: ``onset_device_s`` (the first sample on the rig's device clock, s) and ``onset_clock``
#: (that clock: ``simulated_samples``, ``portaudio_dac``, ``nidaq_start_trigger``,
#: ``nidaq_samples``). A cell is empty where no time was stored (a dry run; a rig without a
#: device clock; an answer stored by an older vibrofocus).
ONSET_COLUMNS = ("onset_host_s", "onset_device_s", "onset_clock")
#: Columns of the stimulus played a study database's export adds after :data:`ONSET_COLUMNS`:
#: ``levels`` (the session's level rule: ``paper`` or ``equal-peak``), ``drive_peak_v``
#: (the largest |drive| over the actuators, V) and ``target_peak_um`` (the peak displacement
#: at the target predicted from the calibration, µm). A peak cell is empty where none was
#: stored (a dry run; an answer stored by an older vibrofocus).
STIMULUS_COLUMNS = ("levels", "drive_peak_v", "target_peak_um")
#: Column a study database's export adds after :data:`STIMULUS_COLUMNS`: ``protocol``, the
#: name of the study protocol the session was planned from (``paper-study1``,
#: ``paper-study2`` or a protocol file's ``name``; docs/protocols.md).
PROTOCOL_COLUMNS = ("protocol",)
#: Columns a study database's export adds after :data:`PROTOCOL_COLUMNS`: a point answer's
#: place in the layout frame, mm (``response`` is then its nearest location); empty cells
#: for a location answer (docs/protocols.md, point responses).
POINT_COLUMNS = ("response_x_mm", "response_y_mm")
#: Column a study database's export adds after :data:`POINT_COLUMNS`: ``xrun_represented``,
#: how many times the trial was presented again because its stimulus lost samples (an
#: xrun; docs/protocols.md); 0 for nearly every trial.
XRUN_COLUMNS = ("xrun_represented",)
#: Columns a study database's export adds after :data:`XRUN_COLUMNS`: the trial's block as
#: the fit of hypotheses reads it (docs/fitting-hypotheses.md): ``level_db``, the block's
#: level in dB re the level rule (``levels``; a block in dB SL is already the participant's
#: threshold plus its level), and ``allowed``, the location numbers the block could be
#: answered with, ascending, separated by spaces (``1 3 7 9``; all of them for the paper's
#: studies). Last in the chain so that every older export's header is still one the reader
#: takes.
BLOCK_COLUMNS = ("level_db", "allowed")
#: Largest magnitude of a ``level_db`` cell, dB (the protocol files' bound on a level).
LEVEL_LIMIT_DB = 120.0
#: Largest magnitude of a point answer's coordinate, mm: a point a metre off the array is
#: on no arm (the picture a participant points on spans a few centimetres).
POINT_LIMIT_MM = 1000.0
#: Last column when some participant is simulated: 1 where the participant is simulated
#: (answers from the perceptual model, not data), else 0.
SIMULATED_COLUMN = "simulated"
#: Column after :data:`SIMULATED_COLUMN` when rows name the model that answered for the
#: simulated participants (key ``model``: ``simulated participants: model v3.0, hypothesis
#: grid-peak v3.3 fitted at paper levels, not data``; empty for a real participant).
MODEL_COLUMN = "model"


def write_trials_csv(rows: Iterable[Mapping[str, Any]], path: str | os.PathLike, *, sessions: bool = False,
                     onsets: bool = False, stimuli: bool = False, protocols: bool = False,
                     points: bool = False, xruns: bool = False, blocks: bool = False) -> int:
    """Write trial rows to ``path`` atomically (:func:`vibrofocus._atomic.atomic_write`).

    A reader never sees half a file; after a failure (a full disk, a read-only folder,
    Ctrl-C) a previous file at ``path`` is unchanged and
    :class:`~vibrofocus.errors.OutputError` says why.

    Parameters
    ----------
    rows : iterable of mapping
        Each with at least the keys of :data:`TRIALS_COLUMNS`. When some row has a true
        ``simulated`` (a simulated participant), the column :data:`SIMULATED_COLUMN` is
        written too (1 / 0 per row), and :data:`MODEL_COLUMN` after it when some row has a
        ``model`` (the label of the model that answered); without one the file has exactly
        the contract's columns. Other keys are ignored.
        ``response`` may be a string or a sequence of location numbers; ``rt_s`` in s.
    path : path-like
        Destination CSV file; its folder must exist.
    sessions : bool
        Also write :data:`SESSION_COLUMNS` (then each row needs those keys too; a missing
        ``rig`` or None is an empty cell).
    onsets : bool
        Also write :data:`ONSET_COLUMNS` (keys of the rows; a missing key or None is an
        empty cell).
    stimuli : bool
        Also write :data:`STIMULUS_COLUMNS` (after the onset columns; a missing key or None
        is an empty cell).
    protocols : bool
        Also write :data:`PROTOCOL_COLUMNS` (after the stimulus columns; a missing key or
        None is an empty cell).
    points : bool
        Also write :data:`POINT_COLUMNS` (after the protocol column; a missing key or None
        is an empty cell).
    xruns : bool
        Also write :data:`XRUN_COLUMNS` (after the point columns; a missing key or None is 0).
    blocks : bool
        Also write :data:`BLOCK_COLUMNS` (after the xrun column; ``allowed`` a string or a
        sequence of location numbers; a missing key or None is an empty cell).

    Returns
    -------
    int
        Number of rows written.
    """
    from .._atomic import TRIALS_CSV

    rows = list(rows)
    with_flag = any(row.get(SIMULATED_COLUMN) for row in rows)
    with_model = with_flag and any(row.get(MODEL_COLUMN) for row in rows)
    header = (TRIALS_COLUMNS + (SESSION_COLUMNS if sessions else ()) + (ONSET_COLUMNS if onsets else ())
              + (STIMULUS_COLUMNS if stimuli else ()) + (PROTOCOL_COLUMNS if protocols else ())
              + (POINT_COLUMNS if points else ()) + (XRUN_COLUMNS if xruns else ())
              + (BLOCK_COLUMNS if blocks else ())
              + ((SIMULATED_COLUMN,) if with_flag else ())
              + ((MODEL_COLUMN,) if with_model else ()))

    def cells(row: Mapping[str, Any]) -> list[Any]:
        response = row["response"]
        if not isinstance(response, str):
            response = format_response(response)
        values = [
            row["participant"], int(row["study"]), row["phase"], int(row["trial"]),
            row["method"], int(row["target"]), response, _seconds_cell(row["rt_s"]),
        ]
        if sessions:
            values += [int(row["session"]), row["session_status"], int(bool(row["dry_run"])),
                       row.get("rig") or ""]
        if onsets:
            values += [_seconds_cell(row.get("onset_host_s")), _seconds_cell(row.get("onset_device_s")),
                       row.get("onset_clock") or ""]
        if stimuli:
            values += [row.get("levels") or "", _seconds_cell(row.get("drive_peak_v")),
                       _seconds_cell(row.get("target_peak_um"))]
        if protocols:
            values.append(row.get("protocol") or "")
        if points:
            values += [_seconds_cell(row.get("response_x_mm")), _seconds_cell(row.get("response_y_mm"))]
        if xruns:
            values.append(int(row.get("xrun_represented") or 0))
        if blocks:
            allowed = row.get("allowed")
            values += [_seconds_cell(row.get("level_db")),
                       "" if allowed is None else allowed if isinstance(allowed, str) else format_response(allowed)]
        if with_flag:
            values.append(int(bool(row.get(SIMULATED_COLUMN))))
        if with_model:
            values.append(row.get(MODEL_COLUMN) or "")
        return values

    return write_rows_csv(path, header, (cells(row) for row in rows), what="trials file", kind=TRIALS_CSV)


def _seconds_cell(value: Any) -> Any:
    # Stored numbers may come back from SQLite as int; the file always spells them as floats.
    return number_cell(None if value is None else float(value))


def read_trials_csv(path: str | os.PathLike) -> list[dict[str, Any]]:
    """Read a trials file back, checking the header; values typed as written.

    Parameters
    ----------
    path : path-like
        A trials CSV (docs/file-formats.md, trials file).

    Returns
    -------
    list of dict
        ``study``, ``trial``, ``target`` as int, ``rt_s`` as float, ``response`` as a
        tuple of int; the rest as str. A file with :data:`SESSION_COLUMNS` also gives
        ``session`` (int), ``session_status`` (str), ``dry_run`` (bool) and ``rig`` (str;
        ``""`` where not stored, and for an export written before sessions named their rig); one with
        :data:`SIMULATED_COLUMN` gives ``simulated`` (bool); the onset and stimulus
        columns' numbers, and the point columns', are floats (None for an empty cell);
        ``xrun_represented`` is an int; ``level_db`` a float and ``allowed`` a tuple of
        int (None for an empty cell). A block or point cell that is not a finite number
        within its bound (:func:`read_block_cells`) is refused.
    """
    from .._atomic import protect

    path = Path(path)
    protect(path, "trials file")
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            reader = csv.reader(fh)
            header = next(reader, None)
            later = (ONSET_COLUMNS, STIMULUS_COLUMNS, PROTOCOL_COLUMNS, POINT_COLUMNS, XRUN_COLUMNS, BLOCK_COLUMNS)
            middles = [()] + [s + sum(later[:k], ()) for s in (SESSION_COLUMNS, LEGACY_SESSION_COLUMNS)
                              for k in range(len(later) + 1)]
            headers = [TRIALS_COLUMNS + m + f for m in middles
                       for f in ((), (SIMULATED_COLUMN,), (SIMULATED_COLUMN, MODEL_COLUMN))]
            if header is None or tuple(header) not in headers:
                raise StudyError(f"{path} is not a trials file: header {header!r}, expected {list(TRIALS_COLUMNS)}")
            columns = tuple(header)
            out = []
            for line_no, rec in enumerate(reader, start=2):
                if len(rec) != len(columns):
                    raise StudyError(f"{path}:{line_no}: expected {len(columns)} fields, got {len(rec)}")
                row = dict(zip(columns, rec))
                if not row["participant"] or not row["participant"].isprintable():
                    # A tab or newline would become a quoted cell downstream (TSV, BIDS).
                    raise StudyError(f"{path}:{line_no}: participant id {shorten(row['participant'])} is empty or "
                                     "holds a control character (tab, newline, ...)")
                if SIMULATED_COLUMN in row:
                    row[SIMULATED_COLUMN] = row[SIMULATED_COLUMN].strip() in ("1", "true", "True")
                try:
                    if "session" in row:
                        row["session"] = int(row["session"])
                        row["dry_run"] = bool(int(row["dry_run"]))
                        row.setdefault("rig", "")
                    if "onset_clock" in row:
                        for key in ("onset_host_s", "onset_device_s"):
                            row[key] = float(row[key]) if row[key] else None
                        row["onset_clock"] = row["onset_clock"] or None
                    if "levels" in row:
                        for key in ("drive_peak_v", "target_peak_um"):
                            row[key] = float(row[key]) if row[key] else None
                    if "response_x_mm" in row or "level_db" in row:
                        level, allowed, point = read_block_cells(row.get("level_db", ""), row.get("allowed", ""),
                                                                 row.get("response_x_mm", ""),
                                                                 row.get("response_y_mm", ""))
                        if "response_x_mm" in row:
                            row["response_x_mm"], row["response_y_mm"] = point if point is not None else (None, None)
                        if "level_db" in row:
                            row["level_db"], row["allowed"] = level, allowed
                    if "xrun_represented" in row:
                        row["xrun_represented"] = int(row["xrun_represented"])
                    row["study"] = int(row["study"])
                    row["trial"] = int(row["trial"])
                    row["target"] = int(row["target"])
                    row["rt_s"] = float(row["rt_s"])
                    row["response"] = parse_response_text(row["response"])
                except ValueError as exc:  # ValidationError is a ValueError
                    raise StudyError(f"{path}:{line_no}: {exc}") from None
                out.append(row)
            return out
    except OSError as exc:
        raise StudyError(f"cannot read the trials file {path}: {exc.strerror or exc}") from exc


def read_block_cells(level_db: str, allowed: str, x_mm: str, y_mm: str, *, n_locations: int | None = None
                     ) -> tuple[float | None, tuple[int, ...] | None, tuple[float, float] | None]:
    """A trial's block cells (:data:`BLOCK_COLUMNS`) and point cells (:data:`POINT_COLUMNS`), read and checked.

    The one reader of these cells, for the trials file, a BIDS events file and the fit of
    hypotheses (:func:`vibrofocus.simulation.fitting.lab_trials`).

    Parameters
    ----------
    level_db, allowed, x_mm, y_mm : str
        The cells as text; an empty cell (or BIDS's ``n/a``) says nothing.
    n_locations : int, optional
        When given, every allowed location must be in ``1..n_locations``.

    Returns
    -------
    level_db : float or None
        The level, dB re the level rule.
    allowed : tuple of int or None
        The allowed locations, ascending.
    point : (float, float) or None
        The point answer in the layout frame, mm.

    Raises
    ------
    ValidationError
        A level that is not a finite number within :data:`LEVEL_LIMIT_DB`; allowed
        locations that are not distinct location numbers; a point that is not two finite
        numbers within :data:`POINT_LIMIT_MM` (or has one coordinate only). The message
        names the column and quotes the cell.
    """
    cells = ["" if str(c).strip() in ("", "n/a") else str(c).strip()
             for c in (level_db, allowed, x_mm, y_mm)]
    level = None
    if cells[0]:
        level = number_text(cells[0])
        if level is None or abs(level) > LEVEL_LIMIT_DB:
            raise ValidationError(f"level_db must be a finite number of dB within +-{LEVEL_LIMIT_DB:g} (re the level "
                                  f"rule), got {shorten(cells[0])}")
    places = parse_response_text(cells[1], n_locations=n_locations, name="allowed") if cells[1] else None
    point = None
    if cells[2] or cells[3]:
        x, y = number_text(cells[2]), number_text(cells[3])
        if x is None or y is None or max(abs(x), abs(y)) > POINT_LIMIT_MM:
            raise ValidationError(f"response_x_mm and response_y_mm must both be finite numbers of mm within "
                                  f"+-{POINT_LIMIT_MM:g} (a point answer), got {shorten(cells[2])} and "
                                  f"{shorten(cells[3])}")
        point = (x, y)
    return level, places, point


def read_trials_table(path: str | os.PathLike):
    """Read a trials file as text, for checking row by row (:func:`vibrofocus.analysis.load_trials`).

    Unlike :func:`read_trials_csv`, nothing is typed or refused here but an unreadable
    file: every value stays the text of the file, so each bad row can be reported with
    its line.

    Parameters
    ----------
    path : path-like
        A trials CSV (docs/file-formats.md, trials file); a UTF-8 byte-order mark and
        spaces after the commas are allowed.

    Returns
    -------
    DataFrame
        One column per header field (names stripped of spaces), every value a str,
        plus ``line``: the line number in the file (the header is line 1).

    Raises
    ------
    ValidationError
        The file does not exist, is empty, or is not a readable CSV file.
    """
    import numpy as np
    import pandas as pd

    from .._atomic import protect

    name = os.fspath(path)
    protect(name, "trials file")
    if not os.path.isfile(name):
        raise ValidationError(f"trials file {name!r} does not exist or is not a file")
    try:
        raw = pd.read_csv(name, dtype=str, keep_default_na=False, skipinitialspace=True, encoding="utf-8-sig")
    except pd.errors.EmptyDataError:
        raise ValidationError(f"trials file {name!r} is empty: expected a header line and one row per trial") from None
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise ValidationError(f"trials file {name!r} is not a readable CSV file: {exc}") from None
    raw.columns = [str(c).strip() for c in raw.columns]
    raw["line"] = np.arange(2, len(raw) + 2)
    return raw
