"""A transfer matrix that knows itself: :class:`TransferMatrix` (docs/method.md, "Rendering methods").

``H`` travels with what a design needs to trust and reuse it: its frequency grid and
sample rate, the layout its rows and columns belong to, the band it was calibrated in,
the coherence where it was measured and where it came from. It is validated once, when
made; the designs then reuse its kept wrap-around check and inverse operators instead of
checking and factorizing ``H`` again on every call.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._docs import fill_doc
from .._validation import as_array, check_band, check_positive
from ..errors import ValidationError
from ..layout import ArrayLayout
from ._checks import ValidatedTransfer, as_transfer, check_window, samples_for
from .causality import WraparoundCheck
from .inverse import InverseOperator
from .taper import band_taper

__all__ = ["TransferMatrix", "as_transfer_matrix", "target_on_model", "calibration_window"]

#: Window of a design when neither the caller nor the source says one, samples.
DEFAULT_WINDOW = 4096


def calibration_window(calibration: Any) -> int:
    """The design window a calibration's ``H`` gives, samples: its own resolution.

    A calibration stores ``H`` on ``rfftfreq(n_fft, 1 / fs)``: its impulse responses, as
    measured, are ``n_fft`` samples long, ring-down included (a longer window only pads
    them with zeros, a shorter one cuts them). A calibration without ``n_fft`` (or an odd
    one) gets :data:`DEFAULT_WINDOW`.

    Parameters
    ----------
    calibration : Calibration

    Returns
    -------
    int
        Samples at the calibration's ``fs``.
    """
    own = getattr(calibration, "n_fft", None)
    ok = isinstance(own, (int, np.integer)) and not isinstance(own, bool) and own >= 16 and own % 2 == 0
    return int(own) if ok else DEFAULT_WINDOW


def _check_fits(shape: tuple[int, ...], layout: ArrayLayout) -> None:
    """Refuse a transfer matrix whose points and actuators are not the layout's."""
    if tuple(shape[1:]) != (layout.n_points, layout.n_actuators):
        raise ValidationError(
            f"H has shape {tuple(shape)} but layout {layout.name!r} has {layout.n_points} points and "
            f"{layout.n_actuators} actuators: H must have shape (n_freqs, {layout.n_points}, {layout.n_actuators})"
        )


def _averages(calibration: Any) -> int:
    """Independent averages behind a calibration's coherence: its repeats, less the other
    actuators for ``mimo`` (a partial coherence given them); at least 1."""
    repeats = int(getattr(calibration.sweep, "repeats", 1) or 1)
    others = calibration.n_actuators - 1 if calibration.method == "mimo" else 0
    return max(1, repeats - others)


@fill_doc
class TransferMatrix(ValidatedTransfer):
    """A calibrated (or modelled) transfer matrix with its grid, layout and provenance.

    Parameters
    ----------
    H : array_like, complex, shape (n // 2 + 1, n_points, n_actuators)
        Transfer matrix, m/V, on ``rfftfreq(n, 1 / fs)``; row ``i`` is
        ``layout.points_xy[i]``, column ``q`` actuator ``q``.
    %(fs)s
    layout : ArrayLayout
        The actuators and points ``H`` belongs to.
    n_samples : int, optional
        Window length ``n``; default ``2 (n_freqs - 1)`` (give it for odd ``n``).
    band : (float, float), optional
        Band ``H`` is valid in, Hz (a calibration's band); a design reaching outside it is
        refused. None: not known (every band under ``fs / 2`` is accepted).
    coherence : array_like, shape (n_freqs', n_points, n_actuators), optional
        Coherence of the measurement, in [0, 1], on the calibration's own grid; None for a
        model.
    provenance : dict, optional
        Where ``H`` came from: ``rig`` (the rig's description), ``participant`` and
        ``skin`` (the skin preset of a simulated arm), ``averages`` (the independent averages
        behind a calibration's coherence), or anything a lab wants to keep.

    Notes
    -----
    The values are checked once here (finite, not all zero) and ``H`` is kept read-only,
    so that what the caches hold stays true. The rendering functions that take a bare
    ``H`` accept a ``TransferMatrix`` too and skip their own check.
    """

    def __init__(self, H: Any, fs: float, layout: ArrayLayout, *, n_samples: int | None = None,
                 band: tuple[float, float] | None = None, coherence: Any = None,
                 provenance: dict | None = None) -> None:
        if not isinstance(layout, ArrayLayout):
            raise ValidationError(f"layout must be an ArrayLayout, got {type(layout).__name__}")
        H = np.array(as_transfer(H), copy=True)
        _check_fits(H.shape, layout)
        fs = check_positive(fs, "fs")
        n = samples_for(H.shape[0], n_samples)
        band = None if band is None else check_band(band, fs, name="calibrated_band")
        if coherence is not None:
            coherence = as_array(coherence, "coherence", ndim=3, finite=False)
        self._set(H, fs, layout, n, band, coherence, dict(provenance or {}))

    def _set(self, H: np.ndarray, fs: float, layout: ArrayLayout, n: int, band: tuple[float, float] | None,
             coherence: np.ndarray | None, provenance: dict) -> None:
        H.flags.writeable = False  # the caches below describe these values
        self.H, self.fs, self.layout, self.n_samples = H, fs, layout, n
        self.band, self.coherence, self.provenance = band, coherence, provenance
        self._check: WraparoundCheck | None = None
        self._operators: dict[tuple, InverseOperator] = {}
        self._std_of: Any = None  # a fitted model's standard error, made on first use (h_std)
        self._h_std: np.ndarray | None = None

    @classmethod
    def _trusted(cls, H: np.ndarray, fs: float, layout: ArrayLayout, n: int, band: tuple[float, float] | None = None,
                 coherence: np.ndarray | None = None, provenance: dict | None = None) -> "TransferMatrix":
        """One made from values the caller has validated (no pass over ``H``)."""
        tm = cls.__new__(cls)
        tm._set(H, float(fs), layout, int(n), band, coherence, dict(provenance or {}))
        return tm

    # -- makers ---------------------------------------------------------------------------
    @classmethod
    def from_calibration(cls, calibration: Any, n_samples: int | None = None, *,
                         taper_octaves: float = 0.5) -> "TransferMatrix":
        """``calibration.transfer_for(n_samples)`` with its band, coherence and provenance.

        Parameters
        ----------
        calibration : Calibration
        n_samples : int, optional
            Design window, samples (even, >= 16, at most what
            :data:`~vibrofocus.rendering._checks.MAX_DESIGN_BYTES` of design memory
            allows: 262144 for the reference layout); default :func:`calibration_window`:
            the calibration's own resolution (``n_fft``), where its ``H`` holds the
            impulse responses as measured.
        taper_octaves : float
            Width of the taper outside the calibrated band, octaves.
        """
        lay = calibration.layout
        n = check_window(calibration_window(calibration) if n_samples is None else n_samples, lay.n_points,
                         lay.n_actuators, check_positive(calibration.fs, "fs"))
        # The calibration keeps this window's check: its H is the design's, validated
        # here once (no copy: the check owns it), and its cached spectra are reused.
        check = calibration.wraparound_check(n, taper_octaves=taper_octaves)
        H = as_transfer(check.H)
        rig = calibration.rig if isinstance(calibration.rig, dict) else {}
        tm = cls._trusted(H, check_positive(calibration.fs, "fs"), calibration.layout, samples_for(H.shape[0], n),
                          check_band(calibration.band, calibration.fs, name="calibrated_band"),
                          calibration.coherence,
                          {"rig": rig, "participant": calibration.participant_id, "skin": rig.get("skin"),
                           "calibration_created": calibration.created,
                           "averages": _averages(calibration)})
        tm._check = check
        fit, predicted = getattr(calibration, "fit", None), getattr(calibration, "predicted_points", np.zeros(0))
        if predicted.size and hasattr(fit, "transfer_std"):  # rows the fit predicted: its standard error
            freqs = np.fft.rfftfreq(n, 1 / calibration.fs)
            with np.errstate(over="ignore", divide="ignore"):  # band_taper at 0 Hz
                taper = band_taper(freqs, calibration.band, taper_octaves)
            tm._std_of = (fit, lay.points_xy, freqs, taper, predicted)
        return tm

    @classmethod
    @fill_doc
    def from_model(cls, model: Any, layout: ArrayLayout, fs: float, n_samples: int | None = None, *,
                   taper_octaves: float = 0.5) -> "TransferMatrix":
        """H of a model of the skin at the layout's points.

        Parameters
        ----------
        model : object with ``transfer(points_xy, freqs)``
            A fitted :class:`~vibrofocus.calibration.FittedSkin` or a simulated arm (its
            true H). A model with ``band`` gives the calibrated band; its ``H`` is its own
            prediction over the band and the ``taper_octaves`` past each edge (where a
            design's drives still reach, :func:`~vibrofocus.signals.band_taper`), and rolls
            off over ``taper_octaves`` beyond. (Tapered from the band's edges, as
            ``Calibration.transfer_for`` tapers a measurement, a model's ``H`` would
            under-state what the drives' roll-off does: from a layered fit, minimax taps
            lost 0.4-0.8 dB of peak contrast to it, ``scripts/robust_fit_minimax.py``.)
        %(layout)s
        %(fs)s
        n_samples : int, optional
            Window, samples; default the model's ``design_window()`` if it has one, else 4096.
        taper_octaves : float
            Width of the taper outside the model's band, octaves.
        """
        own_window = getattr(model, "design_window", None)
        n = (DEFAULT_WINDOW if own_window is None else int(own_window(DEFAULT_WINDOW))) if n_samples is None else n_samples
        n = check_window(n, layout.n_points, layout.n_actuators, check_positive(fs, "fs"))
        freqs = np.fft.rfftfreq(int(n), 1 / fs)
        H = np.asarray(model.transfer(layout.points_xy, freqs))
        band = getattr(model, "band", None)
        if band is not None:
            octaves = check_positive(taper_octaves, "taper_octaves", allow_zero=True)
            reach = (float(band[0]) / 2 ** octaves, float(band[1]) * 2 ** octaves)
            with np.errstate(over="ignore", divide="ignore"):  # band_taper at 0 Hz
                taper = band_taper(freqs, reach, octaves)
            H = H * taper[:, None, None]
        provenance = {"model": type(model).__name__, "skin": getattr(model, "skin", None),
                      "participant": getattr(model, "seed", None)}
        tm = cls(H, fs, layout, n_samples=int(n), band=None if band is None else tuple(band), provenance=provenance)
        if hasattr(model, "transfer_std"):  # a fitted model knows its uncertainty: made when asked
            tm._std_of = (model, layout.points_xy, freqs, np.ones(freqs.size) if band is None else taper,
                          np.arange(layout.n_points))
        return tm

    # -- what it is -----------------------------------------------------------------------
    @property
    def freqs(self) -> np.ndarray:
        """ndarray, shape (n_freqs,): ``rfftfreq(n_samples, 1 / fs)``, Hz."""
        return np.fft.rfftfreq(self.n_samples, 1 / self.fs)

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(n_freqs, n_points, n_actuators)``."""
        return self.H.shape

    @property
    def h_std(self) -> np.ndarray | None:
        """ndarray, real, shape of ``H``, or None: the standard error of a fitted model's
        ``H`` (:meth:`~vibrofocus.calibration.FittedSkin.transfer_std`, tapered as ``H``,
        computed on first use and kept); for a calibration that measured a subset of its
        points (``calibrate(..., measure=K)``), the same at the points its fit predicted,
        zero at the measured ones; None for a measurement of every point (its uncertainty
        is its ``coherence``) or a model that knows none (a simulated arm's true ``H``)."""
        if self._h_std is None and self._std_of is not None:
            model, points, freqs, taper, rows = self._std_of
            std = np.zeros(self.H.shape)
            live = taper > 0
            std[np.ix_(live, rows)] = model.transfer_std(points[rows], freqs[live]) * taper[live, None, None]
            std.flags.writeable = False
            self._h_std = std
        return self._h_std

    @property
    def n_points(self) -> int:
        return self.H.shape[1]

    @property
    def n_actuators(self) -> int:
        return self.H.shape[2]

    def rows(self, indices: Any) -> "TransferMatrix":
        """The transfer to some of the points, as a plain (validated) matrix on the same grid.

        Parameters
        ----------
        indices : sequence of int
            Rows of ``H`` (points), in the order wanted.

        Returns
        -------
        TransferMatrix
            Its layout is this one's (the rows no longer match it: use it for ``H`` only).
        """
        sub = np.ascontiguousarray(self.H[:, np.asarray(indices, int), :])
        return TransferMatrix._trusted(sub, self.fs, self.layout, self.n_samples, self.band)

    # -- caches ---------------------------------------------------------------------------
    def wraparound_check(self) -> WraparoundCheck:
        """The :class:`WraparoundCheck` of ``H``, built on first use and kept (its padded
        spectra make each later check of a design about one inverse FFT per point)."""
        if self._check is None:
            self._check = WraparoundCheck._trusted(self.H, self.n_samples, keep=True)
        return self._check

    def inverse_operator(self, control: Any, *, band: tuple[float, float], regularization: str | None = None,
                         reg_param: float | None = None, taper_octaves: float = 0.5,
                         weights: Any = None) -> InverseOperator:
        """The :class:`InverseOperator` of ``H`` at ``control``, factorized once per set of
        options and kept (arguments as for :class:`InverseOperator`)."""
        control = tuple(int(i) for i in control)
        weights = None if weights is None else tuple(float(w) for w in np.ravel(weights))
        key = (control, tuple(band), regularization, reg_param, float(taper_octaves), weights)
        if key not in self._operators:
            self._operators[key] = InverseOperator(self, self.fs, n_samples=self.n_samples, control=control,
                                                   band=band, regularization=regularization, reg_param=reg_param,
                                                   taper_octaves=taper_octaves, weights=weights)
        return self._operators[key]

    def __repr__(self) -> str:
        band = "unknown" if self.band is None else f"{self.band[0]:g}-{self.band[1]:g} Hz"
        return (f"TransferMatrix(n_freqs={self.H.shape[0]}, n_points={self.n_points}, n_actuators={self.n_actuators}, "
                f"fs={self.fs:g}, n_samples={self.n_samples}, band={band}, layout={self.layout.name!r})")


@fill_doc
def as_transfer_matrix(H: Any, fs: float, layout: ArrayLayout, *, n_samples: int | None = None,
                       calibrated_band: tuple[float, float] | None = None,
                       taper_octaves: float = 0.5) -> TransferMatrix:
    """A :class:`TransferMatrix` from what :func:`render` accepts as ``H``.

    Parameters
    ----------
    H : TransferMatrix, Calibration, skin model or array_like
        A ``TransferMatrix`` is returned as it is; a ``Calibration`` gives
        :meth:`TransferMatrix.from_calibration`; an object with ``transfer(points_xy,
        freqs)`` gives :meth:`TransferMatrix.from_model`; an array is validated.
    %(fs)s
    %(layout)s
    n_samples : int, optional
        Window, samples.
    calibrated_band : (float, float), optional
        Band ``H`` is valid in, Hz; default the source's own (a calibration's, a model's).
    taper_octaves : float
        Taper outside a calibration's or model's band, octaves.
    """
    fs = check_positive(fs, "fs")
    if isinstance(H, TransferMatrix):
        tm = H
    elif hasattr(H, "transfer_for") and hasattr(H, "band"):
        tm = TransferMatrix.from_calibration(H, n_samples, taper_octaves=taper_octaves)
    elif hasattr(H, "transfer"):
        tm = TransferMatrix.from_model(H, layout, fs, n_samples, taper_octaves=taper_octaves)
    else:
        return TransferMatrix(H, fs, layout, n_samples=n_samples, band=calibrated_band)
    _check_fits(tm.shape, layout)
    if tm.fs != fs:
        raise ValidationError(f"fs={fs:g} Hz differs from the transfer matrix's sample rate {tm.fs:g} Hz")
    if n_samples is not None:
        samples_for(tm.H.shape[0], n_samples)
    band = tm.band if calibrated_band is None else check_band(calibrated_band, tm.fs, name="calibrated_band")
    if band != tm.band or layout != tm.layout:  # the caller's band and layout, the same kept check
        kept = tm
        tm = TransferMatrix._trusted(tm.H, tm.fs, layout, tm.n_samples, band, tm.coherence, tm.provenance)
        tm._check, tm._std_of, tm._h_std = kept._check, kept._std_of, kept._h_std
    return tm


@fill_doc
def target_on_model(H: Any, layout: ArrayLayout, target_xy: Any) -> tuple[Any, ArrayLayout, int]:
    """The skin model a tap anywhere is designed with, and the layout with the target in it.

    Parameters
    ----------
    H : Calibration with a fitted model, or skin model
        A calibration gives its ``fit``; a model has ``transfer(points_xy, freqs)``.
    %(layout)s
    target_xy : (float, float)
        Target position on the skin, m, in the layout frame.

    Returns
    -------
    model, layout, location
        The model; the layout with the target as one more location (the same layout when
        the target is one of its locations); the target's 1-based location number.
    """
    if hasattr(H, "transfer_for"):
        if getattr(H, "fit", None) is None:
            raise ValidationError("target_xy needs a model of the skin: fit one to the calibration first "
                                  "(cal.fit = fit_model(cal)) or pass the FittedSkin as H")
        H = H.fit
    if not hasattr(H, "transfer") or isinstance(H, TransferMatrix):
        raise ValidationError("target_xy needs a model of the skin as H (a FittedSkin from fit_model, or a "
                              "SimulatedForearm): a measured matrix knows H only at its calibrated points")
    target = as_array(target_xy, "target_xy", ndim=1, shape=(2,))
    if not np.isfinite(target).all():
        raise ValidationError(f"target_xy must be finite, got {target.tolist()}")
    if hasattr(H, "on_skin") and not bool(H.on_skin(target[None])[0]):
        area = H.skin_area_description() if hasattr(H, "skin_area_description") else "its skin area"
        raise ValidationError(f"target_xy=({target[0] * 1e3:g}, {target[1] * 1e3:g}) mm lies outside the "
                              f"model's skin ({area})")
    same = np.flatnonzero(np.all(np.abs(layout.locations_xy - target) < 1e-9, axis=1))
    if same.size:  # a numbered location: no need for a new one
        return H, layout, int(same[0]) + 1
    layout = ArrayLayout(layout.actuators_xy, np.vstack([layout.locations_xy, target]), layout.guards_xy,
                         spacing_xy=layout.spacing_xy, actuator_names=layout.actuator_names,
                         guard_names=layout.guard_names, name=f"{layout.name} + target")
    return H, layout, layout.n_locations
