"""What a calibration measured: :class:`Calibration` (the transfer matrix and its record)."""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import ValidationError
from ..io.calibration_nc import SCHEMA_VERSION
from ..layout import ArrayLayout
from ..signals.taper import band_taper
from .estimate import resize_impulse_response
from .excitation import SweepSettings
from .quality import QualityReport

__all__ = ["Calibration"]

@dataclass(eq=False)
class Calibration:
    """A measured transfer matrix with everything needed to trust and reproduce it.

    Attributes
    ----------
    H : ndarray, complex, shape (n_freqs, n_points, n_actuators)
        Transfer matrix, m/V, on ``freqs``; point ``i`` is ``layout.points_xy[i]``.
    freqs : ndarray, shape (n_freqs,)
        ``numpy.fft.rfftfreq(n_fft, 1 / fs)``, Hz.
    fs : float
        Sample rate, Hz.
    coherence : ndarray, shape (n_freqs, n_points, n_actuators)
        Coherence over repeats, in [0, 1]; NaN where not assessable (one repeat). For
        ``mimo`` the partial coherence of each actuator given the others
        (:class:`.estimate.MimoEstimate`); NaN with no more takes than actuators.
    layout : ArrayLayout
        The actuators and points calibrated.
    band : (float, float)
        Calibrated band, Hz; outside it ``H`` is not to be trusted.
    participant_id : str
    method : {"h1", "paper", "mimo"}
    quality : QualityReport
    drives : ndarray, shape (n_actuators, n_drive)
        Voltage on actuator ``a``'s channel while ``a`` was measured (all other channels
        were zero), as played after the rig's fades, V. For ``mimo``, every take played
        ``codes[r, a] * drives[a]`` on every actuator ``a`` at once.
    recordings : ndarray, float32
        Raw displacement, m; NaN marks a dropout. Shape (n_actuators, n_repeats,
        n_points, n_rec) for ``h1``/``paper`` (one actuator per take); (n_repeats,
        n_points, n_rec) for ``mimo`` (all actuators in every take). Stored in single
        precision (about 0.1 ppm of the signal, far below sensor noise).
    rig : dict
        ``rig.describe()`` at calibration time.
    straps : dict or None
        Strap force reading taken just before the sweeps (``StrapReading.to_dict()``:
        forces in N against the 1 N target), for rigs with strap sensors; else None.
    sweep : SweepSettings
    created : str
        ISO 8601 time (UTC) of the calibration.
    software_version : str
        ``vibrofocus.__version__`` that measured it.
    schema_version : int
    codes : ndarray of int8, shape (n_repeats, n_actuators), or None
        ``mimo`` only: the sign of each actuator's sweep in each take
        (:func:`.excitation.hadamard_codes`).
    multiple_coherence : ndarray, shape (n_freqs, n_points), or None
        ``mimo`` only: share of each point's response the actuators together explain,
        in [0, 1] (NaN where not assessable); pure noise gives ``n_actuators / n_repeats``.
    recorded_s : float
        Real duration of the takes recorded, re-recordings included, s (NaN when not
        known, e.g. a file written before it was stored).
    fit : FittedSkin or None
        The skin model fitted to ``H`` (``cal.fit = fit_model(cal)``), stored with the
        calibration file when set; None otherwise.
    measured : ndarray of bool, shape (n_points,), or None
        Which rows of ``H`` were measured; False where ``H`` was predicted by ``fit``
        (``calibrate(..., measure=K)``). None: every row measured.
    """

    H: np.ndarray
    freqs: np.ndarray
    fs: float
    coherence: np.ndarray
    layout: ArrayLayout
    band: tuple[float, float]
    participant_id: str
    method: str
    quality: QualityReport
    drives: np.ndarray
    recordings: np.ndarray
    rig: dict
    sweep: SweepSettings
    created: str = field(default_factory=lambda: _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"))
    software_version: str = field(default_factory=lambda: _software_version())
    schema_version: int = SCHEMA_VERSION
    straps: dict | None = None
    codes: np.ndarray | None = None
    multiple_coherence: np.ndarray | None = None
    recorded_s: float = float("nan")
    fit: Any = None
    measured: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.measured is not None:
            m = np.asarray(self.measured)
            if m.dtype != bool or m.shape != (np.shape(self.H)[1],):
                raise ValidationError(f"measured must be a bool array of one flag per point ({np.shape(self.H)[1]}), "
                                      f"got {m.dtype} of shape {m.shape}")
            if not m.all() and self.fit is None:
                raise ValidationError("measured marks predicted points, but fit (the model that predicted them) "
                                      "is None")
            self.measured = m.copy()

    @property
    def measured_points(self) -> np.ndarray:
        """ndarray of bool, shape (n_points,): True where ``H`` was measured (all when
        :attr:`measured` is None)."""
        return np.ones(self.n_points, bool) if self.measured is None else self.measured.copy()

    @property
    def predicted_points(self) -> np.ndarray:
        """ndarray of int: indices of the points whose ``H`` the fitted model predicted."""
        return np.flatnonzero(~self.measured_points)

    @property
    def n_fft(self) -> int:
        """Length of the time window whose real-FFT grid ``freqs`` is."""
        return 2 * (len(self.freqs) - 1)

    @property
    def n_points(self) -> int:
        return self.H.shape[1]

    @property
    def n_actuators(self) -> int:
        return self.H.shape[2]

    def impulse_responses(self) -> np.ndarray:
        """Impulse responses of ``H``, m/V per sample, time zero at index 0 (negative times
        wrap to the end), shape (n_points, n_actuators, n_fft)."""
        return np.fft.irfft(np.moveaxis(self.H, 0, -1), self.n_fft, axis=-1)

    def wraparound_check(self, n: int, *, taper_octaves: float = 0.5):
        """The :class:`~vibrofocus.rendering.WraparoundCheck` of ``transfer_for(n)``, built
        once per ``(n, taper_octaves)`` and kept: its ``H`` is the design's transfer matrix
        and the spectra it caches make every later check of a design cheap."""
        from ..rendering.causality import WraparoundCheck

        cache = self.__dict__.setdefault("_wraparound_checks", {})
        key = (n, float(taper_octaves))
        if key not in cache:
            cache[key] = WraparoundCheck(self.transfer_for(n, taper_octaves=taper_octaves), n)
        return cache[key]

    def transfer_matrix(self, n_samples: int | None = None):
        """The :class:`~vibrofocus.rendering.TransferMatrix` of ``transfer_for(n_samples)``
        (default 4096), with the calibrated band, the coherence and the provenance (rig,
        participant, skin preset); it shares this calibration's kept wrap-around check.

        Parameters
        ----------
        n_samples : int, optional
            Design window, samples (even, >= 16).

        Returns
        -------
        TransferMatrix
        """
        from ..rendering.transfer import TransferMatrix

        return TransferMatrix.from_calibration(self, n_samples)

    def transfer_for(self, n: int, *, taper_octaves: float = 0.5) -> np.ndarray:
        """The transfer matrix on the design grid ``rfftfreq(n, 1 / fs)``.

        The stored ``H`` (on ``rfftfreq(n_fft, 1/fs)``) is taken to the time domain; its
        impulse responses are zero-padded (``n > n_fft``) or cut with half-Hann fades
        (``n < n_fft``), keeping the causal part at the start and a short acausal part
        (1/16 of the window) at the end (:func:`.estimate.resize_impulse_response`), and
        transformed back. Outside the calibrated band, where nothing was measured
        reliably, the values are tapered to zero with a raised cosine over
        ``taper_octaves`` octaves beyond each band edge (the designs band-limit to the
        calibrated band anyway, with the same half-octave taper by default); beyond the
        taper they are exactly zero.

        Parameters
        ----------
        n : int
            Window length, samples (even, >= 16).
        taper_octaves : float
            Width of the out-of-band taper, octaves.

        Returns
        -------
        ndarray, complex, shape (n // 2 + 1, n_points, n_actuators)
            m/V.
        """
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 16 or n % 2:
            raise ValidationError(f"n must be an even integer >= 16 (samples), got {n!r}")
        n = int(n)
        if n == self.n_fft:
            H = self.H.copy()
        else:
            h = resize_impulse_response(self.impulse_responses(), n)
            H = np.moveaxis(np.fft.rfft(h, axis=-1), -1, 0)
        freqs = np.fft.rfftfreq(n, 1 / self.fs)
        with np.errstate(over="ignore", divide="ignore"):  # band_taper at 0 Hz
            taper = band_taper(freqs, self.band, taper_octaves)
        return H * taper[:, None, None]

    def summary_table(self, title: str | None = None):
        """Rich table with a verdict per point and actuator (see :class:`QualityReport`)."""
        title = title or f"Calibration of {self.participant_id} ({self.method}, {self.band[0]:g}-{self.band[1]:g} Hz)"
        return self.quality.table(self.layout, title=title)

    def __repr__(self) -> str:
        return (
            f"Calibration(participant_id={self.participant_id!r}, method={self.method!r}, "
            f"n_points={self.n_points}, n_actuators={self.n_actuators}, n_fft={self.n_fft}, "
            f"fs={self.fs:g}, band={self.band}, quality_ok={self.quality.ok})"
        )


def _software_version() -> str:
    from .. import __version__

    return __version__
