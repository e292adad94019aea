"""BIDS behavioural datasets: the localization studies as ``beh`` events files.

Layout written by :func:`write_bids_dataset` (BIDS 1.10, the ``beh`` datatype)::

    DIR/dataset_description.json       Name, BIDSVersion, DatasetType, GeneratedBy (vibrofocus, version)
    DIR/README                         what the dataset is; that simulated participants are a model
    DIR/participants.tsv, .json        participant_id (sub-<label>), source_id, simulated
    DIR/sub-<label>/ses-<session>/beh/sub-<label>_ses-<session>_task-localization<1|2>_events.tsv
    DIR/sub-<label>/ses-<session>/beh/sub-<label>_ses-<session>_task-localization<1|2>_events.json
    DIR/sub-<label>/ses-<session>/beh/sub-<label>_ses-<session>_task-threshold_events.tsv, .json

(``ses-<session>`` is the study session's id; a source without sessions, such as a
trials CSV without a ``session`` column, writes ``sub-<label>/beh/...`` without it.)

The events file has one row per answered trial with the columns :data:`EVENT_COLUMNS`
(a threshold block's, ``task-threshold``: :data:`THRESHOLD_EVENT_COLUMNS`);
its JSON sidecar describes every column (units, levels) and records where the trials
came from (rig, calibration hash, skin preset, simulated or not). This module writes and
reads plain records (dicts and lists); the study side builds them
(:mod:`vibrofocus.studies.bids`). :func:`read_bids_trials_table` turns a dataset back into
the trials table the analysis reads.
"""

from __future__ import annotations

import csv
import errno as _errno
import io as _io
import json
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from .._validation import shorten
from ..errors import OutputError, ValidationError
from ._capped import read_capped_json
from .jsonsafe import json_safe

__all__ = ["BIDS_VERSION", "EVENT_COLUMNS", "EVENT_COLUMN_DESCRIPTIONS", "TASKS", "TASK_INFO", "METADATA_KEYS",
           "bids_label", "events_name", "check_bids_metadata", "read_bids_metadata", "read_bids_metadata_file", "levels_from_data",
           "write_bids_dataset", "read_bids_trials_table", "THRESHOLD_TASK", "THRESHOLD_EVENT_COLUMNS",
           "THRESHOLD_TASK_INFO", "THRESHOLD_COLUMN_DESCRIPTIONS"]

#: The BIDS version the dataset follows.
BIDS_VERSION = "1.10.0"
#: Task label per study.
TASKS = {1: "localization1", 2: "localization2"}
#: Columns of every events file, in order: BIDS's ``onset`` and ``duration`` first, then
#: the trial (``trial_type``, ``method``, ``target``, ``response``, ``response_time``,
#: ``phase``), then where it sits in the study (``trial``, ``session_status``, ``dry_run``;
#: the session itself is the file's ``ses-`` entity, so no column is named like one), then
#: the stimulus onset on the rig's own clock (``device_onset``, ``device_clock``), then the
#: stimulus played (``levels``, ``drive_peak_v``, ``target_peak_um``), then the protocol's
#: block (``protocol``, ``block``, ``level_db``, ``allowed``), the point answer
#: (``response_x_mm``, ``response_y_mm``) and ``xrun_represented``; a dataset written
#: before those existed (with a ``session_id`` column and no ``ses-``) is read too.
EVENT_COLUMNS = ("onset", "duration", "trial_type", "method", "target", "response", "response_time", "phase",
                 "trial", "session_status", "dry_run", "device_onset", "device_clock",
                 "levels", "drive_peak_v", "target_peak_um", "protocol", "block", "level_db", "allowed",
                 "response_x_mm", "response_y_mm", "xrun_represented")
#: The columns :func:`read_bids_trials_table` needs (every events file has had them).
_REQUIRED_COLUMNS = EVENT_COLUMNS[:11]
#: What each task asks (the events sidecar's ``TaskDescription`` and ``Instructions``, as
#: the participant page words them).
TASK_INFO = {
    1: {"TaskDescription": "Localization of single focused vibrotactile taps: each trial plays one tap, rendered by "
                           "one method at one of the locations of a 3 x 3 grid on the forearm, and the participant "
                           "names the one location where it felt most intense.",
        "Instructions": "The page goes full screen and plays a short beep before each stimulus. Answer with the keys "
                        "1-9 or by tapping or clicking a location: where did you feel it most? The first trials are "
                        "training; the page says when the main trials begin."},
    2: {"TaskDescription": "Localization with several answers: each trial plays one focused vibrotactile tap, and the "
                           "participant chooses every location of the 3 x 3 grid on the forearm where it was felt.",
        "Instructions": "The page goes full screen and plays a short beep before each stimulus. After each stimulus, "
                        "choose every location where you felt it (one or several): tap or click them, or press the "
                        "keys 1-9, then press Confirm (or Enter). The first trials are training; the page says when "
                        "the main trials begin."},
}
#: Metadata a lab gives (``export_bids(metadata=...)``, ``--author``, ``--license``,
#: ``--institution``, ``--metadata FILE``): key -> (file it goes to, ``list`` or ``str``).
#: ``dataset_description.json`` keys are the dataset's; the ``Institution*`` keys go into
#: every events sidecar (BIDS's place for them).
METADATA_KEYS: dict[str, tuple[str, type]] = {
    "Name": ("dataset_description.json", str), "Authors": ("dataset_description.json", list),
    "License": ("dataset_description.json", str), "Acknowledgements": ("dataset_description.json", str),
    "HowToAcknowledge": ("dataset_description.json", str), "Funding": ("dataset_description.json", list),
    "EthicsApprovals": ("dataset_description.json", list), "ReferencesAndLinks": ("dataset_description.json", list),
    "DatasetDOI": ("dataset_description.json", str), "Keywords": ("dataset_description.json", list),
    "InstitutionName": ("events", str), "InstitutionAddress": ("events", str),
    "InstitutionalDepartmentName": ("events", str),
}
#: The sidecar's description of each column of :data:`EVENT_COLUMNS` (BIDS "column
#: description": LongName, Description, Units, Levels).
EVENT_COLUMN_DESCRIPTIONS: dict[str, dict[str, Any]] = {
    "onset": {"LongName": "stimulus onset",
              "Description": "Time of the stimulus onset from the first stimulus onset of this file's session, on "
                             "the host's monotonic clock (onset_host_s: when the drive was handed to the rig, what "
                             "response times count from). n/a when the source stores no onset.",
              "Units": "s"},
    "duration": {"LongName": "stimulus duration",
                 "Description": "n/a: the trials record no drive length; the tap itself lasts a few ms.",
                 "Units": "s"},
    "trial_type": {"LongName": "condition",
                   "Description": "The condition: method and target location, '<method>_loc<target>'."},
    "method": {"LongName": "rendering method",
               "Description": "How the drive was designed.",
               "Levels": {"funneling": "amplitude panning between actuators",
                          "inverse": "spatio-temporal inverse filter from the calibration",
                          "combination": "inverse filter reproducing funneling's field at the target",
                          "time_reversal": "time-reversed transfer functions",
                          "contrast": "acoustic contrast control",
                          "constrained": "energy-contrast design with a fidelity constraint",
                          "minimax": "peak-contrast (minimax) design with a fidelity constraint"}},
    "target": {"LongName": "target location",
               "Description": "The location (1-9 on the reference layout) the stimulus was focused at."},
    "response": {"LongName": "chosen locations",
                 "Description": "Locations the participant chose, ascending, separated by spaces "
                                "(Study 1: one; Study 2: one or more)."},
    "response_time": {"LongName": "response time",
                      "Description": "From the stimulus onset to the answer.", "Units": "s"},
    "phase": {"LongName": "phase", "Description": "Part of the study.",
              "Levels": {"training": "practice trials, not analysed", "main": "the trials analysed"}},
    "trial": {"LongName": "trial number", "Description": "1-based trial number within the phase."},
    "session_status": {"LongName": "session status",
                       "Description": "The session's status when exported.",
                       "Levels": {"planned": "not started", "running": "in progress", "paused": "paused",
                                  "aborted": "ended early (left out of the analysis by default)",
                                  "completed": "all trials answered"}},
    "dry_run": {"LongName": "dry run",
                "Description": "Whether the session ran without a calibration (nothing was played).",
                "Levels": {"0": "stimuli were played", "1": "dry run: nothing was played"}},
    "device_onset": {"LongName": "stimulus onset on the device clock",
                     "Description": "The drive's first sample on the rig's own clock (device_clock says which), as "
                                    "the rig reported it; n/a for a dry run, a rig without a device clock, or a "
                                    "source that stored none.",
                     "Units": "s"},
    "device_clock": {"LongName": "device clock",
                     "Description": "The clock device_onset is on."},
    "levels": {"LongName": "level rule",
               "Description": "How the stimuli's levels were set (the session's protocol).",
               "Levels": {"paper": "each method at the source paper's level: funneling by eq. 3 with A at the drive "
                                   "limit, the inverse filter asking 2 um at the target, the combination funneling's "
                                   "displacement there, each scaled down only over the drive limit",
                          "equal-peak": "every method scaled to the drive limit"}},
    "drive_peak_v": {"LongName": "peak drive",
                     "Description": "Largest absolute drive over the actuators of the stimulus played; n/a where "
                                    "none was stored (a dry run, an older database, a trials CSV without it).",
                     "Units": "V"},
    "target_peak_um": {"LongName": "predicted peak at the target",
                       "Description": "Peak displacement at the target predicted from the participant's calibration; "
                                      "n/a where none was stored.",
                       "Units": "um"},
}
EVENT_COLUMN_DESCRIPTIONS.update({
    "protocol": {"LongName": "study protocol",
                 "Description": "The name of the study protocol the session was planned from (docs/protocols.md); "
                                "paper-study1 or paper-study2 for the source paper's studies."},
    "block": {"LongName": "protocol block", "Description": "0-based index of the protocol's block the session ran."},
    "level_db": {"LongName": "stimulus level",
                 "Description": "The stimulus level re the level rule (levels): 0 is the rule's own level; a block "
                                "in dB SL is at the participant's threshold (the sidecar's Sessions: ThresholdDb) "
                                "plus its level (LevelSlDb).", "Units": "dB"},
    "allowed": {"LongName": "allowed answers",
                "Description": "The locations the trial could be answered with (the protocol block's locations), "
                               "ascending, separated by spaces; every location for the source paper's studies. n/a "
                               "where the source does not say (a trials CSV written before the column)."},
    "response_x_mm": {"LongName": "answered point, x",
                      "Description": "A point answer's x in the layout frame (n/a for a location answer); its "
                                     "nearest location is the response.", "Units": "mm"},
    "response_y_mm": {"LongName": "answered point, y",
                      "Description": "A point answer's y in the layout frame, toward the wrist (n/a for a location "
                                     "answer).", "Units": "mm"},
    "xrun_represented": {"LongName": "presentations again after lost samples",
                         "Description": "How many times the trial was presented again because the audio stream "
                                        "lost samples (an xrun) during its stimulus; the answer is to the last "
                                        "presentation (docs/protocols.md). n/a where the source does not say."},
})

#: Task label of threshold blocks (docs/protocols.md, "Threshold blocks"): their trials are
#: in events files of their own, ``..._task-threshold_events.tsv``, with the columns
#: :data:`THRESHOLD_EVENT_COLUMNS` (read by no localization analysis).
THRESHOLD_TASK = "threshold"
THRESHOLD_EVENT_COLUMNS = ("onset", "duration", "trial_type", "method", "target", "response", "response_time",
                           "phase", "trial", "session_status", "dry_run", "levels", "level_db", "drive_peak_v",
                           "reversal", "threshold_db", "protocol", "block")
THRESHOLD_TASK_INFO = {
    "TaskDescription": "Detection threshold of a focused vibrotactile tap by a 1-up-2-down staircase (Levitt 1971; "
                       "docs/protocols.md, Threshold blocks): each trial plays the tap at the level the staircase "
                       "sets from the answers so far, and the participant says whether it was felt.",
    "Instructions": "After each beep, say whether you felt a tap: press Felt it (or the key Y or 1) or Did not feel "
                    "it (N or 0). Some taps are too weak to feel; that is expected.",
}
THRESHOLD_COLUMN_DESCRIPTIONS: dict[str, dict[str, Any]] = {
    **{c: EVENT_COLUMN_DESCRIPTIONS[c] for c in THRESHOLD_EVENT_COLUMNS if c in EVENT_COLUMN_DESCRIPTIONS},
    "trial_type": {"LongName": "condition",
                   "Description": "The condition: 'detection_<method>_loc<target>'."},
    "response": {"LongName": "felt", "Description": "Whether the participant felt the tap.",
                 "Levels": {"1": "felt", "0": "not felt"}},
    "level_db": {"LongName": "stimulus level",
                 "Description": "The trial's level set by the staircase, re the level rule (levels); training trials "
                                "play at its start.", "Units": "dB"},
    "reversal": {"LongName": "reversal",
                 "Description": "Whether the staircase reversed its direction after this answer.",
                 "Levels": {"1": "a reversal", "0": "no reversal"}},
    "threshold_db": {"LongName": "threshold",
                     "Description": "The session's threshold: the mean of its reversal levels after the first two, "
                                    "re the level rule; n/a before the block ended or with fewer than 6 reversals.",
                     "Units": "dB"},
}
_LABEL = re.compile(r"[^A-Za-z0-9]")
_NA = "n/a"


def bids_label(participant_id: str) -> str:
    """The BIDS label of a participant id: its ASCII letters and digits (``P-01`` -> ``P01``).

    BIDS labels are alphanumeric ASCII only (``[0-9a-zA-Z]+``, BIDS 1.10, "Entities"):
    other characters, letters of other scripts included, are dropped.

    Raises
    ------
    ValidationError
        The id holds a control character (tab, newline, ...), or has no ASCII letter
        or digit (``'李'``): BIDS cannot name such a subject.
    """
    text = str(participant_id)
    if not text.isprintable():
        raise ValidationError(f"participant id {shorten(text)} holds a control character (tab, newline, ...); "
                              "rename the participant")
    label = _LABEL.sub("", text)
    if not label:
        raise ValidationError(f"participant id {shorten(text)} has no ASCII letter or digit: BIDS subject labels "
                              "allow only A-Z, a-z and 0-9, so this participant cannot be a BIDS subject; give "
                              "the participant an id with some of those")
    return label


def events_name(label: str, study: int, session: int | str | None = None, *, task: str | None = None) -> str:
    """``sub-<label>[_ses-<session>]_task-localization<study>_events`` (without suffix); ``task``:
    another task label (:data:`THRESHOLD_TASK`)."""
    ses = "" if session is None else f"_ses-{session}"
    return f"sub-{label}{ses}_task-{task or TASKS[study]}_events"


def _events_folder(label: str, session: int | str | None) -> str:
    return f"sub-{label}/beh" if session is None else f"sub-{label}/ses-{session}/beh"


def levels_from_data(values: Iterable[Any], described: Mapping[str, str], unknown: str) -> dict[str, str]:
    """A sidecar's ``Levels``: each value the column holds, described.

    Parameters
    ----------
    values : iterable
        The column's cells (None and ``n/a`` are skipped).
    described : mapping
        Known value -> its description.
    unknown : str
        The description of a value ``described`` lacks (a lab's own method, say).

    Returns
    -------
    dict
        Value (as written in the TSV) -> description, in sorted order: every value of
        the data is a level, so the validator accepts each cell.
    """
    present = sorted({_cell(v) for v in values if v is not None and _cell(v) != _NA})
    return {v: described.get(v, unknown) for v in present}


def check_bids_metadata(metadata: Mapping[str, Any] | None, name: str = "metadata") -> dict[str, Any]:
    """The dataset's metadata checked: keys of :data:`METADATA_KEYS`, texts or lists of texts.

    Parameters
    ----------
    metadata : mapping or None
        Key -> text, or list of texts for ``Authors``, ``Funding``, ``EthicsApprovals``,
        ``ReferencesAndLinks`` and ``Keywords``.
    name : str
        What the messages call it (an option, a file).

    Returns
    -------
    dict
        The metadata, texts stripped of surrounding blanks (``{}`` for None).

    Raises
    ------
    ValidationError
        Not a mapping, an unknown key, a value of the wrong type, an empty text or list,
        or a control character (which would break the files' lines).
    """
    if metadata is None:
        return {}
    if not isinstance(metadata, Mapping):
        raise ValidationError(f"{name} must be a JSON object of BIDS metadata, got {shorten(metadata)}")
    out: dict[str, Any] = {}
    for key, value in metadata.items():
        if key not in METADATA_KEYS:
            raise ValidationError(f"{name} has the key {shorten(key)}, which vibrofocus does not write; use one of "
                                  f"{', '.join(METADATA_KEYS)}")
        kind = METADATA_KEYS[key][1]
        items = value if kind is list and isinstance(value, list) else [value]
        if kind is list and not isinstance(value, list):
            raise ValidationError(f"{name} {key} must be a list of texts, got {shorten(value)}")
        if not items or not all(isinstance(v, str) and v.strip() and v.isprintable()
                                for v in items):
            raise ValidationError(f"{name} {key} must be {'non-empty texts' if kind is list else 'a non-empty text'} "
                                  f"without control characters, got {shorten(value)}")
        out[key] = [v.strip() for v in items] if kind is list else value.strip()
    return out


#: Keys of a metadata template vibrofocus sets itself (a lab's ``dataset_description.json``
#: given as the template has them): skipped.
_OWN_DESCRIPTION_KEYS = ("BIDSVersion", "DatasetType", "GeneratedBy")
#: Largest metadata template read, bytes.
_MAX_TEMPLATE_BYTES = 1_000_000


def read_bids_metadata_file(path: str | os.PathLike) -> dict[str, Any]:
    """A metadata template: a JSON object of :data:`METADATA_KEYS` (a lab's ``dataset_description.json`` reads too).

    ``BIDSVersion``, ``DatasetType`` and ``GeneratedBy`` are skipped (vibrofocus writes
    them); any other key must be one of :data:`METADATA_KEYS`.

    Parameters
    ----------
    path : path-like
        The JSON file (an input: no output of the command may replace it).

    Returns
    -------
    dict
        As :func:`check_bids_metadata` returns.

    Raises
    ------
    ValidationError
        Missing, unreadable, larger than 1 MB, not a JSON object, or holding an
        unknown key or a value of the wrong type; the message names the file.
    """
    from .._atomic import protect

    path = Path(path)
    protect(path, "BIDS metadata template")
    data = read_capped_json(path, max_bytes=_MAX_TEMPLATE_BYTES, what="BIDS metadata file")
    if not isinstance(data, dict):
        raise ValidationError(f"the BIDS metadata file {path} must hold a JSON object, got {type(data).__name__}")
    return check_bids_metadata({k: v for k, v in data.items() if k not in _OWN_DESCRIPTION_KEYS},
                               f"the BIDS metadata file {path}:")


def read_bids_metadata(root: str | os.PathLike) -> dict[str, Any]:
    """The metadata of :data:`METADATA_KEYS` an existing dataset holds, so a re-export keeps it.

    Read from ``dataset_description.json`` and from the events sidecars vibrofocus wrote
    there (listed in its manifest); what is unreadable or of the wrong type is skipped.
    A missing folder gives ``{}``.

    Parameters
    ----------
    root : path-like
        The dataset folder.

    Returns
    -------
    dict
        Key of :data:`METADATA_KEYS` -> its value.
    """
    from .bids_merge import _read_json, read_manifest

    root = Path(root)
    found: dict[str, Any] = {}
    sources = ["dataset_description.json"]
    manifest, _ = read_manifest(root) if root.is_dir() else ({}, {})
    sources += [rel for rel in sorted(manifest) if rel.endswith("_events.json")]
    for rel in sources:
        # Read below root, no link followed (a manifest may name '../..' or a link outside).
        path = root / rel
        data = _read_json(root, rel) if root.is_dir() else None
        if not isinstance(data, dict):
            continue
        for key, (where, _kind) in METADATA_KEYS.items():
            if key in found or key not in data or (where == "events") == (path.name == "dataset_description.json"):
                continue
            try:
                found.update(check_bids_metadata({key: data[key]}))
            except ValidationError:
                continue
    return found


def _tsv(columns: Sequence[str], rows: Sequence[Mapping[str, Any]]) -> str:
    buf = _io.StringIO()
    writer = csv.writer(buf, delimiter="\t", lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([_NA if row.get(c) is None else _cell(row[c]) for c in columns])
    return buf.getvalue()


def _cell(value: Any) -> str:
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, float):
        return _NA if value != value else repr(value)  # NaN -> n/a; repr keeps every digit
    return str(value)


def _json(value: Any) -> str:
    return json.dumps(json_safe(value), indent=2, sort_keys=False) + "\n"


def write_bids_dataset(
    out_dir: str | os.PathLike,
    *,
    description: Mapping[str, Any],
    readme: str,
    participants: Sequence[Mapping[str, Any]],
    participant_columns: Mapping[str, Mapping[str, Any]],
    runs: Sequence[Mapping[str, Any]],
    source: str | None = None,
    force: bool = False,
) -> dict[str, Any]:
    """Write a BIDS behavioural dataset, or add it to an existing one without touching anything else.

    A new folder is built beside ``out_dir`` and put in place at once
    (:func:`vibrofocus._atomic.atomic_directory`). Into an existing folder (a lab's
    dataset with EEG or MRI, an earlier export, another study's) the files are merged
    by :func:`vibrofocus.io.bids_merge.merge_into_dataset`: only files vibrofocus wrote
    (listed with their SHA-256 in ``.vibrofocus-bids.json``) are replaced;
    ``participants.tsv`` and ``participants.json`` are merged, keeping the lab's columns
    and rows; ``dataset_description.json`` and ``README`` are written only where
    missing or vibrofocus's own; nothing is deleted. A folder given as a symbolic link
    is written through (the link stays), but a link inside it on the path of a file the
    export writes or merges is refused, even with ``force``. One export at a time
    writes into a dataset (a lock on its folder; another is refused at once, saying so).

    Parameters
    ----------
    out_dir : path-like
        The dataset folder; its parent must exist.
    description : mapping
        ``dataset_description.json`` (Name, BIDSVersion, GeneratedBy, ...).
    readme : str
        The README's text.
    participants : sequence of mapping
        One row of ``participants.tsv`` per participant, keys as ``participant_columns``
        (the first is ``participant_id``, ``sub-<label>``).
    participant_columns : mapping
        Column name -> its description (``participants.json``), in column order.
    runs : sequence of mapping
        One per participant, study and session: ``label`` (str), ``study`` (1 or 2),
        ``session`` (the ``ses-`` label, or None for none), ``events`` (rows keyed by
        :data:`EVENT_COLUMNS`; None or NaN is written ``n/a``) and ``sidecar`` (extra keys
        of the events JSON besides the column descriptions, which it may replace); and
        ``task`` :data:`THRESHOLD_TASK` for a threshold block's trials (rows keyed by
        :data:`THRESHOLD_EVENT_COLUMNS`).
    source : str, optional
        Where the data comes from (the source file's resolved path), recorded in the
        manifest: an events file is replaced only by an export of the same source (the
        same label from another study is a file in the way).
    force : bool
        Replace files at the paths the export writes that vibrofocus did not write (or
        that were edited since, or another source's); without it such a file is refused
        and nothing changes.

    Returns
    -------
    dict
        ``participants`` and ``events`` (rows written), ``merged`` (True when added to
        an existing folder) and ``kept`` (the dataset's own ``dataset_description.json``
        or ``README``, left as they were).

    Raises
    ------
    ValidationError
        A run names a study other than 1 or 2, or two runs the same file.
    OutputError
        The folder cannot be written, holds a link where the export writes, a file in
        the way (not ``force``), or another export is writing it.
    """
    from .._atomic import atomic_directory, lock_folder, write_text
    from .._atomic_folders import resolve_folder_link
    from .bids_merge import merge_into_dataset, text_sha256, write_manifest

    files: dict[str, str] = {}
    for run in runs:
        if run["study"] not in TASKS:
            raise ValidationError(f"a BIDS run must be of study 1 or 2, got {run['study']!r}")
        threshold = run.get("task") == THRESHOLD_TASK
        name = events_name(run["label"], run["study"], run.get("session"), task=run.get("task"))
        folder = _events_folder(run["label"], run.get("session"))
        if f"{folder}/{name}.tsv" in files:
            raise ValidationError(f"two runs would both write {name}.tsv")
        described = THRESHOLD_COLUMN_DESCRIPTIONS if threshold else EVENT_COLUMN_DESCRIPTIONS
        sidecar = {"TaskName": run.get("task") or TASKS[run["study"]], **described, **run["sidecar"]}
        files[f"{folder}/{name}.tsv"] = _tsv(THRESHOLD_EVENT_COLUMNS if threshold else EVENT_COLUMNS, run["events"])
        files[f"{folder}/{name}.json"] = _json(sidecar)
    n_events = sum(len(run["events"]) for run in runs)
    shared = {"dataset_description.json": _json(description), "README": readme}
    columns = list(participant_columns)
    rows = [{c: _NA if p.get(c) is None else _cell(p[c]) for c in columns} for p in participants]
    out = resolve_folder_link(out_dir, what="BIDS dataset")
    counts: dict[str, Any] = {"participants": len(participants), "events": n_events}
    if not out.exists():
        try:
            # Only created, never swapped over a dataset another export put there meanwhile.
            with atomic_directory(out, what="BIDS dataset", exclusive=True) as build:
                texts = {**shared, "participants.tsv": _tsv(columns, participants),
                         "participants.json": _json(participant_columns), **files}
                for rel, text in texts.items():
                    write_text(build / rel, text, what="BIDS file", within=build, parents=True)
                write_manifest(build, {rel: text_sha256(text) for rel, text in texts.items()},
                               {rel: source for rel in files} if source is not None else None)
            return {**counts, "merged": False, "kept": []}
        except OutputError as exc:
            if exc.errno != _errno.EEXIST or not out.is_dir():
                raise
            # Another export created the dataset while this one built it: add to it as to any.
    # One export at a time: the manifest is read, checked and rewritten under the lock.
    with lock_folder(out, f"another export is writing the BIDS dataset {out} now; nothing was changed. Wait "
                          "for it to finish, then export again"):
        kept = merge_into_dataset(out, files=files, shared=shared, participant_columns=participant_columns,
                                  participant_rows=rows, participants_tsv=_tsv(columns, participants),
                                  participants_json=_json(participant_columns), source=source, force=force)
    return {**counts, "merged": True, "kept": kept}


#: Events columns :func:`read_bids_trials_table` passes on as they are (``n/a``: empty):
#: the stimulus played, and the protocol's block and the point answer the fit of
#: hypotheses reads.
_PASSED_COLUMNS = ("levels", "drive_peak_v", "target_peak_um", "xrun_represented", "protocol", "level_db", "allowed",
                   "response_x_mm", "response_y_mm")


def _read_tsv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh, delimiter="\t"))


def read_bids_trials_table(root: str | os.PathLike):
    """Read a dataset written by :func:`write_bids_dataset` as the trials table the analysis reads.

    Parameters
    ----------
    root : path-like
        The dataset folder (with ``dataset_description.json`` and ``participants.tsv``).

    Returns
    -------
    DataFrame
        Every value a str, with the trials-file columns (``participant``: the
        ``source_id``, ``study``, ``phase``, ``trial``, ``method``, ``target``,
        ``response``, ``rt_s``), the session columns (``session``, ``session_status``,
        ``dry_run``, ``rig``: the sidecar's ``Sessions`` ``Rig``, empty where it names none or
        several), ``simulated`` (``1``/``0``), the stimulus columns (``levels``,
        ``drive_peak_v``, ``target_peak_um``), ``xrun_represented``, the protocol's block
        (``protocol``, ``level_db``, ``allowed``), the point answer (``response_x_mm``,
        ``response_y_mm``) and, for a simulated participant, ``model``
        (the sidecar's ``SimulatedModel``) where the events files have them, and ``line``
        (row number over all events files, from 2), as
        :func:`~vibrofocus.io.trials_csv.read_trials_table` gives.

    Raises
    ------
    ValidationError
        Not a BIDS dataset, no events file, or an events file without a column of
        :data:`EVENT_COLUMNS`.
    """
    import pandas as pd

    from .._atomic import protect

    root = Path(root)
    if not (root / "dataset_description.json").is_file() or not (root / "participants.tsv").is_file():
        raise ValidationError(f"{root} is not a BIDS dataset: it needs dataset_description.json and participants.tsv")
    try:
        people = {r["participant_id"]: r for r in _read_tsv(root / "participants.tsv")}
    except (OSError, KeyError, csv.Error, UnicodeDecodeError) as exc:
        raise ValidationError(f"cannot read {root / 'participants.tsv'}: {exc}") from exc
    rows: list[dict[str, str]] = []
    files = sorted([*root.glob("sub-*/beh/sub-*_task-localization*_events.tsv"),
                    *root.glob("sub-*/ses-*/beh/sub-*_ses-*_task-localization*_events.tsv")])
    if not files:
        raise ValidationError(f"the BIDS dataset {root} has no sub-*/[ses-*/]beh/*_task-localization*_events.tsv")
    for path in files:
        protect(path, "BIDS events file")
        sub = path.name.split("_", 1)[0]
        study = path.name.split("_task-localization", 1)[1].split("_", 1)[0]
        # The session: the file's ses- entity (an older export: its session_id column).
        ses = path.name.split("_ses-", 1)[1].split("_", 1)[0] if "_ses-" in path.name else None
        person = people.get(sub, {})
        try:
            events = _read_tsv(path)
        except (OSError, csv.Error, UnicodeDecodeError) as exc:
            raise ValidationError(f"cannot read the events file {path}: {exc}") from exc
        if events and set(_REQUIRED_COLUMNS) - set(events[0]):
            missing = sorted(set(_REQUIRED_COLUMNS) - set(events[0]))
            raise ValidationError(f"the events file {path} lacks the column(s) {', '.join(missing)}")
        try:  # the sidecar names the model that answered, and the sessions' rig
            sidecar = json.loads(path.with_suffix(".json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            sidecar = {}
        sidecar = sidecar if isinstance(sidecar, dict) else {}
        model = sidecar.get("SimulatedModel") if person.get("simulated") == "true" else None
        sessions = sidecar.get("Sessions") if isinstance(sidecar.get("Sessions"), list) else []
        rigs = {str(i["Rig"]) for i in sessions if isinstance(i, dict) and i.get("Rig")}
        rig = rigs.pop() if len(rigs) == 1 else ""  # one file, one session: one rig
        for ev in events:
            stimulus = {c: ("" if ev[c] == _NA else ev[c]) for c in _PASSED_COLUMNS if c in ev}
            if model:
                stimulus["model"] = str(model)
            rows.append({
                "participant": person.get("source_id") or sub.removeprefix("sub-"), "study": study,
                "phase": ev["phase"], "trial": ev["trial"], "method": ev["method"], "target": ev["target"],
                "response": ev["response"], "rt_s": ev["response_time"],
                "session": ses if ses is not None else (
                    "0" if ev.get("session_id", _NA) in (_NA, None) else ev["session_id"]),
                "session_status": "completed" if ev["session_status"] == _NA else ev["session_status"],
                "dry_run": "0" if ev["dry_run"] == _NA else ev["dry_run"],
                "simulated": "1" if person.get("simulated") == "true" else "0", "rig": rig,
                **stimulus,
            })
    table = pd.DataFrame(rows, dtype=str).fillna("")  # a column some events files lack: empty cells
    table["line"] = range(2, len(table) + 2)
    return table
