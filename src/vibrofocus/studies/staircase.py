"""A 1-up-2-down staircase for a participant's detection threshold (docs/protocols.md, "Threshold blocks").

The staircase is a pure function of the answers so far (:meth:`Staircase.run`): a session
that stops and resumes, a replay for the export and a simulated participant all find the
same levels from the same answers, and nothing but the answers needs storing. Its rule is
PsychoPy's ``StairHandler`` with ``stepType="lin"`` on levels in dB, ``nUp=1, nDown=2``
and its initial rule (1-up-1-down until the first reversal); tests/studies/test_staircase.py
checks the two give the same levels. It converges on the level felt on 70.7 % of trials
(Levitt 1971).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from .._validation import shorten
from ..errors import StudyError

__all__ = ["Staircase", "StaircaseRun", "MIN_REVERSALS", "DISCARDED_REVERSALS", "DETECTION_ANSWERS",
           "parse_detection"]

#: Reversals a staircase needs for a threshold; fewer: no threshold (the block was too short).
MIN_REVERSALS = 6
#: Reversals left out of the threshold's mean: the first ones, from the starting level's approach.
DISCARDED_REVERSALS = 2
#: A detection answer as stored (``response``): 1 felt, 0 not felt.
DETECTION_ANSWERS = (0, 1)


@dataclass(frozen=True)
class StaircaseRun:
    """The levels a staircase played and what it found.

    Attributes
    ----------
    levels_db : tuple of float
        The level of each trial answered, dB re the level rule, then the next trial's.
    reversals_db : tuple of float
        The levels at which the direction reversed, dB.
    reversal_trials : tuple of int
        0-based staircase trial of each reversal.
    threshold_db : float or None
        Mean of the reversal levels after the first :data:`DISCARDED_REVERSALS`, dB re the
        level rule; None with fewer than :data:`MIN_REVERSALS` reversals.
    """

    levels_db: tuple[float, ...]
    reversals_db: tuple[float, ...]
    reversal_trials: tuple[int, ...]
    threshold_db: float | None

    @property
    def next_db(self) -> float:
        """The level of the next trial, dB."""
        return self.levels_db[-1]


@dataclass(frozen=True)
class Staircase:
    """A 1-up-2-down staircase on levels in dB re a level rule.

    Parameters
    ----------
    start_db : float
        First level, dB re the level rule (well above threshold: the initial rule walks down
        one step per felt tap until the first miss).
    steps_db : tuple of float
        Step sizes, dB: ``steps_db[k]`` after ``k`` reversals, the last one thereafter
        (default 4 dB, then 2 dB).
    max_db : float
        Highest level played, dB re the level rule (default 0: the rule's own level, within
        the drive limit); a higher one is checked against the drive limit when planned.
    min_db : float
        Lowest level played, dB (default -60).
    """

    start_db: float
    steps_db: tuple[float, ...] = (4.0, 2.0)
    max_db: float = 0.0
    min_db: float = -60.0

    def __post_init__(self) -> None:
        for name in ("start_db", "max_db", "min_db"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or abs(value) > 120.0:
                raise StudyError(f"staircase {name} must be a finite number within +-120 dB, got {shorten(value)}")
            object.__setattr__(self, name, float(value))
        steps = tuple(self.steps_db)
        if not steps or len(steps) > 16 or any(isinstance(s, bool) or not isinstance(s, (int, float))
                                               or not math.isfinite(s) or not 0.0 < s <= 40.0 for s in steps):
            raise StudyError(f"staircase steps_db must be 1-16 steps in (0, 40] dB, got {shorten(steps)}")
        object.__setattr__(self, "steps_db", tuple(float(s) for s in steps))
        if not self.min_db <= self.start_db <= self.max_db:
            raise StudyError(f"staircase start_db {self.start_db:g} must lie within min_db {self.min_db:g} and "
                             f"max_db {self.max_db:g}")

    def to_dict(self) -> dict[str, Any]:
        """JSON form (stored in a threshold session's config)."""
        return {"start_db": self.start_db, "steps_db": list(self.steps_db), "max_db": self.max_db,
                "min_db": self.min_db}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Staircase":
        """The staircase of :meth:`to_dict`'s form."""
        if not isinstance(data, Mapping):
            raise StudyError(f"a staircase is a table of start_db, steps_db, max_db, min_db, got {shorten(data)}")
        unknown = set(data) - {"start_db", "steps_db", "max_db", "min_db"}
        if unknown:
            raise StudyError(f"unknown staircase key(s): {', '.join(sorted(map(str, unknown)))}")
        if "start_db" not in data:
            raise StudyError("a staircase needs start_db")
        return cls(**{k: (tuple(v) if k == "steps_db" else v) for k, v in data.items()})

    def run(self, felt: Iterable[Any]) -> StaircaseRun:
        """Replay the staircase over the answers so far.

        Parameters
        ----------
        felt : iterable of bool or {0, 1}
            Whether each trial's tap was felt, in order.

        Returns
        -------
        StaircaseRun
            ``levels_db`` has one level more than the answers: the next trial's.
        """
        level = self.start_db
        step = self.steps_db[0]
        levels = [level]
        reversals: list[float] = []
        reversal_trials: list[int] = []
        direction = "start"
        counter = 0
        previous: int | None = None
        initial = False
        for k, answer in enumerate(felt):
            result = _detection(answer)
            # PsychoPy's StairHandler.addResponse: runs of equal answers count on.
            if result == 1:
                counter = counter + 1 if previous == 1 else 1
            else:
                counter = counter - 1 if previous == 0 else -1
            previous = result
            if not reversals:  # the initial rule: 1-up-1-down until the first reversal
                reversal = direction == ("up" if result == 1 else "down")
                direction = "down" if result == 1 else "up"
            elif counter >= 2:
                reversal = direction not in ("start", "down")
                direction = "down"
            elif counter <= -1:
                reversal = direction not in ("start", "up")
                direction = "up"
            else:
                reversal = False
            if reversal:
                if not reversals:
                    initial = True
                reversals.append(levels[-1])
                reversal_trials.append(k)
                step = self.steps_db[min(len(reversals), len(self.steps_db) - 1)]
            if not reversals or initial:
                initial = False
                level = level - step if result == 1 else level + step
                counter = 0
            elif counter >= 2:
                level, counter = level - step, 0
            elif counter <= -1:
                level, counter = level + step, 0
            level = min(max(level, self.min_db), self.max_db)
            levels.append(level)
        usable = reversals[DISCARDED_REVERSALS:]
        threshold = sum(usable) / len(usable) if len(reversals) >= MIN_REVERSALS else None
        return StaircaseRun(tuple(levels), tuple(reversals), tuple(reversal_trials), threshold)

    def level_of(self, felt: Sequence[Any]) -> float:
        """The level of the trial after the answers ``felt``, dB re the level rule."""
        return self.run(felt).next_db


def parse_detection(answer: Any) -> int:
    """A detection answer as stored: 1 (felt) or 0 (not felt).

    Parameters
    ----------
    answer : bool, int, str or one-item sequence
        ``1``/``0``, ``True``/``False``, ``"yes"``/``"no"``, ``"felt"``/``"not felt"``, ``[1]``.

    Returns
    -------
    int
    """
    if isinstance(answer, str):
        text = answer.strip().lower()
        answer = {"1": 1, "yes": 1, "y": 1, "felt": 1, "0": 0, "no": 0, "n": 0, "not felt": 0}.get(text, answer)
    return _detection(answer)


def _detection(answer: Any) -> int:
    """1 (felt) or 0 (not felt) from a stored or given detection answer."""
    if isinstance(answer, (tuple, list)) and len(answer) == 1:
        answer = answer[0]
    if isinstance(answer, bool):
        return int(answer)
    if isinstance(answer, int) and answer in DETECTION_ANSWERS:
        return answer
    raise StudyError(f"a detection answer is 1 (felt) or 0 (not felt), got {shorten(answer)}")
