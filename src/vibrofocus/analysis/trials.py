"""Read and validate a trials file (docs/file-formats.md, trials file), and check each study's design.

A trials file has one row per trial with the columns ``participant, study, phase, trial,
method, target, response, rt_s``. :func:`load_trials` reads it, types every column and
refuses (or, on request, excludes) rows that break the contract, always saying which
line, which column and why. :func:`check_design` then finds, per study, the participants
whose main phase misses a condition (target × method), so they can be left out of the
statistics *and reported*, never silently.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from typing import Literal

import numpy as np
import pandas as pd

from .._validation import check_choice, integer_text
from ..errors import ValidationError
from ..io.responses import parse_response_text
from ..io.bids import read_bids_trials_table
from ..io.trials_csv import TRIALS_COLUMNS, read_block_cells, read_trials_table
from ..layout import ArrayLayout

__all__ = [
    "REQUIRED_COLUMNS",
    "KNOWN_METHODS",
    "PHASES",
    "STUDIES",
    "KINDS",
    "select_kind",
    "load_trials",
    "trial_problems",
    "check_design",
    "method_order",
    "main_trials",
]

#: Columns a trials file must have (docs/file-formats.md, trials file): :data:`vibrofocus.io.trials_csv.TRIALS_COLUMNS`.
REQUIRED_COLUMNS: tuple[str, ...] = TRIALS_COLUMNS
#: Rendering methods in the order tables and figures list them; others follow alphabetically.
KNOWN_METHODS: tuple[str, ...] = ("funneling", "inverse", "combination", "time_reversal", "contrast", "constrained")
#: Valid phases.
PHASES: tuple[str, ...] = ("training", "main")
#: Valid study numbers.
STUDIES: tuple[int, ...] = (1, 2)

#: The kinds of participant one analysis takes (docs/file-formats.md, trials file):
#: ``people`` (people on hardware: not simulated, on a rig other than the simulated one),
#: ``simulated`` (simulated participants: answers from the perceptual model),
#: ``rehearsals`` (people's sessions on the simulated rig: nothing was felt), or ``all``
#: (every row, as the file holds them).
KINDS: tuple[str, ...] = ("people", "simulated", "rehearsals", "all")
#: How each kind is asked for at the command line (``vibrofocus analyze``).
_KIND_FLAGS = {"people": "the default", "simulated": "--simulated", "rehearsals": "--rehearsals"}

_MAX_LISTED = 5  # problems quoted in one error message


def method_order(methods: Iterable[str]) -> list[str]:
    """Sort method names: the known methods first (in :data:`KNOWN_METHODS` order), then the rest.

    Parameters
    ----------
    methods : iterable of str
        Method names; repeats are dropped.

    Returns
    -------
    list of str
    """
    methods = set(methods)
    known = [m for m in KNOWN_METHODS if m in methods]
    return known + sorted(methods - set(known))


def _short(value: object) -> str:
    from .._validation import shorten

    return shorten(value)


def _require_columns(raw: pd.DataFrame) -> None:
    """ValidationError naming the contract's columns that ``raw`` lacks (checked before any row is used)."""
    missing = [c for c in REQUIRED_COLUMNS if c not in raw.columns]
    if missing:
        from .._validation import shorten

        raise ValidationError(
            f"trials file is missing the column(s) {', '.join(missing)}; "
            f"expected the columns {', '.join(REQUIRED_COLUMNS)} (docs/file-formats.md, trials file), got "
            f"{shorten(', '.join(map(str, raw.columns)), 300, as_text=True)}"
        )


def _parse_selection(text: str, n_locations: int) -> tuple[tuple[int, ...] | None, str | None]:
    """Parse a response such as ``"4 5"``; return ``(selection, None)`` or ``(None, reason)``."""
    try:
        return parse_response_text(text, n_locations=n_locations), None
    except ValidationError as exc:
        return None, str(exc)


def _normal_name(name: str) -> str:
    return name.strip().lower().replace("-", "_").replace(" ", "_")


def _suspect_methods(
    method: pd.Series, study: pd.Series, phase: pd.Series, target: pd.Series, participant: pd.Series,
    n_locations: int,
) -> pd.Series:
    """Reasons (or None) per row for a method name that is most likely a typo.

    A method other than :data:`KNOWN_METHODS` is allowed (a new rendering method), but
    not one that differs from a known name only in case or separators (``'Inverse'``),
    nor one that no participant has for every target of the study (``'bogus'`` on one
    row): such a row would otherwise become a condition of its own, and every correct
    participant would look incomplete.
    """
    import difflib

    reasons = pd.Series(None, index=method.index, dtype=object)
    known = {_normal_name(m): m for m in KNOWN_METHODS}
    usable = study.notna() & target.between(1, n_locations).fillna(False).astype(bool) & method.ne("")
    for st in sorted(study[usable].unique()):
        in_study = usable & study.eq(st).fillna(False).astype(bool)
        main = in_study & phase.eq("main")
        basis = main if main.any() else in_study
        targets = set(target[basis].astype(int))
        complete: set[str] = set()
        for m in method[basis].unique():
            rows = basis & method.eq(m)
            have = pd.DataFrame({"p": participant[rows], "t": target[rows].astype(int)}).groupby("p")["t"].nunique()
            if len(targets) and (have >= len(targets)).any():
                complete.add(m)
        candidates = list(KNOWN_METHODS) + sorted(m for m in complete if m not in KNOWN_METHODS)
        for m in method[in_study].unique():
            if m in KNOWN_METHODS:
                continue
            rows = in_study & method.eq(m)
            norm = _normal_name(m)
            if norm in known:
                why = (f"method {m!r} is not {known[norm]!r}: method names are case-sensitive and a variant "
                       f"would count as a method of its own; write {known[norm]!r}")
            elif m in complete:
                continue
            else:
                close = difflib.get_close_matches(norm, [_normal_name(c) for c in candidates], n=1, cutoff=0.6)
                hint = ""
                if close:
                    hint = f"; did you mean {next(c for c in candidates if _normal_name(c) == close[0])!r}?"
                why = (f"method {m!r} is not one of {', '.join(KNOWN_METHODS)} and no participant has it for every "
                       f"target of study {int(st)}: probably a typo{hint}")
            reasons[rows] = why
    return reasons


#: Columns kept as text where a table has them: a study database's protocol, block level
#: and allowed answers, and point answers (:func:`vibrofocus.simulation.fitting.lab_trials`).
_BLOCK_COLUMNS = ("protocol", "level_db", "allowed", "response_x_mm", "response_y_mm")


def _block_reasons(df: pd.DataFrame, n_locations: int) -> dict[str, pd.Series]:
    """Per block or point column the table has, each row's reason (or None) to refuse its cell
    (:func:`~vibrofocus.io.trials_csv.read_block_cells`: a level, allowed answers, a point)."""
    blank = pd.Series("", index=df.index)
    out: dict[str, pd.Series] = {}
    for k, column in enumerate(("level_db", "allowed", "response_x_mm")):
        if column not in df.columns:
            continue
        args = [blank] * 4
        args[k] = df[column].astype(str)
        if column == "response_x_mm":
            args[3] = df["response_y_mm"].astype(str) if "response_y_mm" in df.columns else blank
        reasons = []
        for cells in zip(*args):
            try:
                read_block_cells(*cells, n_locations=n_locations)
                reasons.append(None)
            except ValidationError as exc:
                reasons.append(str(exc))
        out[column] = pd.Series(reasons, index=df.index, dtype=object)
    return out


def trial_problems(raw: pd.DataFrame, *, layout: ArrayLayout | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Type the columns of a raw trials table and list every row that breaks the contract.

    Parameters
    ----------
    raw : DataFrame
        The trials as read from CSV, every cell a string (see :func:`load_trials`). A
        ``line`` column (1-based line in the file) is used in messages when present.
    layout : ArrayLayout, optional
        Gives the number of locations (valid targets and responses are ``1..N``).
        Default :meth:`ArrayLayout.reference` (nine locations).

    Returns
    -------
    trials : DataFrame
        The rows that passed, typed: ``participant`` (str), ``study`` (int), ``phase``
        (str), ``trial`` (int), ``method`` (str), ``target`` (int), ``response`` (str),
        ``selection`` (tuple of int, sorted), ``n_selected`` (int), ``rt_s`` (float, s;
        NaN when empty), ``line`` (int); where the table has them, the protocol, block
        and point columns as text (``protocol``, ``level_db``, ``allowed``,
        ``response_x_mm``, ``response_y_mm``), each cell checked by
        :func:`~vibrofocus.io.trials_csv.read_block_cells`.
    problems : DataFrame
        One row per problem: ``line``, ``participant``, ``study``, ``column``, ``value``,
        ``reason``.

    Raises
    ------
    ValidationError
        If a required column is missing.
    """
    layout = ArrayLayout.reference() if layout is None else layout
    n_locations = len(layout.locations_xy)
    _require_columns(raw)
    df = raw.copy()
    if "line" not in df.columns:
        df["line"] = np.arange(2, len(df) + 2)  # header is line 1
    for col in REQUIRED_COLUMNS:
        df[col] = df[col].astype(str).str.strip()

    def as_int(col: str) -> pd.Series:
        """Integer values (``"3"``, ``"3.0"``; ASCII digits only) as Int64; anything else becomes <NA>."""
        num = pd.to_numeric(df[col].where(df[col].map(str.isascii)), errors="coerce")
        ok = num.notna() & np.isfinite(num) & (num == np.round(num))
        return num.where(ok).astype("Int64")

    study = as_int("study")
    trial = as_int("trial")
    target = as_int("target")
    phase = df["phase"]  # the contract's words exactly: 'MAIN' is a typo to report, not to guess
    rt_text = df["rt_s"]
    rt_empty = rt_text.eq("")
    rt = pd.to_numeric(rt_text.where(~rt_empty & rt_text.map(str.isascii)), errors="coerce")
    parsed = [_parse_selection(text, n_locations) for text in df["response"]]
    selection = pd.Series([sel for sel, _ in parsed], index=df.index, dtype=object)
    response_reason = pd.Series([why for _, why in parsed], index=df.index, dtype=object)
    n_sel = selection.map(lambda sel: len(sel) if sel is not None else 0)

    checks: list[tuple[str, pd.Series, pd.Series]] = []  # (column, bad mask, reason per row)

    def add(column: str, bad: pd.Series, reason) -> None:
        bad = bad.fillna(True).astype(bool)
        if bad.any():
            reasons = reason if isinstance(reason, pd.Series) else pd.Series(reason, index=df.index)
            checks.append((column, bad, reasons))

    empty_participant = df["participant"].eq("") | df["participant"].str.lower().eq("nan")
    add("participant", empty_participant, "participant is empty")
    add("study", ~study.isin(STUDIES), "study must be 1 or 2, got " + df["study"].map(_short))
    add("phase", ~phase.isin(PHASES), "phase must be 'training' or 'main', got " + df["phase"].map(_short))
    add("trial", ~trial.ge(1), "trial must be an integer trial number >= 1, got " + df["trial"].map(_short))
    empty_method = df["method"].eq("") | df["method"].str.lower().eq("nan")
    add("method", empty_method, "method is empty")
    method_reason = _suspect_methods(df["method"], study, phase, target, df["participant"], n_locations)
    add("method", method_reason.notna(), method_reason.fillna(""))
    add(
        "target",
        ~target.between(1, n_locations),
        f"target must be a location number 1..{n_locations}, got " + df["target"].map(_short),
    )
    add("response", response_reason.notna(), response_reason.fillna(""))
    add(
        "response",
        response_reason.isna() & study.eq(1).fillna(False).astype(bool) & n_sel.ne(1),
        "response study 1 takes exactly one location per trial, got " + n_sel.astype(str),
    )
    add(
        "rt_s",
        ~rt_empty & ~(np.isfinite(rt) & (rt >= 0)),
        "rt_s must be a time >= 0 in seconds (or empty), got " + rt_text.map(_short),
    )

    for column, reason in _block_reasons(df, n_locations).items():
        add(column, reason.notna(), reason.fillna(""))

    problems: list[dict] = []
    any_bad = pd.Series(False, index=df.index)
    for column, bad, reasons in checks:
        any_bad |= bad
        for i in np.flatnonzero(bad.to_numpy()):
            problems.append(
                {
                    "line": int(df["line"].iloc[i]),
                    "participant": df["participant"].iloc[i],
                    "study": None if pd.isna(study.iloc[i]) else int(study.iloc[i]),
                    "column": column,
                    "value": df[column].iloc[i],
                    "reason": reasons.iloc[i],
                }
            )
    problems.sort(key=lambda p: p["line"])  # stable: per line, in the order of the checks
    good = ~any_bad
    # A study database's export names the session of each row: trial numbers repeat
    # across two sessions of one participant, and are unique within a session.
    by_session = {"session": df["session"][good]} if "session" in df.columns else {}
    # The stimulus columns of a study database's export (the level rule, the peaks), kept as they are.
    stimulus = {}
    if {"levels", "drive_peak_v", "target_peak_um"} <= set(df.columns):
        stimulus = {"levels": df["levels"][good].astype(str).str.strip(),
                    **{c: pd.to_numeric(df[c][good], errors="coerce") for c in ("drive_peak_v", "target_peak_um")}}
    # The block and point columns of a study database's trials (the fit of hypotheses reads them), as text.
    block = {c: df[c][good].astype(str).str.strip() for c in _BLOCK_COLUMNS if c in df.columns}
    trials = pd.DataFrame(
        {
            "participant": df["participant"][good],
            "study": study[good],
            "phase": phase[good],
            "trial": trial[good],
            "method": df["method"][good],
            "target": target[good],
            "response": df["response"][good],
            "selection": selection[good],
            "n_selected": n_sel[good],
            "rt_s": rt[good],
            "line": df["line"][good],
            **by_session,
            **stimulus,
            **block,
        }
    ).reset_index(drop=True)
    if len(trials):
        trials = trials.astype(
            {"study": int, "trial": int, "target": int, "n_selected": int, "rt_s": float, "line": int}
        )
        key = ["participant", "study", "phase", "trial"] + list(by_session)
        dup = trials.duplicated(key, keep="first")
        for row in trials[dup].itertuples(index=False):
            problems.append(
                {
                    "line": int(row.line),
                    "participant": row.participant,
                    "study": int(row.study),
                    "column": "trial",
                    "value": str(row.trial),
                    "reason": f"trial {row.trial} of the {row.phase} phase of study {row.study} appears twice",
                }
            )
        trials = trials[~dup].reset_index(drop=True)
    problems_df = pd.DataFrame.from_records(
        problems, columns=["line", "participant", "study", "column", "value", "reason"]
    )
    return trials, problems_df


def load_trials(
    source: str | os.PathLike | pd.DataFrame,
    *,
    layout: ArrayLayout | None = None,
    on_invalid: Literal["raise", "exclude"] = "raise",
    keep_aborted: bool = False,
    keep_dry_runs: bool = False,
    kind: str = "all",
) -> pd.DataFrame:
    """Read a trials CSV file (docs/file-formats.md, trials file) and validate every row.

    Parameters
    ----------
    source : path or DataFrame
        The CSV file, a BIDS dataset folder written by ``vibrofocus export --bids``
        (:func:`vibrofocus.io.bids.read_bids_trials_table`), or a table with the same columns.
    layout : ArrayLayout, optional
        Layout whose locations the targets and responses refer to; default the
        reference layout (locations 1–9).
    on_invalid : {"raise", "exclude"}
        (An optional ``simulated`` column marks simulated participants; they are listed
        in ``trials.attrs["simulated_participants"]``.)
        What to do with rows that break the contract (a response or target outside the
        locations, an unparsable response, an unknown study or phase, a duplicated
        trial, ...): ``"raise"`` refuses the file, quoting the first problems;
        ``"exclude"`` drops *all* rows of each participant with a bad row and records
        why in ``trials.attrs["exclusions"]`` (a list of dicts with ``participant``,
        ``study`` and ``reason``), which :func:`vibrofocus.analysis.analyze` reports.
    keep_aborted, keep_dry_runs : bool
        For a file with the session columns of a study database's export (``session``,
        ``session_status``, ``dry_run``): rows of aborted sessions and of dry runs (no
        calibration, nothing played) are left out unless these are True, and each such
        session is listed in ``attrs["exclusions"]``.
    kind : {"all", "people", "simulated", "rehearsals"}
        Which participants to analyse (:data:`KINDS`, :func:`select_kind`): every row
        (default), or one kind alone, the others listed in ``attrs["exclusions"]``.

    Returns
    -------
    DataFrame
        Typed trials, both phases (see :func:`trial_problems` for the columns), sorted
        by participant, study, phase and trial. ``attrs["exclusions"]`` lists the
        excluded participants (empty with ``on_invalid="raise"``) and
        ``attrs["source"]`` names the file.

    Raises
    ------
    ValidationError
        Unreadable or empty file, a missing column, or (``on_invalid="raise"``) any
        invalid row.
    """
    check_choice(on_invalid, "on_invalid", ("raise", "exclude"))
    if isinstance(source, pd.DataFrame):
        raw = source.astype(str).reset_index(drop=True)
        for c in _BLOCK_COLUMNS[1:]:  # a missing value is an empty cell, not the text 'nan'
            if c in raw.columns:
                raw[c] = source[c].where(source[c].notna(), "").astype(str).to_numpy()
        name = "<DataFrame>"
        if "line" not in raw.columns:
            raw["line"] = np.arange(2, len(raw) + 2)
    elif os.path.isdir(source):  # a BIDS dataset (vibrofocus export --bids)
        name = os.fspath(source)
        raw = read_bids_trials_table(name)
    else:
        name = os.fspath(source)
        raw = read_trials_table(name)
    if len(raw) == 0:
        raise ValidationError(f"trials file {name!r} has a header but no trials")
    _require_columns(raw)  # before the session columns are used
    # A study database's rows (simulation.fitting.trials_source) name the database.
    named = str(source.attrs.get("source", name)) if isinstance(source, pd.DataFrame) else name
    raw, exclusions = _drop_sessions(raw, keep_aborted=keep_aborted, keep_dry_runs=keep_dry_runs)
    if on_invalid == "raise":  # a broken file is said to be broken, whatever kinds of participant it holds
        _raise_problems(name, trial_problems(raw, layout=layout)[1])
    raw, left_out = select_kind(raw, kind, name=named)
    exclusions = left_out + exclusions
    trials, problems = trial_problems(raw, layout=layout)
    if len(problems):
        if on_invalid == "raise":
            _raise_problems(name, problems)
        for participant, group in problems.groupby("participant", sort=True):
            first = group.iloc[0]
            extra = f" (and {len(group) - 1} more problem(s))" if len(group) > 1 else ""
            exclusions.append(
                {
                    "participant": str(participant),
                    "study": None,
                    "reason": f"invalid row(s) in the trials file: line {first.line}: {first.reason}{extra}",
                }
            )
        trials = trials[~trials["participant"].isin(problems["participant"])].reset_index(drop=True)
    trials = trials.sort_values(["participant", "study", "phase", "trial"], kind="stable").reset_index(drop=True)
    trials.attrs["exclusions"] = exclusions
    trials.attrs["source"] = name
    trials.attrs["simulated_participants"] = simulated_participants(raw)
    trials.attrs["simulated_models"] = simulated_models(raw)
    trials.attrs["xrun_represented"] = xrun_represented(raw[raw["participant"].isin(trials["participant"])])
    return trials


def xrun_represented(raw: pd.DataFrame) -> int | None:
    """Answered trials presented again because their stimulus lost samples (an xrun): rows whose
    ``xrun_represented`` (a study database's export) is above 0; None when the trials do not say."""
    if "xrun_represented" not in raw.columns:
        return None
    return int((pd.to_numeric(raw["xrun_represented"], errors="coerce").fillna(0) > 0).sum())


def simulated_models(raw: pd.DataFrame) -> list[str]:
    """The labels of the models that answered for the simulated participants (column
    ``model`` of a study database's export: model version and hypothesis), sorted; empty
    when the trials do not name them."""
    if "model" not in raw.columns or "simulated" not in raw.columns:
        return []
    flag = raw["simulated"].astype(str).str.strip().str.lower().isin(("1", "true", "yes", "1.0"))
    return sorted({str(m).strip() for m in raw.loc[flag, "model"] if str(m).strip()})


def simulated_participants(raw: pd.DataFrame) -> list[str]:
    """Participants whose rows say ``simulated`` (column ``simulated`` true: 1/true/yes).

    Their answers come from the perceptual model of simulated participants, not from
    people; the report flags them.
    """
    if "simulated" not in raw.columns or "participant" not in raw.columns:
        return []
    flag = raw["simulated"].astype(str).str.strip().str.lower().isin(("1", "true", "yes", "1.0"))
    return sorted({str(p).strip() for p in raw.loc[flag, "participant"]})


def _raise_problems(name: str, problems: pd.DataFrame) -> None:
    """Refuse a trials file with invalid values, listing the first of them by line."""
    if not len(problems):
        return
    listed = "; ".join(f"line {p.line}: {p.reason}" for p in problems.head(_MAX_LISTED).itertuples())
    more = f" (and {len(problems) - _MAX_LISTED} more)" if len(problems) > _MAX_LISTED else ""
    raise ValidationError(
        f"trials file {name!r} has {len(problems)} invalid value(s): {listed}{more}. "
        "Fix the file, or exclude the participants concerned (on_invalid='exclude', CLI --exclude-invalid)"
    )


def _row_kinds(raw: pd.DataFrame) -> pd.Series:
    """Each row's kind: ``simulated`` (column ``simulated`` true), ``rehearsals`` (a person on
    the ``simulated`` rig, column ``rig``) or ``people`` (anyone else: a file without these
    columns holds people)."""
    def flag(column: str, words: tuple[str, ...]) -> pd.Series:
        if column not in raw.columns:
            return pd.Series(False, index=raw.index)
        return raw[column].astype(str).str.strip().str.lower().isin(words)

    simulated = flag("simulated", ("1", "true", "yes", "1.0"))
    on_model = flag("rig", ("simulated",))
    return pd.Series(np.where(simulated, "simulated", np.where(on_model, "rehearsals", "people")), index=raw.index)


def select_kind(raw: pd.DataFrame, kind: str, *, name: str = "the trials") -> tuple[pd.DataFrame, list[dict]]:
    """Keep the rows of one kind of participant; say what was left out, and why.

    Parameters
    ----------
    raw : DataFrame
        A trials table as read (text cells), with the optional columns ``simulated`` and
        ``rig`` of a study database's export.
    kind : {"people", "simulated", "rehearsals", "all"}
        :data:`KINDS`: people on hardware, simulated participants, people's rehearsals on
        the simulated rig, or every row.
    name : str
        The source, for the message.

    Returns
    -------
    raw : DataFrame
        The rows of that kind.
    left_out : list of dict
        ``participant``, ``study`` (None) and ``reason`` for each participant of another
        kind, or each rehearsal session of a person (when the table names sessions).

    Raises
    ------
    ValidationError
        An unknown kind, or no row of that kind (the message says which kinds there are
        and how to ask for them).
    """
    check_choice(kind, "kind", KINDS)
    if kind == "all":
        return raw, []
    kinds = _row_kinds(raw)
    keep = kinds.eq(kind)
    if not keep.any():
        found = [f"{raw.loc[kinds.eq(k), 'participant'].nunique()} {words} ({_KIND_FLAGS[k]})"
                 for k, words in (("simulated", "simulated participant(s)"),
                                  ("rehearsals", "person(s) rehearsing on the simulated rig"),
                                  ("people", "person(s) on hardware")) if kinds.eq(k).any()]
        wanted = {"people": "people on hardware", "simulated": "simulated participants",
                  "rehearsals": "rehearsals on the simulated rig"}[kind]
        raise ValidationError(f"{name} holds no {wanted} to analyse; it holds {' and '.join(found)}: "
                              "analyse one kind at a time, with the option named")
    why = {
        "simulated": "simulated participant: answers from a perceptual model, not from a person; "
                     "analysed alone with --simulated",
        "rehearsals": "rehearsal on the simulated rig: the person felt nothing; analysed alone with --rehearsals",
        "people": "a person on hardware, not of this analysis's kind; analysed alone by default",
    }
    left_out = []
    for k in ("simulated", "rehearsals", "people"):
        # A rehearsal is a session (a person may rehearse, then sit on hardware); the others a participant.
        by = ["participant", "session"] if k == "rehearsals" and "session" in raw.columns else ["participant"]
        for key, rows in raw[~keep & kinds.eq(k)].groupby(by, sort=True):
            key = key if isinstance(key, tuple) else (key,)
            where = f"session {key[1]} left out" if len(key) > 1 else "left out"
            left_out.append({"participant": str(key[0]), "study": None,
                             "reason": f"{where}: {why[k]} ({len(rows)} answered trials)"})
    return raw[keep].reset_index(drop=True), left_out


def _drop_sessions(raw: pd.DataFrame, *, keep_aborted: bool, keep_dry_runs: bool) -> tuple[pd.DataFrame, list[dict]]:
    """Leave out the rows of aborted sessions and dry runs; one exclusion per session."""
    if not {"session", "session_status", "dry_run"} <= set(raw.columns):
        return raw, []
    status = raw["session_status"].astype(str).str.strip().str.lower()
    dry = raw["dry_run"].astype(str).str.strip().str.lower().isin(("1", "true", "yes"))
    aborted = status.eq("aborted") & (not keep_aborted)
    dry_out = dry & (not keep_dry_runs)
    drop = aborted | dry_out
    exclusions = []
    for (participant, study, session), rows in raw[drop].groupby(["participant", "study", "session"], sort=False):
        whys = (["it was aborted"] if aborted[rows.index].any() else []) + (
            ["it was a dry run (no calibration: nothing was played)"] if dry_out[rows.index].any() else [])
        exclusions.append({
            "participant": str(participant),
            "study": integer_text(str(study)),
            "reason": f"session {session} left out because {' and '.join(whys)} ({len(rows)} answered trials)",
        })
    return raw[~drop].reset_index(drop=True), exclusions


def main_trials(trials: pd.DataFrame, study: int) -> pd.DataFrame:
    """Return the main-phase rows of one study (training rows are never analysed).

    Parameters
    ----------
    trials : DataFrame
        The table returned by :func:`load_trials`.
    study : {1, 2}
        Which study.

    Returns
    -------
    DataFrame
        Its main-phase rows, re-indexed from 0.
    """
    check_choice(study, "study", STUDIES)
    missing = [c for c in ("study", "phase", "participant", "method", "target", "selection") if c not in trials.columns]
    if missing:
        raise ValidationError(
            f"trials must be the table returned by load_trials; missing column(s) {', '.join(missing)}"
        )
    return trials[(trials["study"] == study) & (trials["phase"] == "main")].reset_index(drop=True)


def check_design(trials: pd.DataFrame, study: int) -> tuple[pd.DataFrame, list[dict], list[str]]:
    """Keep the participants who completed every condition of one study.

    The conditions are all (target, method) pairs seen in the study's main phase. A
    participant missing any of them cannot enter the repeated-measures statistics and
    is excluded with the reason; unequal numbers of repetitions are kept (trials are
    averaged per condition) and returned as warnings.

    Parameters
    ----------
    trials : DataFrame
        Output of :func:`load_trials`.
    study : {1, 2}
        Which study.

    Returns
    -------
    complete : DataFrame
        Main-phase trials of the complete participants.
    exclusions : list of dict
        ``participant``, ``study``, ``reason`` for each excluded participant.
    warnings : list of str
        Remarks that do not exclude anyone (unequal repetitions).
    """
    main = main_trials(trials, study)
    exclusions: list[dict] = []
    warnings: list[str] = []
    in_study = trials.loc[trials["study"] == study, "participant"].unique()
    for participant in sorted(set(in_study) - set(main["participant"])):
        exclusions.append(
            {"participant": str(participant), "study": study, "reason": f"no main-phase trials in study {study}"}
        )
    if main.empty:
        return main, exclusions, warnings
    conditions = main[["target", "method"]].drop_duplicates()
    all_conditions = set(map(tuple, conditions.to_numpy().tolist()))
    counts = main.groupby(["participant", "target", "method"]).size()
    rank = {m: i for i, m in enumerate(method_order(main["method"].unique()))}
    complete = []
    for participant, sub in counts.groupby(level="participant", sort=True):
        have = {(t, m) for _, t, m in sub.index}
        lacking = sorted(all_conditions - have, key=lambda c: (c[0], rank[c[1]]))
        if lacking:
            shown = ", ".join(f"location {t} × {m}" for t, m in lacking[:_MAX_LISTED])
            more = f" and {len(lacking) - _MAX_LISTED} more" if len(lacking) > _MAX_LISTED else ""
            exclusions.append(
                {
                    "participant": str(participant),
                    "study": study,
                    "reason": (
                        f"incomplete: no main-phase trial for {len(lacking)} of the {len(all_conditions)} "
                        f"conditions in study {study} ({shown}{more})"
                    ),
                }
            )
            continue
        complete.append(participant)
        reps = sub.to_numpy()
        if reps.min() != reps.max():
            warnings.append(
                f"participant {participant}, study {study}: unequal repetitions per condition "
                f"({reps.min()} to {reps.max()} trials); conditions are averaged"
            )
    return main[main["participant"].isin(complete)].reset_index(drop=True), exclusions, warnings
