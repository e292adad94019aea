"""The calibration record: what one calibration file holds, as typed, frozen dataclasses.

:class:`CalibrationFileRecord` is what :func:`~vibrofocus.io.calibration_nc.read_calibration_file`
returns and :func:`~vibrofocus.io.calibration_nc.write_calibration_file` takes: arrays,
numbers, strings and JSON-like dicts, never a domain object (the
:class:`~vibrofocus.calibration.Calibration` is built from it one floor up). Its quality
figures are a :class:`QualityRecord`, its skin-model fit a :class:`FitRecord`. Each checks
itself when made (``__post_init__``): the one place where a record's consistency (shapes,
band, frequency grid, value ranges) is validated, for the file read and the file written
alike. The file layout is in docs/file-formats.md, "Calibration file".
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import MISSING, dataclass, fields
from typing import Any

import numpy as np

from ..errors import ValidationError

__all__ = ["CalibrationFileRecord", "QualityRecord", "FitRecord", "RECORD_KEYS"]

#: The calibration methods a file may hold (``mimo``: all actuators in every take).
METHODS = ("h1", "paper", "mimo")


def _shape(value: Any, name: str, shape: tuple[int, ...]) -> None:
    if np.shape(value) != shape:
        raise ValidationError(f"{name} must have shape {shape}, got {np.shape(value)}")


def _unit_interval(values: np.ndarray, name: str) -> None:
    """Refuse finite values outside [0, 1] (NaN: not assessable, allowed)."""
    arr = np.asarray(values, float)
    finite = arr[np.isfinite(arr)]
    if (finite < -1e-9).any() or (finite > 1 + 1e-9).any():
        raise ValidationError(f"variable {name} holds values outside [0, 1]")


@dataclass(frozen=True, eq=False, kw_only=True)
class QualityRecord:
    """A calibration's quality figures as stored (named as :class:`~vibrofocus.calibration.QualityReport`'s).

    Attributes
    ----------
    issues : list of dict
        The quality issues (``QualityIssue.to_dict()``).
    thresholds : dict
        The thresholds judged against (``QualityThresholds.to_dict()``).
    snr_db, noise_rms_m, band_gain, low_coherence_share, coherent_to_hz : ndarray, shape (n_points, n_actuators)
        In-band SNR (dB), noise floor (m), RMS of ``|H|`` over the band (m/V), share of
        band frequencies with low coherence (1), coherent up to (Hz).
    clipped : ndarray of bool, shape (n_points, n_actuators)
    repeats_used, dropouts : ndarray of int, shape (n_points, n_actuators)
    polarity : ndarray of int, shape (n_actuators,)
        +1/-1, 0 where not judged.
    input_condition, input_correlation : ndarray, shape (n_freqs, n_points), or None
        ``mimo`` only.
    """

    issues: list[dict[str, Any]]
    thresholds: dict[str, Any]
    snr_db: np.ndarray
    noise_rms_m: np.ndarray
    band_gain: np.ndarray
    low_coherence_share: np.ndarray
    coherent_to_hz: np.ndarray
    clipped: np.ndarray
    repeats_used: np.ndarray
    dropouts: np.ndarray
    polarity: np.ndarray
    input_condition: np.ndarray | None = None
    input_correlation: np.ndarray | None = None

    #: The (n_points, n_actuators) figures.
    PAIR_FIGURES = ("snr_db", "noise_rms_m", "band_gain", "low_coherence_share", "coherent_to_hz", "clipped",
                    "repeats_used", "dropouts")

    def __post_init__(self) -> None:
        if not isinstance(self.issues, list) or not all(isinstance(i, Mapping) for i in self.issues):
            raise ValidationError(f"quality issues must be a list of dicts, got {type(self.issues).__name__}")
        if not isinstance(self.thresholds, Mapping):
            raise ValidationError(f"quality thresholds must be a dict, got {type(self.thresholds).__name__}")
        shape = np.shape(self.snr_db)
        if len(shape) != 2:
            raise ValidationError(f"quality snr_db must have shape (n_points, n_actuators), got {shape}")
        for name in self.PAIR_FIGURES:
            _shape(getattr(self, name), f"quality {name}", shape)
        _shape(self.polarity, "quality polarity", shape[1:])

    @classmethod
    def from_mapping(cls, quality: Mapping[str, Any]) -> QualityRecord:
        """A record from a mapping with these fields as keys (a dict of an older caller)."""
        return quality if isinstance(quality, QualityRecord) else cls(**_known(cls, quality, "quality"))


@dataclass(frozen=True, eq=False, kw_only=True)
class FitRecord:
    """A skin-model fit as stored (:class:`~vibrofocus.calibration.FittedSkin`'s data).

    Attributes
    ----------
    names : tuple of str
        The model's parameter names.
    values : ndarray, shape (n_params,)
        The fitted values, SI units.
    std : ndarray, shape (n_params,), or None
        Their standard errors.
    log_covariance : ndarray, shape (n_params, n_params)
        Covariance of the parameters' natural logarithms.
    residual : ndarray, shape (n_points,)
        Relative fit residual per point.
    band : (float, float)
        The band fitted, Hz.
    fs : float
        Sample rate, Hz.
    fixed, info : dict
        The settings held fixed (``law`` among them) and the fit's diagnostics.
    """

    names: tuple[str, ...]
    values: np.ndarray
    std: np.ndarray | None
    log_covariance: np.ndarray
    residual: np.ndarray
    band: tuple[float, float]
    fs: float
    fixed: dict[str, Any]
    info: dict[str, Any]

    def __post_init__(self) -> None:
        object.__setattr__(self, "names", tuple(str(n) for n in self.names))
        object.__setattr__(self, "band", tuple(self.band))
        n = len(self.names)
        _shape(self.values, "fit values", (n,))
        if self.std is not None:
            _shape(self.std, "fit std", (n,))
        _shape(self.log_covariance, "fit log_covariance", (n, n))
        if np.ndim(self.residual) != 1:
            raise ValidationError(f"fit residual must be one value per point, got shape {np.shape(self.residual)}")

    @classmethod
    def from_mapping(cls, fit: Mapping[str, Any] | None) -> FitRecord | None:
        """A record from a mapping with these fields as keys, or None for None."""
        if fit is None or isinstance(fit, FitRecord):
            return fit
        return cls(**_known(cls, fit, "fit"))


def _known(cls, mapping: Mapping[str, Any], what: str) -> dict[str, Any]:
    """The mapping's items, refusing a key that is not one of ``cls``'s fields (naming the valid ones)."""
    if not isinstance(mapping, Mapping):
        raise ValidationError(f"a {what} record must be a mapping, got {type(mapping).__name__}")
    names = [f.name for f in fields(cls)]
    unknown = sorted(set(mapping) - set(names))
    if unknown:
        raise ValidationError(f"unknown {what} record key(s) {', '.join(unknown)}; valid: {', '.join(names)}")
    missing = [f.name for f in fields(cls) if f.name not in mapping and f.default is MISSING]
    if missing:
        raise ValidationError(f"a {what} record lacks the key(s) {', '.join(missing)}")
    return dict(mapping)


@dataclass(frozen=True, eq=False, kw_only=True)
class CalibrationFileRecord:
    """Everything one calibration file holds (docs/file-formats.md, "Calibration file").

    Attributes
    ----------
    H : ndarray, complex, shape (n_freqs, n_points, n_actuators)
        Transfer matrix, m/V.
    freqs : ndarray, shape (n_freqs,)
        ``numpy.fft.rfftfreq(n_fft, 1 / fs)``, Hz.
    coherence : ndarray, shape (n_freqs, n_points, n_actuators)
        In [0, 1]; NaN where not assessable.
    drives : ndarray, shape (n_actuators, n_drive)
        V.
    recordings : ndarray
        m; (n_actuators, n_repeats, n_points, n_rec), or (n_takes, n_points, n_rec) for ``mimo``.
    fs : float
        Sample rate, Hz.
    band : (float, float)
        Calibrated band, Hz: ``0 < low < high <= fs / 2``.
    n_fft : int
        FFT length of ``H``.
    method : {"h1", "paper", "mimo"}
    participant_id, created, software_version : str
    schema_version : int
        The file's layout version (the reader's; the writer writes the current one).
    layout : dict
        :meth:`~vibrofocus.layout.ArrayLayout.to_dict`.
    point_labels : list of str
    point_kinds : list of str, or None
        ``"location"`` / ``"guard"`` per point.
    actuator_names : list of str
    points_xy : ndarray, shape (n_points, 2)
        m.
    actuators_xy : ndarray, shape (n_actuators, 2)
        m.
    rig, sweep : dict
        ``rig.describe()`` and the sweep settings.
    quality : QualityRecord
    codes : ndarray of int8, shape (n_takes, n_actuators), or None
        ``mimo`` only: +1/-1.
    multiple_coherence : ndarray, shape (n_freqs, n_points), or None
        ``mimo`` only, in [0, 1].
    straps : dict or None
        The strap force reading.
    recorded_s : float
        s; NaN when not known.
    fit : FitRecord or None
    measured : ndarray of bool, shape (n_points,), or None
        None: every row of ``H`` measured; False where the fit predicted it.

    Raises
    ------
    ValidationError
        When made from inconsistent parts (the message names the part).
    """

    H: np.ndarray
    freqs: np.ndarray
    coherence: np.ndarray
    drives: np.ndarray
    recordings: np.ndarray
    fs: float
    band: tuple[float, float]
    n_fft: int
    method: str
    participant_id: str
    created: str
    software_version: str
    schema_version: int
    layout: dict[str, Any]
    point_labels: list[str]
    point_kinds: list[str] | None
    actuator_names: list[str]
    points_xy: np.ndarray
    actuators_xy: np.ndarray
    rig: dict[str, Any]
    sweep: dict[str, Any]
    quality: QualityRecord
    codes: np.ndarray | None = None
    multiple_coherence: np.ndarray | None = None
    straps: dict[str, Any] | None = None
    recorded_s: float = float("nan")
    fit: FitRecord | None = None
    measured: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.quality, QualityRecord):
            object.__setattr__(self, "quality", QualityRecord.from_mapping(self.quality))
        object.__setattr__(self, "fit", FitRecord.from_mapping(self.fit))
        if self.method not in METHODS:
            raise ValidationError(f"method must be one of {', '.join(METHODS)}, got {self.method!r}")
        fs = float(self.fs)
        if not np.isfinite(fs) or fs <= 0:
            raise ValidationError(f"invalid sample rate fs={self.fs!r}")
        low, high = (float(b) for b in self.band)
        if not 0 < low < high <= fs / 2:
            raise ValidationError(f"invalid band {low:g}-{high:g} Hz (needs 0 < low < high <= fs/2 = {fs / 2:g} Hz)")
        if isinstance(self.n_fft, bool) or not float(self.n_fft).is_integer() or self.n_fft < 2:
            raise ValidationError(f"n_fft must be an integer >= 2, got {self.n_fft!r}")
        for name in ("fs", "recorded_s"):
            object.__setattr__(self, name, float(getattr(self, name)))
        object.__setattr__(self, "band", (low, high))
        object.__setattr__(self, "n_fft", int(self.n_fft))
        self._check_shapes()
        self._check_values()

    def _check_shapes(self) -> None:
        if np.ndim(self.H) != 3:
            raise ValidationError(f"H must have shape (n_freqs, n_points, n_actuators), got {np.shape(self.H)}")
        n_f, n_p, n_a = np.shape(self.H)
        if n_f != self.n_fft // 2 + 1:
            raise ValidationError(f"{n_f} frequencies but n_fft={self.n_fft} needs {self.n_fft // 2 + 1}")
        _shape(self.freqs, "freqs", (n_f,))
        if not np.allclose(self.freqs, np.fft.rfftfreq(self.n_fft, 1 / self.fs), rtol=1e-9, atol=1e-9):
            raise ValidationError(f"the frequency axis is not rfftfreq({self.n_fft}, 1/{self.fs:g})")
        _shape(self.coherence, "coherence", (n_f, n_p, n_a))
        _shape(self.point_labels, "point_labels", (n_p,))
        if self.point_kinds is not None:
            _shape(self.point_kinds, "point_kinds", (n_p,))
        _shape(self.points_xy, "points_xy", (n_p, 2))
        _shape(self.actuator_names, "actuator_names", (n_a,))
        _shape(self.actuators_xy, "actuators_xy", (n_a, 2))
        if np.ndim(self.drives) != 2 or np.shape(self.drives)[0] != n_a:
            raise ValidationError(f"drives must have shape (n_actuators={n_a}, n_drive), got {np.shape(self.drives)}")
        if np.ndim(self.recordings) != (3 if self.method == "mimo" else 4):
            raise ValidationError(f"recordings of a {self.method} calibration must have "
                                  f"{3 if self.method == 'mimo' else 4} dimensions, got {np.shape(self.recordings)}")
        if np.shape(self.recordings)[-1] < np.shape(self.drives)[1]:
            raise ValidationError("recordings are shorter than the drives")
        _shape(self.quality.snr_db, "quality snr_db", (n_p, n_a))
        if self.method == "mimo":
            for name in ("codes", "multiple_coherence"):
                if getattr(self, name) is None:
                    raise ValidationError(f"a mimo calibration needs {name}")
            _shape(self.multiple_coherence, "multiple_coherence", (n_f, n_p))
            if np.ndim(self.codes) != 2 or np.shape(self.codes)[1] != n_a:
                raise ValidationError(f"codes must have shape (n_takes, n_actuators={n_a}), got {np.shape(self.codes)}")
        if self.fit is not None:
            _shape(self.fit.residual, "fit residual", (n_p,))
        if self.measured is not None:
            _shape(self.measured, "point_measured", (n_p,))

    def _check_values(self) -> None:
        _unit_interval(self.coherence, "coherence")
        if not np.isfinite(self.drives).all():
            raise ValidationError("variable drive holds NaN/Inf")
        if self.method == "mimo":
            if not np.isin(self.codes, (-1, 1)).all():
                raise ValidationError("variable code must hold +1 or -1 for every take and actuator")
            object.__setattr__(self, "codes", np.asarray(self.codes).astype(np.int8))
            _unit_interval(self.multiple_coherence, "multiple_coherence")
        if self.measured is not None:
            flags = np.asarray(self.measured)
            if not np.isin(flags, (0, 1)).all():
                raise ValidationError("variable point_measured must hold 0 (predicted) or 1 (measured) for every point")
            if not flags.any():
                raise ValidationError("variable point_measured marks no point as measured")
            if not flags.all() and self.fit is None:
                raise ValidationError("variable point_measured marks predicted points, but the file holds no fitted "
                                      "skin model (fit_value) that predicted them")
            object.__setattr__(self, "measured", flags.astype(bool))

    @classmethod
    def from_mapping(cls, record: Mapping[str, Any]) -> CalibrationFileRecord:
        """A record from a mapping keyed as :data:`RECORD_KEYS` (the plain dict of earlier versions)."""
        if isinstance(record, CalibrationFileRecord):
            return record
        return cls(**_known(cls, record, "calibration"))


#: The fields of a calibration record, in order (the keys of the plain dict it replaces).
RECORD_KEYS = tuple(f.name for f in fields(CalibrationFileRecord))
