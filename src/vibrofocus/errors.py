"""Exception types raised by vibrofocus.

Every error a user can trigger derives from :class:`VibrofocusError`, so callers (the
CLI, the web app) can turn them into clear messages without catching programming bugs.
"""

from __future__ import annotations

__all__ = [
    "VibrofocusError",
    "ValidationError",
    "SafetyError",
    "DriveLimitError",
    "CausalityError",
    "CalibrationFileError",
    "StudyError",
]


class VibrofocusError(Exception):
    """Base class of all errors vibrofocus raises on purpose."""


class ValidationError(VibrofocusError, ValueError):
    """An argument has the wrong shape, type, value range or contains NaN/Inf."""


class SafetyError(VibrofocusError):
    """A drive was refused before reaching any actuator (limits, NaN/Inf, duration)."""


class DriveLimitError(SafetyError):
    """A design needs more than the drive limit and the caller asked to refuse it."""


class CausalityError(VibrofocusError):
    """The design window is too short: the drive would wrap around in time."""


class CalibrationFileError(VibrofocusError):
    """A calibration file is missing, truncated, foreign or fails validation."""


class StudyError(VibrofocusError):
    """A study request is invalid: unknown participant/session, bad answer, ..."""
