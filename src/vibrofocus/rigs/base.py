"""The rig interface every backend implements (simulated, audio, NI-DAQmx).

In the way nidaqmx separates its public API from interchangeable interpreters, the
public methods here (``play``, ``play_and_record``, ``stop``) are final: they run the
safety layer and guarantee zero outputs afterwards, then hand a checked drive to the
backend's private ``_play`` / ``_play_and_record`` / ``_zero_outputs``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from .._validation import as_array, check_positive
from ..defaults import FS_HZ
from ..errors import ValidationError
from ..layout import ArrayLayout
from .safety import SafetyLimits, check_drive

__all__ = ["Rig"]


class Rig(ABC):
    """A rig: actuators to play drives and (optionally) a sensor to record the skin.

    Parameters
    ----------
    layout : ArrayLayout, optional
        The array; default the reference setup.
    fs : float
        Sample rate of drives and recordings, Hz.
    limits : SafetyLimits, optional
        Limits at the actuator; default ``SafetyLimits()``.

    Notes
    -----
    ``max_points_per_recording`` is the number of skin points one recording can cover:
    1 for a single-spot vibrometer (the operator aims it between recordings), ``None``
    for a rig that can measure anywhere at once, such as the simulated forearm.
    """

    #: Short identifier used by ``--rig``.
    kind: str = "abstract"
    #: Points one recording can cover; None means any number.
    max_points_per_recording: int | None = 1

    def __init__(self, layout: ArrayLayout | None = None, fs: float = FS_HZ, limits: SafetyLimits | None = None):
        self.layout = layout if layout is not None else ArrayLayout.reference()
        self.fs = check_positive(fs, "fs")
        self.limits = limits if limits is not None else SafetyLimits()

    # ------------------------------------------------------------------ public, final
    def check(self, drive: np.ndarray) -> np.ndarray:
        """Run the safety layer on ``drive`` without playing it; return what would play."""
        return check_drive(drive, self.fs, self.layout.n_actuators, self.limits)

    def play(self, drive: np.ndarray) -> None:
        """Play a drive on the actuators (participant stimulation).

        Parameters
        ----------
        drive : ndarray, shape (n_actuators, n_samples)
            Voltages at the actuators, V.

        Raises
        ------
        SafetyError
            Before anything is played, if the drive breaks a limit.
        """
        safe = self.check(drive)
        self._run_guarded(self._play, safe)

    def play_and_record(
        self, drive: np.ndarray, points_xy: np.ndarray | None = None, *, tail_s: float = 0.05
    ) -> np.ndarray:
        """Play a drive and record skin displacement, sample-synchronously.

        Parameters
        ----------
        drive : ndarray, shape (n_actuators, n_samples)
            Voltages at the actuators, V.
        points_xy : ndarray, shape (n_points, 2), optional
            Where to measure, m. A single-spot rig measures where its sensor is aimed and
            accepts at most one point (used as a label only); ``None`` means that spot.
        tail_s : float
            Recording continues this long after the drive ends, s, to catch the decay.

        Returns
        -------
        ndarray, shape (n_points, n_samples + round(tail_s * fs))
            Displacement, m.
        """
        safe = self.check(drive)
        n_tail = int(round(check_positive(tail_s, "tail_s", allow_zero=True) * self.fs))
        if points_xy is not None:
            points_xy = as_array(points_xy, "points_xy", ndim=2, shape=(None, 2))
            limit = self.max_points_per_recording
            if limit is not None and len(points_xy) > limit:
                raise ValidationError(
                    f"points_xy asks for {len(points_xy)} points, but the {self.kind} rig records "
                    f"{limit} point(s) per recording; record them one at a time"
                )
        out = self._run_guarded(self._play_and_record, safe, points_xy, n_tail)
        return np.asarray(out, dtype=float)

    def stop(self) -> None:
        """Stop at once and leave every output at zero."""
        self._zero_outputs()

    def close(self) -> None:
        """Release the device (outputs left at zero)."""
        self.stop()

    def __enter__(self) -> "Rig":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def describe(self) -> dict:
        """Settings to store beside a calibration or a session (JSON-serialisable)."""
        return {"kind": self.kind, "fs": self.fs, "limits": self.limits.to_dict(), "layout": self.layout.to_dict()}

    # ------------------------------------------------------------------ backend
    def _run_guarded(self, func, *args):
        # Outputs go to zero whatever happens, including KeyboardInterrupt mid-play.
        try:
            return func(*args)
        finally:
            self._zero_outputs()

    @abstractmethod
    def _play(self, drive: np.ndarray) -> None:
        """Play a drive that has passed the safety layer."""

    @abstractmethod
    def _play_and_record(self, drive: np.ndarray, points_xy: np.ndarray | None, n_tail: int) -> np.ndarray:
        """Play a checked drive and return displacement, shape (n_points, n_samples + n_tail), m."""

    @abstractmethod
    def _zero_outputs(self) -> None:
        """Set every output to zero volts now."""
