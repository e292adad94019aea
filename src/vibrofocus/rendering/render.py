"""High-level rendering: one call from a calibrated transfer matrix to drives (SPEC §2)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import check_band, check_choice, check_positive
from ..defaults import (
    BAND_HZ,
    DRIVE_LIMIT_V,
    FUNNELING_AMPLITUDE_V,
    METHODS,
    SIGMA_S,
    TARGET_FRACTION,
    TARGET_PEAK_M,
)
from ..errors import ValidationError
from ..layout import ArrayLayout
from ..signals.ricker import ricker
from ._checks import as_transfer, check_regularization, samples_for
from .causality import DEFAULT_WRAPAROUND_TOL, check_wraparound as _check_wraparound
from .combination import combination_target
from .funneling import funneling_gains
from .inverse import InverseOperator, apply_drive_limit, predict_response
from .metrics import focus_metrics
from .taper import band_taper
from .time_reversal import time_reversal_drives

__all__ = ["Rendering", "render", "CONTROL_SETS"]

#: Default weight of the quiet control points against the target (see ``render``).
DEFAULT_GUARD_WEIGHT = 0.1
#: Which points a design constrains besides the target: ``"guards"`` (SPEC §2: the
#: target and the guard points) or ``"all"`` (every other calibrated point held at zero).
CONTROL_SETS = ("guards", "all")


@dataclass(frozen=True, eq=False)
class Rendering:
    """Drives for one tap and what they are predicted to do.

    Attributes
    ----------
    method : str
        One of ``"funneling"``, ``"inverse"``, ``"combination"``, ``"time_reversal"``.
    location : int
        1-based location number of the target.
    target_index : int
        Index of the target in ``layout.points_xy`` (and in the rows of ``predicted``).
    drives : ndarray, shape (n_actuators, n)
        Drive signals, V, within the drive limit.
    predicted : ndarray, shape (n_points, n)
        Displacement predicted through ``H`` at every calibrated point (locations then
        guards), m.
    desired : ndarray, shape (n,)
        Band-limited target waveform the method aims for, m: the Ricker at
        ``target_peak_m`` for "inverse", "time_reversal" and "funneling" (the ideal
        tap), the funneling prediction at the target for "combination".
    reference : ndarray, shape (n,)
        Band-limited Ricker at ``target_peak_m`` (same for every method), m: a common
        yardstick across methods.
    fs : float
        Sample rate, Hz.
    t0 : float
        Centre of the base stimulus in the window, s.
    sigma : float
        Ricker spread, s.
    band : (float, float)
        Design band, Hz.
    scale : float
        1.0 unless the drives were scaled down to the limit (then ``limit_v /
        needed_peak_v``). Time reversal is always normalized to the limit and reports 1.0.
    needed_peak_v : float
        Peak drive the design needed before any scaling, V.
    reached_peak_m : float
        Peak predicted ``|u|`` at the target after scaling, m.
    control_indices : ndarray of int
        Points the design constrained (target first); empty for funneling.
    wraparound_fraction : float
        Share of the response energy past the window when played once from silence
        (NaN if not checked).
    gains : ndarray, shape (n_actuators,) or None
        Funneling amplitudes, V ("funneling" and "combination").
    layout : ArrayLayout or None
        The layout rendered on.
    """

    method: str
    location: int
    target_index: int
    drives: np.ndarray
    predicted: np.ndarray
    desired: np.ndarray
    reference: np.ndarray
    fs: float
    t0: float
    sigma: float
    band: tuple[float, float]
    scale: float
    needed_peak_v: float
    reached_peak_m: float
    control_indices: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    wraparound_fraction: float = float("nan")
    gains: np.ndarray | None = None
    layout: ArrayLayout | None = None

    @property
    def n_samples(self) -> int:
        return self.drives.shape[1]

    @property
    def time(self) -> np.ndarray:
        """ndarray, shape (n,): sample times, s."""
        return np.arange(self.n_samples) / self.fs

    def metrics(self, *, against: str = "desired", contrast_over: str = "locations") -> dict[str, float]:
        """:func:`focus_metrics` of the prediction.

        Parameters
        ----------
        against : {"desired", "reference"}
            Waveform the fidelity compares with (``t0`` is its peak).
        contrast_over : {"locations", "points"}
            The contrast compares the target with the other skin locations (the grid a
            participant names; default) or with every other calibrated point, guards
            included.
        """
        check_choice(against, "against", ("desired", "reference"))
        check_choice(contrast_over, "contrast_over", ("locations", "points"))
        wanted = self.desired if against == "desired" else self.reference
        compare = None
        if contrast_over == "locations" and self.layout is not None:
            compare = np.arange(self.layout.n_locations)
        return focus_metrics(self.predicted, self.target_index, wanted, self.fs, sigma=self.sigma,
                             drives=self.drives, compare_indices=compare)


def render(
    method: str,
    H: Any,
    fs: float,
    layout: ArrayLayout,
    location: int,
    *,
    limit_v: float = DRIVE_LIMIT_V,
    on_limit: str = "scale",
    sigma: float = SIGMA_S,
    target_peak_m: float = TARGET_PEAK_M,
    regularization: str | None = None,
    reg_param: float | None = None,
    band: tuple[float, float] = BAND_HZ,
    n_samples: int | None = None,
    t0: float | None = None,
    control: str = "guards",
    funneling_law: str = "linear",
    funneling_amplitude_v: float = FUNNELING_AMPLITUDE_V,
    taper_octaves: float = 0.5,
    form: str = "zero_mean",
    check_wraparound: bool | str = True,
    wraparound_tol: float = DEFAULT_WRAPAROUND_TOL,
    calibrated_band: tuple[float, float] | None = None,
    guard_weight: float = DEFAULT_GUARD_WEIGHT,
) -> Rendering:
    """Render a tap at a layout location with one of the methods of SPEC §2.

    Parameters
    ----------
    method : {"funneling", "inverse", "combination", "time_reversal"}
    H : ndarray, complex, shape (n // 2 + 1, n_points, n_actuators), or Calibration
        Calibrated transfer matrix (m/V) on ``rfftfreq(n, 1 / fs)``, rows in the order of
        ``layout.points_xy`` (locations then guards). A ``Calibration`` gives its
        ``transfer_for(n_samples)`` (default 4096) and its ``band`` as ``calibrated_band``.
    fs : float
        Sample rate, Hz.
    layout : ArrayLayout
    location : int
        1-based location number of the target.
    limit_v : float
        Drive limit, V peak.
    on_limit : {"scale", "refuse"}
        A design over the limit is scaled down (reported in ``scale`` and
        ``reached_peak_m``) or refused with :class:`~vibrofocus.errors.DriveLimitError`.
    sigma : float
        Ricker spread of the base stimulus, s.
    target_peak_m : float
        Peak displacement asked at the target by "inverse" and "time_reversal", m.
    regularization, reg_param
        Inverse design ("inverse", "combination"); see :func:`inverse_filter`.
    band : (float, float)
        Design band, Hz.
    n_samples : int, optional
        Window length; default ``2 (n_freqs - 1)``.
    t0 : float, optional
        Centre of the base stimulus, s; default ``TARGET_FRACTION`` (half) of the window,
        which leaves room for the drive's pre-ringing before it and the medium's
        ring-down after it.
    control : {"guards", "all"}
        Control points of the inverse designs. ``"guards"`` (default, SPEC §2): the
        target and the guard points (held at zero); the other locations are free, which
        keeps the system close to square (5 x 4 in the reference setup) so the target is
        met. ``"all"``: every other calibrated point held at zero too (a least-squares
        compromise that trades target fidelity for quiet elsewhere).
    funneling_law : {"linear", "energy"}
    funneling_amplitude_v : float
        Funneling ``A``, V ("funneling" and "combination").
    taper_octaves : float
        Band taper roll-off, octaves.
    form : {"zero_mean", "printed"}
        Ricker form; see :func:`~vibrofocus.signals.ricker`.
    check_wraparound : bool or "warn"
        Check that the drives, played once from silence, fit the window (raise
        CausalityError, warn, or skip).
    wraparound_tol : float
        Tolerated share of the response energy past the window.
    calibrated_band : (float, float), optional
        Band the calibration is valid in, Hz (``Calibration.band``); ``band`` must lie
        inside it.
    guard_weight : float
        Weight of the zero-displacement control points relative to the target in the
        least-squares inverse designs (> 0). ``1.0`` is the plain pseudo-inverse of the
        method's source paper (SPEC §2). With four actuators, the target and four guards
        are five equations for four unknowns; the guards sit 6 mm from the actuators and
        couple far more strongly than the target, so with equal weights the fit keeps
        them quiet at the target's expense: on the simulated forearm the tap keeps only
        fidelity 0.63-0.85 and about 5 % of the asked amplitude. The default
        ``DEFAULT_GUARD_WEIGHT = 0.1`` weights the target's waveform first (fidelity
        0.95-0.99 from a measured calibration) and still pushes the guards down.

    Returns
    -------
    Rendering
    """
    check_choice(method, "method", METHODS)
    if not isinstance(layout, ArrayLayout):
        raise ValidationError(f"layout must be an ArrayLayout, got {type(layout).__name__}")
    if hasattr(H, "transfer_for") and hasattr(H, "band"):
        # A Calibration carries the band it is valid in: a design outside it is refused.
        if calibrated_band is None:
            calibrated_band = tuple(H.band)
        H = H.transfer_for(4096 if n_samples is None else n_samples)
    H = as_transfer(H)
    if H.shape[1:] != (layout.n_points, layout.n_actuators):
        raise ValidationError(
            f"H has shape {H.shape} but layout {layout.name!r} has {layout.n_points} points and "
            f"{layout.n_actuators} actuators: H must have shape (n_freqs, {layout.n_points}, {layout.n_actuators})"
        )
    fs = check_positive(fs, "fs")
    n = samples_for(H.shape[0], n_samples)
    band = check_band(band, fs)
    if calibrated_band is not None:
        cal_low, cal_high = check_band(calibrated_band, fs, name="calibrated_band")
        if band[0] < cal_low or band[1] > cal_high:
            raise ValidationError(
                f"band=({band[0]:g}, {band[1]:g}) Hz reaches outside the calibrated band "
                f"({cal_low:g}, {cal_high:g}) Hz: H is not known there"
            )
    limit_v = check_positive(limit_v, "limit_v")
    check_choice(on_limit, "on_limit", ("scale", "refuse"))
    check_choice(control, "control", CONTROL_SETS)
    check_choice(check_wraparound, "check_wraparound", (True, False, "warn"))
    target_peak_m = check_positive(target_peak_m, "target_peak_m")
    guard_weight = check_positive(guard_weight, "guard_weight")
    regularization, reg_param = check_regularization(regularization, reg_param)
    target_index = layout.location_index(location)
    duration = n / fs
    t0 = TARGET_FRACTION * duration if t0 is None else t0
    stimulus = ricker(fs, sigma, duration, t0, form=form)
    taper = band_taper(np.fft.rfftfreq(n, 1 / fs), band, check_positive(taper_octaves, "taper_octaves", allow_zero=True))
    reference = np.fft.irfft(np.fft.rfft(target_peak_m * stimulus) * taper, n)
    others = layout.guard_indices if control == "guards" else np.delete(np.arange(layout.n_points), target_index)
    control_indices = np.concatenate([[target_index], others]).astype(int)
    what = f"the {method} design for location {location}"

    gains = None
    desired = reference
    if method in ("funneling", "combination"):
        gains = funneling_gains(layout.actuators_xy, layout.locations_xy[target_index], funneling_amplitude_v,
                                funneling_law, spacing_xy=layout.spacing_xy)
    if method == "funneling":
        control_indices = np.zeros(0, int)
        drives = gains[:, None] * stimulus
    elif method == "time_reversal":
        targets = np.zeros((len(control_indices), n))
        targets[0] = target_peak_m * stimulus
        drives = time_reversal_drives(H[:, control_indices], targets, fs, max_drive=limit_v, band=band,
                                      taper_octaves=taper_octaves)
    else:
        weights = np.full(len(control_indices), guard_weight)
        weights[0] = 1.0
        operator = InverseOperator(H, fs, n_samples=n, control=control_indices, band=band,
                                   regularization=regularization, reg_param=reg_param, taper_octaves=taper_octaves,
                                   weights=weights)
        # The operator applies the band taper itself: hand it the raw target waveform.
        if method == "combination":
            raw_target = combination_target(H, target_index, gains, stimulus, fs, band=None)
            desired = operator.band_limit(raw_target)
        else:
            raw_target = target_peak_m * stimulus
        drives = operator.drives_for_point(target_index, raw_target)

    fraction = float("nan")
    if check_wraparound:
        fraction = _check_wraparound(drives, H, tol=wraparound_tol, action="warn" if check_wraparound == "warn" else "raise")
    drives, scale, needed = apply_drive_limit(drives, limit_v, on_limit, what)
    predicted = predict_response(H, drives)
    return Rendering(
        method=method,
        location=int(location),
        target_index=target_index,
        drives=drives,
        predicted=predicted,
        desired=desired,
        reference=reference,
        fs=fs,
        t0=float(t0),
        sigma=float(sigma),
        band=band,
        scale=scale,
        needed_peak_v=needed,
        reached_peak_m=float(np.max(np.abs(predicted[target_index]))),
        control_indices=control_indices,
        wraparound_fraction=fraction,
        gains=gains,
        layout=layout,
    )
