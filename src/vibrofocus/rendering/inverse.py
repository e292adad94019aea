"""The inverse filter (docs/method.md, "Rendering methods"): per-frequency (regularized) pseudo-inverse designs.

``S(f) = T(f) H_c(f)^+ U_c(f)`` at every frequency ``f`` of ``rfftfreq(n, 1/fs)``, with
``H_c`` the transfer matrix at the control points, ``U_c`` the spectra of their desired
displacements and ``T`` the smooth band taper; the drives are ``irfft(S)``. All
frequencies are solved in one batched computation (see :mod:`._pinv`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._docs import fill_doc
from .._validation import as_array, check_band, check_choice, check_positive
from ..defaults import BAND_HZ
from ..errors import DriveLimitError, ValidationError
from ._checks import as_indices, as_transfer, check_grid, check_regularization, check_transfer_energy, samples_for
from ._pinv import SpectralPinv, _single_threaded_blas, small_gram
from .causality import DEFAULT_WRAPAROUND_TOL, WraparoundCheck
from .taper import design_grid

__all__ = ["InverseOperator", "inverse_filter", "DesignReport", "DriveScaledWarning", "apply_drive_limit",
           "scale_to_peak"]


class DriveScaledWarning(UserWarning):
    """Drives were scaled down to the drive limit (the target is reached only partly)."""


@dataclass(frozen=True)
class DesignReport:
    """What :func:`inverse_filter` did, returned with ``full_output=True``.

    Attributes
    ----------
    scale : float
        Factor applied to the designed drives (1.0 unless scaled down to ``max_drive``).
    needed_peak : float
        Peak absolute drive the design needs before scaling, unit of the drives.
    peak_drive : float
        Peak absolute drive returned.
    target_peak : float
        Largest ``|targets|``, unit of the response.
    reached_peak : float
        Peak ``|predicted|`` at the point of ``target_peak`` after scaling.
    wraparound_fraction : float
        Share of the response energy past the window (NaN if not checked).
    predicted : ndarray, shape (n_points, n)
        Predicted response at every point of ``H`` (circular, through ``H``).
    """

    scale: float
    needed_peak: float
    peak_drive: float
    target_peak: float
    reached_peak: float
    wraparound_fraction: float
    predicted: np.ndarray


def _prepare_design(H: np.ndarray, fs: Any, n: int | None, band: Any, taper_octaves: Any):
    """Validate ``fs``, ``band`` and the taper for an already validated ``H``; return them
    with the active bins (where the taper is non-zero)."""
    fs = check_positive(fs, "fs")
    n = samples_for(H.shape[0], n)
    low, high = check_band(band, fs)
    taper_octaves = check_positive(taper_octaves, "taper_octaves", allow_zero=True)
    freqs, taper = design_grid(n, fs, (low, high), taper_octaves)
    nonzero = np.flatnonzero(taper > 0)
    if nonzero.size == 0:
        raise ValidationError(f"band=({low:g}, {high:g}) Hz holds no frequency of the {n}-sample grid at fs={fs:g} Hz")
    # The taper's support is one run of bins: a slice selects it from H without a copy.
    active = slice(int(nonzero[0]), int(nonzero[-1]) + 1)
    return H, fs, n, (low, high), taper, freqs, active


def _check_in_band(vanishes: np.ndarray, freqs_active: np.ndarray, band: tuple[float, float], what: str) -> None:
    """Refuse a transfer matrix that vanishes (``vanishes``: bool per active frequency) at
    frequencies inside the band."""
    inside = (freqs_active >= band[0]) & (freqs_active <= band[1])
    zero = inside & vanishes
    if zero.any():
        raise ValidationError(
            f"H is zero at {int(zero.sum())} {'frequency' if zero.sum() == 1 else 'frequencies'} inside "
            f"band={band} Hz{what} (first at "
            f"{freqs_active[zero][0]:g} Hz): the transfer matrix is singular there; recalibrate or narrow the band"
        )


@fill_doc
class InverseOperator:
    """Precomputed band-limited (regularized) pseudo-inverse of a transfer matrix.

    Factorizes ``H_c(f)`` once for all frequencies; afterwards every new target
    waveform or focus point costs about one inverse FFT of the drives.

    Parameters
    ----------
    H : ndarray, complex, shape (n // 2 + 1, n_points, n_actuators)
        Transfer matrix on ``rfftfreq(n, 1 / fs)``, response unit per drive unit (m/V).
    %(fs)s
    n_samples : int, optional
        Window length ``n``; default ``2 (n_freqs - 1)``. Give it for odd ``n``.
    control : sequence of int, optional
        Indices of the control points (rows of ``H``) the design constrains; default all.
    band : (float, float)
        Design band, Hz; the drives are tapered outside it (:func:`band_taper`).
    regularization : {None, "tikhonov", "tsvd"}
        ``None``: plain pseudo-inverse (the paper's method). ``"tikhonov"``: damping
        ``reg_param`` relative to the largest singular value at each frequency.
        ``"tsvd"``: drop singular values below ``reg_param`` times the largest.
    reg_param : float, optional
        Default 1e-2 for the regularized designs; must be None for the plain one.
    taper_octaves : float
        Width of the raised-cosine roll-off outside each band edge, octaves.
    weights : ndarray, shape (n_control,), optional
        Positive weights ``w_c`` of the control points: the design minimizes
        ``sum_c w_c^2 |H_c S - U_c|^2`` (then the smallest-norm ``S``), i.e. uses
        ``(W H_c)^+ W``. Default: all 1, the plain ``H_c^+`` of the
        published method (docs/method.md, "Rendering methods").

    Attributes
    ----------
    freqs : ndarray, shape (n // 2 + 1,)
        Frequencies, Hz.
    taper : ndarray, shape (n // 2 + 1,)
        Band taper in [0, 1].
    singular_values : ndarray, shape (n // 2 + 1, k)
        Singular values of ``H_c`` at each frequency (0 outside the taper's support).
    """

    def __init__(
        self,
        H: Any,
        fs: float,
        *,
        n_samples: int | None = None,
        control: Any = None,
        band: tuple[float, float] = BAND_HZ,
        regularization: str | None = None,
        reg_param: float | None = None,
        taper_octaves: float = 0.5,
        weights: Any = None,
    ) -> None:
        H, fs, n, band, taper, freqs, active = _prepare_design(as_transfer(H), fs, n_samples, band, taper_octaves)
        self.regularization, self.reg_param = check_regularization(regularization, reg_param)
        self.control = np.arange(H.shape[1]) if control is None else as_indices(control, "control", H.shape[1])
        self.H, self.fs, self.n_samples, self.band = H, fs, n, band
        self.freqs, self.taper, self._active = freqs, taper, active
        H_active = H[active][:, self.control, :]
        if weights is None:
            self.weights = np.ones(len(self.control))
        else:
            self.weights = as_array(weights, "weights", ndim=1, shape=(len(self.control),))
            if np.any(self.weights <= 0):
                raise ValidationError(f"weights must all be > 0, got {self.weights.tolist()}")
            H_active = H_active * self.weights[None, :, None]
        factors = SpectralPinv.factorize(H_active, self.regularization, self.reg_param)
        _check_in_band(factors.zero_freqs, freqs[active], band, " at the control points")
        # Stored per control point, (n_control, n_actuators, F_active), contiguous along
        # frequency: retargeting one point then reads one contiguous block and its drive
        # spectra come out in the layout the inverse FFT wants.
        weighted = factors.matrix() * (taper[active, None, None] * self.weights[None, None, :])
        self._columns = np.ascontiguousarray(np.transpose(weighted, (2, 1, 0)))
        self._factors = factors
        self._wraparound: WraparoundCheck | None = None

    @property
    def wraparound(self) -> WraparoundCheck:
        """The wrap-around check through ``H``, built on first use and kept: checking a
        design then costs about one inverse FFT per point."""
        if self._wraparound is None:
            self._wraparound = WraparoundCheck(self.H, self.n_samples)
        return self._wraparound

    def check_wraparound(self, drives: Any, *, tol: float = DEFAULT_WRAPAROUND_TOL, action: str = "raise") -> float:
        """:func:`~vibrofocus.rendering.check_wraparound` of ``drives`` through ``H``, with
        the operator's cached :attr:`wraparound` spectra; returns the fraction."""
        drives = as_array(drives, "drives", ndim=2, shape=(self.n_actuators, self.n_samples))
        return self.wraparound.check(drives, tol=tol, action=action)

    @property
    def singular_values(self) -> np.ndarray:
        """Singular values of ``H_c`` at each frequency, shape (n // 2 + 1, k) (0 outside the
        taper's support); computed on first use."""
        s = np.zeros((len(self.freqs), min(len(self.control), self.n_actuators)))
        s[self._active] = self._factors.singular_values
        return s

    @property
    def n_actuators(self) -> int:
        return self.H.shape[2]

    @property
    def n_points(self) -> int:
        return self.H.shape[1]

    def matrix(self) -> np.ndarray:
        """Band-limited pseudo-inverse, complex, shape (n // 2 + 1, n_actuators, n_control)."""
        full = np.zeros((len(self.freqs), self.n_actuators, len(self.control)), complex)
        full[self._active] = np.transpose(self._columns, (2, 1, 0))
        return full

    def _spectra_to_drives(self, spectra_active: np.ndarray) -> np.ndarray:
        """(n_actuators, F_active) drive spectra -> (n_actuators, n) drives."""
        spectra = np.zeros((self.n_actuators, len(self.freqs)), complex)
        spectra[:, self._active] = spectra_active
        return np.fft.irfft(spectra, self.n_samples, axis=-1)

    def drives(self, targets: Any) -> np.ndarray:
        """Drives reproducing ``targets`` at the control points.

        Parameters
        ----------
        targets : ndarray, shape (n_control, n)
            Desired displacements at the control points (in ``control`` order), real.

        Returns
        -------
        ndarray, shape (n_actuators, n)
        """
        targets = as_array(targets, "targets", ndim=2, shape=(len(self.control), self.n_samples))
        spectra = np.fft.rfft(targets, axis=-1)[:, self._active]  # (n_control, F_active)
        return self._spectra_to_drives(np.einsum("cqf,cf->qf", self._columns, spectra))

    def drives_for_point(self, point: int, waveform: Any) -> np.ndarray:
        """Drives putting ``waveform`` at one control point and zero at all the others.

        Costs one FFT of the waveform and one inverse FFT of the drives: use it to
        retarget the same operator to a new focus point or a new waveform.

        Parameters
        ----------
        point : int
            Index of the focus point among the rows of ``H``; must be a control point.
        waveform : ndarray, shape (n,)
            Desired displacement there, real.

        Returns
        -------
        ndarray, shape (n_actuators, n)
        """
        where = np.flatnonzero(self.control == point) if isinstance(point, (int, np.integer)) else ()
        if isinstance(point, bool) or len(where) == 0:
            raise ValidationError(f"point {point!r} is not one of the operator's control points {self.control.tolist()}")
        waveform = as_array(waveform, "waveform", ndim=1, shape=(self.n_samples,))
        spectrum = np.fft.rfft(waveform)[self._active]
        return self._spectra_to_drives(self._columns[where[0]] * spectrum)

    def predict(self, drives: Any) -> np.ndarray:
        """Predicted response at every point of ``H`` (circular convolution through ``H``).

        Parameters
        ----------
        drives : ndarray, shape (n_actuators, n)

        Returns
        -------
        ndarray, shape (n_points, n)
        """
        drives = as_array(drives, "drives", ndim=2, shape=(self.n_actuators, self.n_samples))
        return predict_response(self.H, drives)

    def band_limit(self, signal: Any) -> np.ndarray:
        """``signal`` (shape (..., n)) filtered by the design's band taper."""
        signal = as_array(signal, "signal", shape=None)
        if signal.shape[-1:] != (self.n_samples,):
            raise ValidationError(f"signal must have {self.n_samples} samples on its last axis, got shape {signal.shape}")
        return np.fft.irfft(np.fft.rfft(signal, axis=-1) * self.taper, self.n_samples, axis=-1)


def predict_response(H: np.ndarray, drives: np.ndarray) -> np.ndarray:
    """Response ``irfft(H @ rfft(drives))`` at every point (circular, as the design sees it).

    Parameters
    ----------
    H : ndarray, complex, shape (n // 2 + 1, n_points, n_actuators)
        Transfer matrix, m/V (already validated).
    drives : ndarray, real, shape (n_actuators, n)
        Drives, V (already validated).

    Returns
    -------
    ndarray, shape (n_points, n)
        Displacement, m.
    """
    n = drives.shape[1]
    spectra = np.fft.rfft(drives, axis=-1).T  # (F, n_act)
    return np.fft.irfft((H @ spectra[:, :, None])[:, :, 0], n, axis=0).T


def _check_same_transfer(wraparound: Any, H: np.ndarray, n: int) -> None:
    """Refuse a wrap-around check built from another transfer matrix or window, or from
    this ``H`` before it was changed in place: it would judge the drives through the
    wrong medium. Its comparison is the pass that validates ``H``'s values."""
    if not isinstance(wraparound, WraparoundCheck):
        raise ValidationError(f"wraparound must be a WraparoundCheck of H (WraparoundCheck(H)), got {type(wraparound).__name__}")
    if wraparound.n != n or not wraparound.matches(H):
        raise ValidationError(
            f"wraparound was built from another transfer matrix (shape {wraparound.H.shape}, window "
            f"{wraparound.n} samples) than this design's H (shape {H.shape}, window {n}), or H was changed "
            "in place since: build it with WraparoundCheck(H)"
        )


def scale_to_peak(drives: np.ndarray, peak: float) -> np.ndarray:
    """Scale ``drives`` so that their largest magnitude is ``peak``, never above it.

    ``drives * (peak / max|drives|)`` can round one ulp over ``peak`` (about 1 in 60 random
    arrays); the result is clipped to ``[-peak, peak]``, which moves only such samples, by
    that ulp, so a drive scaled to a limit reads as the limit, not just over it.

    Parameters
    ----------
    drives : ndarray, shape (n_actuators, n_samples)
        Drives, V; not all zero.
    peak : float
        The wanted peak, V.

    Returns
    -------
    ndarray, shape (n_actuators, n_samples)
        A scaled copy.
    """
    out = drives * (peak / float(np.max(np.abs(drives))))
    return np.clip(out, -peak, peak, out=out)


def apply_drive_limit(drives: np.ndarray, max_drive: float | None, on_limit: str, what: str = "the design") -> tuple[np.ndarray, float, float]:
    """Refuse or scale drives whose peak exceeds ``max_drive``.

    Returns
    -------
    drives : ndarray
        Possibly scaled copy.
    scale : float
        Applied factor (1.0 when within the limit or without a limit).
    needed_peak : float
        Peak before scaling.
    """
    needed = float(np.max(np.abs(drives))) if drives.size else 0.0
    if max_drive is None or needed <= max_drive:
        return drives, 1.0, needed
    if on_limit == "refuse":
        raise DriveLimitError(
            f"{what} needs {needed:.4g} peak drive, over the limit max_drive={max_drive:.4g}; "
            "refused (ask for on_limit='scale' to scale it down, or lower the target amplitude)"
        )
    return scale_to_peak(drives, max_drive), max_drive / needed, needed


@_single_threaded_blas()  # one BLAS thread for the whole design (set once)
@fill_doc
def inverse_filter(
    H: Any,
    targets: Any,
    fs: float,
    *,
    band: tuple[float, float] = BAND_HZ,
    regularization: str | None = None,
    reg_param: float | None = None,
    max_drive: float | None = None,
    on_limit: str = "refuse",
    taper_octaves: float = 0.5,
    check_wraparound: bool | str = True,
    wraparound_tol: float = DEFAULT_WRAPAROUND_TOL,
    wraparound: WraparoundCheck | None = None,
    full_output: bool = False,
) -> np.ndarray | tuple[np.ndarray, DesignReport]:
    """Inverse-filter drives: ``irfft(T(f) H(f)^+ U(f))`` (docs/method.md, "Rendering methods").

    Every row of ``H`` is a control point; give zero targets for quiet points.

    Parameters
    ----------
    H : ndarray, complex, shape (n // 2 + 1, n_points, n_actuators)
        Transfer matrix on ``numpy.fft.rfftfreq(n, 1 / fs)`` (m/V, or any unit pair).
    targets : ndarray, real, shape (n_points, n)
        Desired displacement at every point (unit of ``H``'s output, m).
    %(fs)s
    band : (float, float)
        Design band, Hz, inside (0, fs/2]; a raised-cosine taper of ``taper_octaves``
        rolls off outside it.
    regularization : {None, "tikhonov", "tsvd"}
        See :class:`InverseOperator`. ``None`` is the paper's plain pseudo-inverse.
    reg_param : float, optional
        Relative regularization (default 1e-2 for "tikhonov" and "tsvd").
    max_drive : float, optional
        Drive limit, unit of the drives (V). ``None`` (default): no limit, the design
        works in the units of ``H``.
    on_limit : {"refuse", "scale"}
        Above ``max_drive``: raise :class:`~vibrofocus.errors.DriveLimitError`, or
        scale all drives down together (the target is then reached only partly; the
        factor is in the report, and a :class:`DriveScaledWarning` says so when
        ``full_output`` is False).
    taper_octaves : float
        Roll-off width outside each band edge, octaves (0: brick wall).
    check_wraparound : bool or "warn"
        Check that the drives, played once from silence by linear convolution, reproduce
        the design within the window (:func:`~vibrofocus.rendering.wraparound_fraction`);
        True raises :class:`~vibrofocus.errors.CausalityError`, "warn" warns, False skips.
    wraparound_tol : float
        Largest tolerated share of the response energy past the window.
    wraparound : WraparoundCheck, optional
        ``WraparoundCheck(H)``, built once and passed to every design through this ``H``:
        it keeps the impulse responses' padded spectra after its first check, so each
        later check costs a fraction of the design instead of several designs. Default:
        a one-shot check, which transforms every path's impulse response.
    full_output : bool
        Also return a :class:`DesignReport`.

    Returns
    -------
    drives : ndarray, real, shape (n_actuators, n)
        Unit of ``H``'s input (V).
    report : DesignReport
        Only with ``full_output=True``.
    """
    H = as_transfer(H, values=False)  # values checked where used: a pass less over H
    targets = as_array(targets, "targets", ndim=2)
    n = targets.shape[1]
    if n < 2:
        raise ValidationError(f"targets must have at least 2 samples, got shape {targets.shape}")
    check_grid(H.shape[0], n, "targets (n_points, n)")
    if targets.shape[0] != H.shape[1]:
        raise ValidationError(
            f"targets has {targets.shape[0]} rows but H has {H.shape[1]} points: "
            "targets must have shape (n_points, n) with a row (zeros for quiet points) for every point of H"
        )
    check_choice(on_limit, "on_limit", ("refuse", "scale"))
    check_choice(check_wraparound, "check_wraparound", (True, False, "warn"))
    if max_drive is not None:
        max_drive = check_positive(max_drive, "max_drive")
    regularization, reg_param = check_regularization(regularization, reg_param)
    if wraparound is not None:
        _check_same_transfer(wraparound, H, n)
    H, fs, n, band, taper, freqs, active = _prepare_design(H, fs, n, band, taper_octaves)
    with np.errstate(over="ignore", invalid="ignore"):
        gram = small_gram(H[active])
        check_transfer_energy(np.trace(gram, axis1=1, axis2=2).real.sum(), H[active], "H", " in the design band")
    factors = SpectralPinv.factorize(H[active], regularization, reg_param, gram=gram)
    _check_in_band(factors.zero_freqs, freqs[active], band, "")
    rows = np.flatnonzero(np.any(targets != 0, axis=1))  # quiet points add nothing to H^H U
    rhs = np.fft.rfft(targets[rows], axis=-1).T[active] * taper[active, None]
    spectra = np.zeros((len(freqs), H.shape[2]), complex)
    spectra[active] = factors.apply(rhs, rows)
    drives = np.fft.irfft(spectra, n, axis=0).T

    fraction = float("nan")
    if (check_wraparound or full_output) and wraparound is None:  # (else validated by its comparison)
        with np.errstate(over="ignore", invalid="ignore"):
            check_transfer_energy(np.vdot(H, H).real, H)  # the rest of H is used from here on
    if check_wraparound:
        playback = WraparoundCheck._trusted(H, n, keep=False) if wraparound is None else wraparound
        fraction = playback.check(drives, tol=wraparound_tol, spectra=spectra,
                                  action="warn" if check_wraparound == "warn" else "raise")
    drives, scale, needed = apply_drive_limit(drives, max_drive, on_limit, "the inverse filter")
    if not full_output:
        if scale < 1.0:
            warnings.warn(
                f"drives scaled by {scale:.3g} to max_drive={max_drive:g} (needed {needed:.4g}); "
                "the targets are reached at that fraction of their amplitude",
                DriveScaledWarning,
                stacklevel=2,
            )
        return drives
    predicted = predict_response(H, drives)
    peak_index = np.unravel_index(np.argmax(np.abs(targets)), targets.shape)[0] if targets.size else 0
    report = DesignReport(
        scale=scale,
        needed_peak=needed,
        peak_drive=float(np.max(np.abs(drives))),
        target_peak=float(np.max(np.abs(targets))),
        reached_peak=float(np.max(np.abs(predicted[peak_index]))),
        wraparound_fraction=fraction,
        predicted=predicted,
    )
    return drives, report
