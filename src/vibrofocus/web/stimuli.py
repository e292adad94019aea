"""Renderings of a calibration, computed once per (method, location) and reused.

A study plays each of its 27 conditions several times; rendering is deterministic for a
given calibration, so the web app renders each condition on first use and keeps it.
"""

from __future__ import annotations

import threading
from typing import Any

from ..defaults import N_SAMPLES

__all__ = ["StimulusBank"]


class StimulusBank:
    """Render and cache the stimuli of one calibration.

    Parameters
    ----------
    calibration : Calibration
        From :func:`vibrofocus.calibration.calibrate` or ``load_calibration``.
    limit_v : float, optional
        Drive limit passed to the renderer, V (the rig's limit).
    n_samples : int
        Rendering window, samples.
    """

    def __init__(self, calibration: Any, *, limit_v: float | None = None, n_samples: int = N_SAMPLES) -> None:
        self.calibration = calibration
        self.limit_v = limit_v
        self.n_samples = int(n_samples)
        self._lock = threading.Lock()
        self._cache: dict[tuple[str, int], Any] = {}
        self._H = None

    def rendering(self, method: str, location: int) -> Any:
        """The :class:`~vibrofocus.rendering.Rendering` of ``method`` at location number ``location``."""
        from ..rendering import render  # imported here: the web app starts without rendering

        key = (str(method), int(location))
        with self._lock:
            if key in self._cache:
                return self._cache[key]
            if self._H is None:
                self._H = self.calibration.transfer_for(self.n_samples)
            kwargs: dict[str, Any] = {}
            if self.limit_v is not None:
                kwargs["limit_v"] = self.limit_v
            cal = self.calibration
            result = render(key[0], self._H, cal.fs, cal.layout, key[1], **kwargs)
            self._cache[key] = result
            return result

    def drives_for(self, trial: Any):
        """Drives of a planned trial, shape (n_actuators, n_samples), V."""
        return self.rendering(trial.method, trial.target).drives
