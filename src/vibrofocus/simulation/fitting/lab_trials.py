"""A lab's trials as the arrays the likelihood reads: stimulus and answer of every main trial.

:func:`trials_source` turns a study database into the table :func:`vibrofocus.analysis.load_trials`
reads (a trials CSV and a BIDS folder are read by it directly; all three carry each
trial's block level and allowed answers, columns :data:`BLOCK_COLUMNS`), and :func:`lab_trials` maps the
loaded trials onto a feature bank's stimuli (method x location), with each trial's level,
the locations it could be answered with and its point answer, refusing trials the bank
or the likelihood cannot represent. How the fit uses them: docs/fitting-hypotheses.md.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import cached_property
from typing import Any, NamedTuple

import numpy as np

from ...errors import ValidationError
from ...io.trials_csv import BLOCK_COLUMNS, read_block_cells
from ..bank import FeatureBank

__all__ = ["LabTrials", "TrialGroup", "BLOCK_COLUMNS", "PAPER_PROTOCOLS", "trials_source", "lab_trials"]

# BLOCK_COLUMNS: what a study database's trials, its trials file and its BIDS events say of
# each trial's block (io.trials_csv): level_db, the level in dB re the session's level rule
# (a level in dB SL already turned into it), and allowed, the locations it could be answered with.
#: Protocols whose every trial is at 0 dB with every location allowed: the paper's two
#: studies (also the protocol of a session stored before protocol files).
PAPER_PROTOCOLS = ("paper-study1", "paper-study2")


class TrialGroup(NamedTuple):
    """Trials that share a level and allowed locations, with their distinct stimuli.

    Attributes
    ----------
    level_db : float
    allowed : ndarray of int or None
        The allowed locations (0-based); None: every location.
    rows : ndarray of int
        The group's trials (indices into the study's arrays).
    stimuli : ndarray of int
        The distinct stimuli (sorted), or for Study 2 the stimulus of each distinct
        (stimulus, selection) pair.
    which : ndarray of int, shape (rows.size,)
        Each trial's entry in ``stimuli`` (Study 2: in ``selections`` too).
    selections : ndarray of bool, shape (stimuli.size, n_locations), or None
        Study 2: each distinct pair's selection.
    """

    level_db: float
    allowed: np.ndarray | None
    rows: np.ndarray
    stimuli: np.ndarray
    which: np.ndarray
    selections: np.ndarray | None = None


def _distinct_rows(*columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct rows of the columns side by side (sorted), and each row's index among them."""
    keys = np.column_stack([np.asarray(c, dtype=float).reshape(np.shape(c)[0], -1 if np.size(c) else 1)
                            for c in columns])
    uniq, inverse = np.unique(keys, axis=0, return_inverse=True)
    return uniq, inverse.reshape(-1)


@dataclass(frozen=True)
class LabTrials:
    """The main-phase trials of a lab's Study 1 and Study 2, on a feature bank's stimuli.

    Stimulus ``s`` is ``method * n_locations + location`` (0-based, the order of
    :meth:`~vibrofocus.simulation.likelihood.Stimuli.from_bank`).

    Attributes
    ----------
    participants : tuple of str
        Participant ids, in the order of the ``participant`` indices below.
    methods : tuple of str
        The bank's methods (the stimulus numbering's methods).
    n_locations : int
    part1, stim1, answer1 : ndarray of int, shape (n1,)
        Study 1: participant index, stimulus, answered location (0-based).
    part2, stim2 : ndarray of int, shape (n2,)
        Study 2: participant index, stimulus.
    selected2 : ndarray of bool, shape (n2, n_locations)
        Study 2 selections.
    source : str
        The trials' source (file name, or ``<DataFrame>``).
    levels : str or None
        The level rule the trials name (column ``levels``), or None where they name none.
    level1, level2 : ndarray of float, shape (n1,) and (n2,), or None
        Each trial's level, dB re the level rule (None: all at 0 dB).
    allowed1, allowed2 : ndarray of bool, shape (n1, n_locations) and (n2, n_locations), or None
        The locations each trial could be answered with (None: every location).
    point1 : ndarray of float, shape (n1, 2), or None
        Study 1 point answers in the layout frame, m; NaN rows for location answers (None:
        no point answer). A point trial's ``answer1`` is the allowed location nearest it.
    """

    participants: tuple[str, ...]
    methods: tuple[str, ...]
    n_locations: int
    part1: np.ndarray
    stim1: np.ndarray
    answer1: np.ndarray
    part2: np.ndarray
    stim2: np.ndarray
    selected2: np.ndarray
    source: str = "<DataFrame>"
    levels: str | None = None
    level1: np.ndarray | None = None
    level2: np.ndarray | None = None
    allowed1: np.ndarray | None = None
    allowed2: np.ndarray | None = None
    point1: np.ndarray | None = None

    @property
    def n_participants(self) -> int:
        return len(self.participants)

    def study1_conditions(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Study 1 trials' level (dB), allowed locations (bool, (n1, n_locations)) and point (m, NaN: none)."""
        n = self.stim1.size
        return (np.zeros(n) if self.level1 is None else self.level1,
                np.ones((n, self.n_locations), dtype=bool) if self.allowed1 is None else self.allowed1,
                np.full((n, 2), np.nan) if self.point1 is None else self.point1)

    def study2_conditions(self) -> tuple[np.ndarray, np.ndarray]:
        """Study 2 trials' level (dB) and allowed locations (bool, (n2, n_locations))."""
        n = self.stim2.size
        return (np.zeros(n) if self.level2 is None else self.level2,
                np.ones((n, self.n_locations), dtype=bool) if self.allowed2 is None else self.allowed2)

    def _groups(self, level: np.ndarray, allowed: np.ndarray, stim: np.ndarray,
                selected: np.ndarray | None) -> tuple[TrialGroup, ...]:
        """Trials grouped by (level, allowed locations), in sorted order of those keys."""
        if not stim.size:
            return ()
        keys, group = _distinct_rows(level, allowed)
        out = []
        for g, key in enumerate(keys):
            rows = np.flatnonzero(group == g)
            ok = np.flatnonzero(key[1:])
            if selected is None:
                stimuli, which = np.unique(stim[rows], return_inverse=True)
                picks = None
            else:
                pairs, which = _distinct_rows(stim[rows], selected[rows])
                stimuli, picks = pairs[:, 0].astype(int), pairs[:, 1:].astype(bool)
            out.append(TrialGroup(float(key[0]), None if ok.size == self.n_locations else ok, rows,
                                  stimuli, which.reshape(-1), picks))
        return tuple(out)

    @cached_property
    def study1_groups(self) -> tuple[TrialGroup, ...]:
        """Study 1 trials by (level, allowed locations): what every likelihood evaluation scores alike.

        Computed once per trials object (the likelihood reads it at every parameter set
        and population draw).
        """
        level, allowed, _ = self.study1_conditions()
        return self._groups(level, allowed, self.stim1, None)

    @cached_property
    def study2_groups(self) -> tuple[TrialGroup, ...]:
        """Study 2 trials by (level, allowed locations), each group's distinct (stimulus, selection) pairs."""
        level, allowed = self.study2_conditions()
        return self._groups(level, allowed, self.stim2, self.selected2)

    def table(self) -> Any:
        """The trials as a trials-file table (docs/file-formats.md, trials file), every cell text.

        Returns
        -------
        DataFrame
            Columns ``participant, study, phase, trial, method, target, response, rt_s``
            (main phase; ``rt_s`` empty), which :func:`vibrofocus.analysis.load_trials` reads.
        """
        import pandas as pd

        frames = []
        for study, part, stim, sel in ((1, self.part1, self.stim1, np.eye(self.n_locations, dtype=bool)[self.answer1]),
                                       (2, self.part2, self.stim2, self.selected2)):
            response = [" ".join(str(j + 1) for j in np.flatnonzero(row)) for row in sel]
            trial = np.zeros(part.size, dtype=int)
            for i in np.unique(part):
                trial[part == i] = np.arange(1, np.count_nonzero(part == i) + 1)
            frames.append(pd.DataFrame({
                "participant": [self.participants[i] for i in part], "study": study, "phase": "main", "trial": trial,
                "method": [self.methods[k] for k in stim // self.n_locations], "target": stim % self.n_locations + 1,
                "response": response, "rt_s": ""}))
        return pd.concat(frames, ignore_index=True).astype(str)

    def subset(self, keep: np.ndarray, studies: tuple[int, ...] = (1, 2)) -> "LabTrials":
        """Only the participants ``keep`` (indices into :attr:`participants`), renumbered in that order.

        Parameters
        ----------
        keep : ndarray of int
            Participant indices.
        studies : tuple of int
            The studies whose trials are kept.

        Returns
        -------
        LabTrials
        """
        keep = np.asarray(keep, dtype=int)
        new = np.full(self.n_participants, -1)
        new[keep] = np.arange(keep.size)
        r1 = (new[self.part1] >= 0) & (1 in studies)
        r2 = (new[self.part2] >= 0) & (2 in studies)

        def rows(a: np.ndarray | None, r: np.ndarray) -> np.ndarray | None:
            return None if a is None else a[r]

        return LabTrials(tuple(self.participants[i] for i in keep), self.methods, self.n_locations,
                         new[self.part1][r1], self.stim1[r1], self.answer1[r1], new[self.part2][r2], self.stim2[r2],
                         self.selected2[r2], self.source, self.levels, rows(self.level1, r1), rows(self.level2, r2),
                         rows(self.allowed1, r1), rows(self.allowed2, r2), rows(self.point1, r1))


def _is_database(path: str) -> bool:
    try:
        with open(path, "rb") as fh:
            return fh.read(16) == b"SQLite format 3\x00"
    except OSError:
        return False


def trials_source(source: str | os.PathLike) -> Any:
    """What :func:`vibrofocus.analysis.load_trials` reads for ``source``.

    Parameters
    ----------
    source : path-like
        A trials CSV, a BIDS folder (``vibrofocus export --bids``) or a study database
        (SQLite, e.g. of ``vibrofocus simulate-study``).

    Returns
    -------
    path or DataFrame
        The path as it is for a CSV or a folder; for a database, its answered trials as a
        table of text cells (:meth:`~vibrofocus.studies.storage.StudyStore.trial_rows`)
        with each session's block level and allowed answers (:data:`BLOCK_COLUMNS`), and
        ``attrs["source"]`` the database's path.
    """
    name = os.fspath(source)
    if os.path.isdir(name) or not _is_database(name):
        return source
    import pandas as pd

    from ..._output_rules import protect
    from ...studies.storage import StudyStore

    protect(name, "study database")
    with StudyStore(name, create=False) as store:
        rows = store.trial_rows()  # with each session's block: BLOCK_COLUMNS
    if not rows:
        raise ValidationError(f"study database {name!r} holds no answered trials")
    table = pd.DataFrame(rows).astype(object)
    table = table.where(table.notna(), "").astype(str)
    table.attrs["source"] = name
    return table


def _cells(p: Any, column: str) -> list[str]:
    """The column's cells as stripped text ('' for an empty cell or a missing column)."""
    if column not in p.columns:
        return [""] * len(p)
    return ["" if str(v).strip() in ("", "None", "nan", "NaN") else str(v).strip() for v in p[column]]


def _block_conditions(p: Any, study: int, n_loc: int, source: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each row's level (dB), allowed locations (bool) and point answer (m, NaN: none).

    Refuses rows of a protocol other than the paper's whose level or allowed answers the
    table does not hold (a trials file or BIDS dataset exported before they were), and
    values :func:`~vibrofocus.io.trials_csv.read_block_cells` cannot read."""
    where = f"study {study} of {source!r}"
    level = np.zeros(len(p))
    allowed = np.ones((len(p), n_loc), dtype=bool)
    point = np.full((len(p), 2), np.nan)
    columns = [_cells(p, c) for c in (*BLOCK_COLUMNS, "response_x_mm", "response_y_mm")]
    for i, (protocol, *cells) in enumerate(zip(_cells(p, "protocol"), *columns)):
        try:
            lvl, places, pt = read_block_cells(*cells, n_locations=n_loc)
        except ValidationError as exc:
            raise ValidationError(f"{where}: {exc}") from None
        if protocol and protocol not in PAPER_PROTOCOLS and (lvl is None or places is None):
            missing = " and ".join(c for c, v in zip(BLOCK_COLUMNS, (lvl, places)) if v is None)
            raise ValidationError(f"{where} comes from protocol {protocol!r}, and the trials do not say each block's "
                                  f"{missing}: export them again with this vibrofocus (vibrofocus study export, "
                                  "vibrofocus export --bids) or fit the study database itself (vibrofocus analyze "
                                  "STUDY.db --hypotheses)")
        if lvl is not None:
            level[i] = lvl
        if places is not None:
            allowed[i] = False
            allowed[i, np.asarray(places, dtype=int) - 1] = True
        if pt is not None:
            point[i] = pt[0] * 1e-3, pt[1] * 1e-3
    if study == 2 and np.isfinite(point).any():
        raise ValidationError(f"{where} has point answers: a Study 2 trial's answer is a selection of locations")
    return level, allowed, point


def lab_trials(trials: Any, bank: FeatureBank) -> LabTrials:
    """The main-phase trials of ``trials`` on the stimuli of ``bank``.

    Each trial is read with its block's level (column ``level_db``, dB re the level rule;
    default 0), the locations it could be answered with (column ``allowed``, location
    numbers; default every location) and, in Study 1, its point answer (columns
    ``response_x_mm``, ``response_y_mm``, layout frame; default none): the columns of a
    study database's trials (:func:`trials_source`, :data:`BLOCK_COLUMNS`).

    Parameters
    ----------
    trials : DataFrame
        As :func:`vibrofocus.analysis.load_trials` returns (training rows are left out).
    bank : FeatureBank
        Whose methods and locations the trials must use.

    Returns
    -------
    LabTrials

    Raises
    ------
    ValidationError
        No main-phase trial of either study; a method the bank has no stimuli of; a
        target or answer beyond the bank's locations; a Study 1 answer of more than one
        location; an answer outside its block's allowed locations; a point answer in
        Study 2; trials of a protocol other than the paper's without their blocks' levels
        and allowed answers (a designed study's trials file or BIDS dataset exported
        before they carried them: export it again, or fit its database); a level, allowed
        answer or point cell that is not readable (:func:`~vibrofocus.io.trials_csv.read_block_cells`);
        trials that name a level rule other than the bank's.
    """
    from ...analysis.trials import main_trials

    n_loc = len(bank.locations_xy)
    source = str(trials.attrs.get("source", "<DataFrame>"))
    parts = [main_trials(trials, 1), main_trials(trials, 2)]
    if not any(len(p) for p in parts):
        raise ValidationError(f"trials {source!r} have no main-phase trials of study 1 or 2 to fit")
    levels = None
    if "levels" in trials.columns:
        named = sorted({str(v) for v in trials["levels"] if str(v).strip() not in ("", "None", "nan")})
        if len(named) > 1:
            raise ValidationError(f"trials {source!r} mix level rules ({', '.join(named)}); fit one at a time")
        if named and named[0] != bank.levels:
            raise ValidationError(f"trials {source!r} were played at level rule {named[0]!r}, the feature bank's "
                                  f"stimuli at {bank.levels!r}; build a bank with scripts/build_feature_bank.py "
                                  f"--levels {named[0]}")
        levels = named[0] if named else None
    unknown = sorted({str(m) for p in parts for m in p["method"]} - set(bank.methods))
    if unknown:
        raise ValidationError(f"trials {source!r} use method(s) {', '.join(unknown)} that the feature bank has no "
                              f"stimuli of (it has {', '.join(bank.methods)})")
    participants = tuple(sorted({str(x) for p in parts for x in p["participant"]}))
    number = {p: i for i, p in enumerate(participants)}
    method = {m: i for i, m in enumerate(bank.methods)}
    out: list[np.ndarray] = []
    block: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    for study, p in zip((1, 2), parts):
        target = p["target"].to_numpy(dtype=int) - 1
        if np.any((target < 0) | (target >= n_loc)):
            raise ValidationError(f"study {study} of {source!r} has targets beyond the bank's {n_loc} locations")
        sel = np.zeros((len(p), n_loc), dtype=bool)
        for row, chosen in enumerate(p["selection"]):
            chosen = np.asarray(chosen, dtype=int) - 1
            if chosen.size == 0 or np.any((chosen < 0) | (chosen >= n_loc)):
                raise ValidationError(f"study {study} of {source!r} has an answer beyond the bank's {n_loc} locations")
            sel[row, chosen] = True
        block[study] = _block_conditions(p, study, n_loc, source)
        located = ~np.isfinite(block[study][2][:, 0])  # a point answer's stored location may lie outside
        if np.any(sel[located] & ~block[study][1][located]):
            raise ValidationError(f"study {study} of {source!r} has an answer outside its block's allowed locations")
        stim = np.array([method[m] for m in p["method"]], dtype=int) * n_loc + target
        who = np.array([number[str(x)] for x in p["participant"]], dtype=int)
        if study == 1:
            if np.any(sel.sum(axis=1) != 1):
                raise ValidationError(f"study 1 of {source!r} has answers of more than one location")
            out += [who, stim, np.argmax(sel, axis=1)]
        else:
            out += [who, stim, sel]
    (level1, allowed1, point1), (level2, allowed2, _) = block[1], block[2]
    return LabTrials(participants, tuple(bank.methods), n_loc, *out, source=source, levels=levels,
                     level1=level1 if level1.any() else None, level2=level2 if level2.any() else None,
                     allowed1=None if allowed1.all() else allowed1, allowed2=None if allowed2.all() else allowed2,
                     point1=point1 if np.isfinite(point1).any() else None)
