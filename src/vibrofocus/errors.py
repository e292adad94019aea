"""Exception types raised by vibrofocus.

Every error a user can trigger derives from :class:`VibrofocusError`, so callers (the
CLI, the web app) can turn them into clear messages without catching programming bugs.
"""

from __future__ import annotations

__all__ = [
    "VibrofocusError",
    "ValidationError",
    "InfeasibleDesignError",
    "SafetyError",
    "CoolingError",
    "DriveLimitError",
    "CausalityError",
    "CalibrationFileError",
    "StudyError",
    "AnswerRefused",
    "OutputError",
]


class VibrofocusError(Exception):
    """Base class of all errors vibrofocus raises on purpose."""


class ValidationError(VibrofocusError, ValueError):
    """An argument has the wrong shape, type, value range or contains NaN/Inf."""


class InfeasibleDesignError(ValidationError):
    """A constrained design has no solution (a fidelity out of reach, a drive limit too
    tight): relax a constraint. Callers that relax and retry catch this type."""


class SafetyError(VibrofocusError):
    """A drive was refused before reaching any actuator (limits, NaN/Inf, duration)."""


class CoolingError(SafetyError):
    """A drive refused by a limit over time (the energy budget) that a wait would lift.

    Attributes
    ----------
    wait_s : float
        A wait after which the same drive is admitted, s.
    """

    def __init__(self, message: str, wait_s: float) -> None:
        super().__init__(message)
        self.wait_s = float(wait_s)


class DriveLimitError(SafetyError):
    """A design needs more than the drive limit and the caller asked to refuse it."""


class CausalityError(VibrofocusError):
    """The design window is too short: the drive would wrap around in time."""


class CalibrationFileError(VibrofocusError):
    """A calibration file is missing, truncated, foreign or fails validation."""


class StudyError(VibrofocusError):
    """A study request is invalid: unknown participant/session, bad answer, ..."""


class AnswerRefused(StudyError):
    """An answer the study database refused to store; nothing was written.

    Attributes
    ----------
    reason : str
        Which rule refused it, so that a caller can word it for its audience (the
        participant page says "already answered" for ``answered``): ``invalid`` (the
        response, reaction time or answer id is malformed), ``unknown_trial`` (the
        session has no such trial), ``answered`` (the trial already has another answer,
        or this answer id another response), ``reused_id`` (the answer id was used for
        another trial), ``not_current`` (not the session's first unanswered trial:
        answers come in trial order) or ``not_presented`` (no stimulus onset is logged
        for the trial, and the caller asked for one).
    """

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


class OutputError(VibrofocusError):
    """An output file or folder cannot be written: no space, no permission, read-only.

    Raised instead of a bare :class:`OSError` by every writer of vibrofocus (see
    :mod:`vibrofocus._atomic`); the previous file under the target name is left untouched.

    Attributes
    ----------
    errno : int or None
        The ``errno`` of the underlying :class:`OSError` (``None`` when the problem was
        found before writing, e.g. too little free space).
    path : str or None
        The file or folder concerned.
    """

    def __init__(self, message: str, *, errno: int | None = None, path: str | None = None) -> None:
        super().__init__(message)
        self.errno = errno
        self.path = path
