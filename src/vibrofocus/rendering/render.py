"""High-level rendering: one call from a calibrated transfer matrix to drives (SPEC §2)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import as_array, check_band, check_choice, check_positive
from ..defaults import (
    BAND_HZ,
    DRIVE_LIMIT_V,
    FUNNELING_AMPLITUDE_V,
    METHODS,
    SIGMA_S,
    TARGET_FRACTION,
    TARGET_PEAK_M,
)
from ..errors import CausalityError, ValidationError
from ..layout import ArrayLayout
from ..signals.ricker import ricker
from ._checks import as_transfer, check_regularization, samples_for
from .causality import DEFAULT_WRAPAROUND_TOL
from .causality import WraparoundCheck
from .combination import combination_target
from .contrast import (
    DEFAULT_ACC_REG,
    ContrastBound,
    constrained_drives,
    contrast_bound,
    contrast_drives,
    exact_target_spectra,
    taper_drive_ends,
)
from .funneling import funneling_gains
from .inverse import InverseOperator, apply_drive_limit, predict_response
from .metrics import focus_metrics
from .taper import band_taper, design_grid
from .time_reversal import time_reversal_drives

__all__ = ["Rendering", "render", "CONTROL_SETS"]

#: Default weight of the quiet control points against the target (see ``render``).
DEFAULT_GUARD_WEIGHT = 1.0
#: Which points a design constrains besides the target: ``"guards"`` (SPEC §2: the
#: target and the guard points) or ``"all"`` (every other calibrated point held at zero).
CONTROL_SETS = ("guards", "all", "locations", "field")
#: Methods whose control points are quiet points of an energy (contrast) design.
CONTRAST_METHODS = ("contrast", "constrained")


@dataclass(frozen=True, eq=False)
class Rendering:
    """Drives for one tap and what they are predicted to do.

    Attributes
    ----------
    method : str
        One of ``"funneling"``, ``"inverse"``, ``"combination"``, ``"time_reversal"``,
        ``"contrast"``, ``"constrained"``.
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
        yardstick across methods. Like ``desired``, at the design's own level: when
        the drives are scaled (``scale != 1``), the prediction is ``scale`` times the
        design's.
    fs : float
        Sample rate, Hz.
    t0 : float
        Centre of the base stimulus in the window, s.
    sigma : float
        Ricker spread, s.
    band : (float, float)
        Design band, Hz.
    scale : float
        Factor applied to the design's drives: ``limit_v / needed_peak_v`` when scaled to
        the limit (up or down, ``scaled_to_limit``) or down to it, else 1.0. Time
        reversal is always normalized to the limit and reports 1.0.
    needed_peak_v : float
        Peak drive the design needed before any scaling, V.
    reached_peak_m : float
        Peak predicted ``|u|`` at the target after scaling, m.
    control_indices : ndarray of int
        Points the design constrained (target first, then the points held at zero or,
        for the contrast designs, kept quiet); empty for funneling.
    wraparound_fraction : float
        Share of the response energy past the window when played once from silence
        (NaN if not checked).
    gains : ndarray, shape (n_actuators,) or None
        Funneling amplitudes, V ("funneling" and "combination").
    layout : ArrayLayout or None
        The layout rendered on.
    scaled_to_limit : bool
        True when the drives were scaled so that their peak is exactly the drive limit
        (``render(..., scale_to_limit=True)``, the default): every method then plays at
        equal peak drive.
    bound : ContrastBound or None
        Energy-contrast bound of the array at this target against the other locations
        (:func:`contrast_bound`, the Ricker's spectrum).
    bound_all : ContrastBound or None
        The same against every other calibrated point (guards included).
    field_predicted : ndarray, shape (n_grid, n) or None
        Displacement predicted over the quiet grid of ``control="field"``, m.
    target_xy : ndarray, shape (2,) or None
        Position of the target on the skin, m (``layout.points_xy[target_index]``).
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
    scaled_to_limit: bool = False
    bound: ContrastBound | None = field(default=None, repr=False)
    bound_all: ContrastBound | None = field(default=None, repr=False)
    field_predicted: np.ndarray | None = field(default=None, repr=False)
    target_xy: np.ndarray | None = None

    @property
    def n_samples(self) -> int:
        return self.drives.shape[1]

    @property
    def time(self) -> np.ndarray:
        """ndarray, shape (n,): sample times, s."""
        return np.arange(self.n_samples) / self.fs

    def metrics(self, *, against: str = "desired", contrast_over: str = "locations",
                field: Any = None) -> dict[str, float]:
        """:func:`focus_metrics` of the prediction, with the array's contrast bound.

        Parameters
        ----------
        against : {"desired", "reference"}
            Waveform the fidelity compares with (``t0`` is its peak).
        contrast_over : {"locations", "points"}
            The contrast compares the target with the other skin locations (the grid a
            participant names; default) or with every other calibrated point, guards
            included. ``contrast_all_db`` and ``energy_contrast_all_db`` always compare
            with every calibrated point.
        field : ndarray, shape (n_grid, n), optional
            Displacement over a dense skin grid, m (default ``field_predicted``); adds
            ``contrast_field_db`` and ``energy_contrast_field_db``.

        Returns
        -------
        dict
            The keys of :func:`focus_metrics`, plus ``bound_db`` (exact-tap energy
            contrast bound against the compared points, dB), ``bound_own_db`` (the bound
            for the waveform the target actually receives: no drive producing it does
            better) and ``bound_all_db`` (exact tap, against all points), when known.
        """
        check_choice(against, "against", ("desired", "reference"))
        check_choice(contrast_over, "contrast_over", ("locations", "points"))
        wanted = self.desired if against == "desired" else self.reference
        compare = None
        bound = self.bound_all
        if contrast_over == "locations" and self.layout is not None:
            compare = np.arange(self.layout.n_locations)
            bound = self.bound
        out = focus_metrics(self.predicted, self.target_index, wanted, self.fs, sigma=self.sigma,
                            drives=self.drives, compare_indices=compare,
                            field=self.field_predicted if field is None else field, bound=bound)
        out["bound_all_db"] = self.bound_all.bound_db if self.bound_all is not None else float("nan")
        return out


def render(
    method: str,
    H: Any,
    fs: float,
    layout: ArrayLayout,
    location: int | None = None,
    *,
    target_xy: Any = None,
    limit_v: float = DRIVE_LIMIT_V,
    on_limit: str = "scale",
    sigma: float = SIGMA_S,
    target_peak_m: float = TARGET_PEAK_M,
    regularization: str | None = None,
    reg_param: float | None = None,
    band: tuple[float, float] = BAND_HZ,
    n_samples: int | None = None,
    t0: float | None = None,
    control: str | None = None,
    funneling_law: str = "linear",
    funneling_amplitude_v: float = FUNNELING_AMPLITUDE_V,
    taper_octaves: float = 0.5,
    form: str = "zero_mean",
    check_wraparound: bool | str = True,
    wraparound_tol: float = DEFAULT_WRAPAROUND_TOL,
    calibrated_band: tuple[float, float] | None = None,
    guard_weight: float = DEFAULT_GUARD_WEIGHT,
    scale_to_limit: bool = True,
    exact_target: bool | None = None,
    contrast_weight: float | None = None,
    min_contrast_db: float | None = None,
    acc_reg: float = DEFAULT_ACC_REG,
    field: Any = None,
    field_xy: Any = None,
    field_exclusion_m: float = 5e-3,
    bounds: bool = True,
) -> Rendering:
    """Render a tap at a layout location, or anywhere on the skin, with one of the methods of SPEC §2.

    Parameters
    ----------
    method : {"funneling", "inverse", "combination", "time_reversal", "contrast", "constrained"}
        ``"contrast"``: acoustic contrast control, phase-aligned so the target receives
        the band-limited tap exactly (:func:`contrast_drives`). ``"constrained"``: the
        best fidelity for a required energy contrast, or a weighted trade-off
        (:func:`constrained_drives`; ``min_contrast_db`` or ``contrast_weight``).
    H : ndarray, complex, shape (n // 2 + 1, n_points, n_actuators), Calibration or model
        Calibrated transfer matrix (m/V) on ``rfftfreq(n, 1 / fs)``, rows in the order of
        ``layout.points_xy`` (locations then guards). A ``Calibration`` gives its
        ``transfer_for(n_samples)`` (default 4096) and its ``band`` as ``calibrated_band``
        (with ``target_xy``: its fitted model ``cal.fit``). A model of the skin, any
        object with ``transfer(points_xy, freqs)`` (a fitted
        :class:`~vibrofocus.calibration.FittedSkin`, or a ``SimulatedForearm`` for its
        true H), gives H at the layout's points (and the target) on
        ``rfftfreq(n_samples, 1 / fs)`` (``n_samples`` default: the model's
        ``design_window()`` if it has one, else 4096); a model with a ``band`` is tapered outside it
        like ``Calibration.transfer_for`` and sets ``calibrated_band``.
    fs : float
        Sample rate, Hz.
    layout : ArrayLayout
    location : int, optional
        1-based location number of the target; give this or ``target_xy``.
    target_xy : (float, float), optional
        Target position on the skin, m, in the layout frame: a tap anywhere, designed
        with a model of the skin as ``H``. The target joins the layout as one more
        location (number ``n_locations + 1``; ``Rendering.layout`` is that layout), so
        the other locations and the guards keep their roles. A model with
        ``on_skin(points_xy)`` refuses a target off its skin area.
    limit_v : float
        Drive limit, V peak.
    on_limit : {"scale", "refuse"}
        A design over the limit is scaled down (reported in ``scale`` and
        ``reached_peak_m``) or refused with :class:`~vibrofocus.errors.DriveLimitError`
        (whatever ``scale_to_limit``).
    scale_to_limit : bool
        True (default): scale the drives up or down so that their peak is exactly
        ``limit_v``, so that every method is compared at equal peak drive (fidelity and
        contrast do not depend on the scale; the target amplitude does). False: keep
        the design's own level (``target_peak_m`` at the target for the inverse and
        contrast designs, funneling at ``funneling_amplitude_v``), scaled only down to
        the limit if needed.
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
    control : {"guards", "all", "locations", "field"}, optional
        Points held at zero (inverse designs) or kept quiet (contrast designs) besides
        the target. ``"guards"`` (default of the inverse designs, SPEC §2): the guard
        points; the other locations are free, which keeps the system close to square
        (5 x 4 in the reference setup) so the target is met. ``"all"`` (default of the
        contrast designs): every other calibrated point (for the inverse designs a
        least-squares compromise that trades target fidelity for quiet elsewhere).
        ``"locations"``: the other locations. ``"field"`` (contrast designs only): the
        points of a dense skin grid given by ``field``.
    exact_target : bool, optional
        Inverse designs: meet the target waveform exactly and fit the other control
        points in least squares (``guard_weight`` then plays no part), instead of one
        weighted least-squares fit of all. Default True for "combination" (the paper's
        condition: its displacement at the target is the funneling one), False for
        "inverse". ``exact_target=False, guard_weight=1`` is the paper's plain
        pseudo-inverse for both.
    contrast_weight, min_contrast_db
        "constrained" only: the trade-off weight (relative, >= 0; 0 is the exact tap of
        "contrast") or the required energy contrast against the quiet points, dB; at most
        one (neither: ``contrast_weight=1``). See :func:`constrained_drives`.
    acc_reg : float
        Regularization of the contrast designs, relative to the mean eigenvalue of the
        quiet points' Gram matrix.
    field : ndarray or callable, optional
        ``control="field"``: transfer to the grid points, complex, shape
        (n // 2 + 1, n_grid, n_actuators), m/V, or a callable ``field(freqs) -> H_grid``
        (e.g. ``lambda f: forearm.transfer(grid_xy, f)``).
    field_xy : ndarray, shape (n_grid, 2), optional
        The grid points, m; those within ``field_exclusion_m`` of the target are not
        counted as quiet (the tap must be able to spread over its own spot).
    field_exclusion_m : float
        See ``field_xy``, m.
    bounds : bool
        Compute the array's energy-contrast bounds (``Rendering.bound``, ``bound_all``).
    funneling_law : {"linear", "energy"}
    funneling_amplitude_v : float
        Funneling ``A``, V ("funneling" and "combination").
    taper_octaves : float
        Band taper roll-off, octaves.
    form : {"zero_mean", "printed"}
        Ricker form; see :func:`~vibrofocus.signals.ricker`.
    check_wraparound : bool or "warn"
        Check that the drives, played once from silence, fit the window (raise
        CausalityError, warn, or skip). The drives of a contrast design that does not
        fit are first tapered at the window's ends (``contrast.DRIVE_WINDOW_TAPER``).
    wraparound_tol : float
        Tolerated share of the response energy past the window.
    calibrated_band : (float, float), optional
        Band the calibration is valid in, Hz (``Calibration.band``); ``band`` must lie
        inside it.
    guard_weight : float
        Weight of the zero-displacement control points relative to the target in the
        least-squares inverse designs (> 0). The default ``DEFAULT_GUARD_WEIGHT = 1.0`` is
        the plain pseudo-inverse of the method's source paper (docs/method.md). With four
        actuators, the target and four guards are five equations for four unknowns, so the
        fit gives up part of the tap's waveform. A smaller weight (e.g. 0.1) keeps more of
        the waveform at the expense of contrast: on simulated forearms, at equal peak
        drive, 0.1 raised the median fidelity from 0.35 to 0.68 but lost 2.9 dB of contrast
        against the other locations, 10 dB against every calibrated point and 58 % of the
        target's peak (``scripts/compare_render_defaults.py``; README, "Choosing the
        default design").

    Returns
    -------
    Rendering
    """
    check_choice(method, "method", METHODS)
    if not isinstance(layout, ArrayLayout):
        raise ValidationError(f"layout must be an ArrayLayout, got {type(layout).__name__}")
    if (location is None) == (target_xy is None):
        raise ValidationError("give the target as location= (a layout location number) or target_xy= (a skin "
                              "position, m), " + ("not both" if location is not None else "one of them"))
    if target_xy is not None and hasattr(H, "transfer_for"):
        if getattr(H, "fit", None) is None:
            raise ValidationError("target_xy needs a model of the skin: fit one to the calibration first "
                                  "(cal.fit = fit_model(cal)) or pass the FittedSkin as H")
        H = H.fit
    if hasattr(H, "transfer") and not hasattr(H, "transfer_for"):
        H, layout, location, calibrated_band = _model_transfer(H, layout, location, target_xy, fs, n_samples,
                                                               calibrated_band, taper_octaves)
    elif target_xy is not None:
        raise ValidationError("target_xy needs a model of the skin as H (a FittedSkin from fit_model, or a "
                              "SimulatedForearm): a measured matrix knows H only at its calibrated points")
    playback = None
    if hasattr(H, "transfer_for") and hasattr(H, "band"):
        # A Calibration carries the band it is valid in: a design outside it is refused.
        if calibrated_band is None:
            calibrated_band = tuple(H.band)
        if hasattr(H, "wraparound_check"):  # its transfer matrix with the check's cached spectra
            playback = H.wraparound_check(4096 if n_samples is None else n_samples)
            H = playback.H
        else:
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
    if control is None:
        control = "all" if method in CONTRAST_METHODS else "guards"
    check_choice(control, "control", CONTROL_SETS)
    if control == "field" and method not in CONTRAST_METHODS:
        raise ValidationError(f"control='field' is for the contrast designs ({', '.join(CONTRAST_METHODS)}), not {method!r}")
    if (control == "field") != (field is not None):
        raise ValidationError("a dense quiet grid needs both control='field' and field=... (its transfer matrix)")
    if method != "constrained" and (contrast_weight is not None or min_contrast_db is not None):
        raise ValidationError("contrast_weight and min_contrast_db are options of method='constrained'")
    if exact_target is None:
        exact_target = method == "combination"
    acc_reg = check_positive(acc_reg, "acc_reg", allow_zero=True)
    check_choice(check_wraparound, "check_wraparound", (True, False, "warn"))
    target_peak_m = check_positive(target_peak_m, "target_peak_m")
    guard_weight = check_positive(guard_weight, "guard_weight")
    regularization, reg_param = check_regularization(regularization, reg_param)
    target_index = layout.location_index(location)
    duration = n / fs
    t0 = TARGET_FRACTION * duration if t0 is None else t0
    stimulus = ricker(fs, sigma, duration, t0, form=form)
    taper = design_grid(n, fs, band, check_positive(taper_octaves, "taper_octaves", allow_zero=True))[1]
    reference = np.fft.irfft(np.fft.rfft(target_peak_m * stimulus) * taper, n)
    if control == "guards":
        others = layout.guard_indices
    elif control == "locations":
        others = np.delete(np.arange(layout.n_locations), target_index)
    elif control == "all":
        others = np.delete(np.arange(layout.n_points), target_index)
    else:
        others = np.zeros(0, int)
    quiet_H = None
    if control == "field":
        quiet_H = field(np.fft.rfftfreq(n, 1 / fs)) if callable(field) else field
        quiet_H = as_transfer(quiet_H, "field")
        if quiet_H.shape[0] != H.shape[0] or quiet_H.shape[2] != H.shape[2]:
            raise ValidationError(
                f"field has shape {quiet_H.shape}; it must have shape ({H.shape[0]}, n_grid, {H.shape[2]}) like H"
            )
        if field_xy is not None:
            field_xy = as_array(field_xy, "field_xy", ndim=2, shape=(quiet_H.shape[1], 2))
            far = np.linalg.norm(field_xy - layout.locations_xy[target_index], axis=1) > check_positive(
                field_exclusion_m, "field_exclusion_m", allow_zero=True)
            if not far.any():
                raise ValidationError(f"every field point lies within field_exclusion_m={field_exclusion_m:g} m of the target")
            quiet_H = quiet_H[:, far, :]
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
    elif method in CONTRAST_METHODS:
        options = dict(quiet_indices=others if others.size else None, quiet_H=quiet_H, band=band, sigma=sigma,
                       waveform=target_peak_m * stimulus, reg_param=acc_reg, taper_octaves=taper_octaves)
        if method == "contrast":
            drives = contrast_drives(H, target_index, fs, **options)
        else:
            drives = constrained_drives(H, target_index, fs, contrast_weight=contrast_weight,
                                        min_contrast_db=min_contrast_db, **options)
    elif exact_target:
        freqs, taper = design_grid(n, fs, band, taper_octaves)
        raw_target = (combination_target(H, target_index, gains, stimulus, fs, band=None)
                      if method == "combination" else target_peak_m * stimulus)
        desired = np.fft.irfft(np.fft.rfft(raw_target) * taper, n)
        active = np.flatnonzero(taper > 0)
        active = slice(int(active[0]), int(active[-1]) + 1)
        spectra = np.zeros((len(freqs), layout.n_actuators), complex)
        spectra[active] = exact_target_spectra(H[active], target_index, np.asarray(others, int),
                                               np.fft.rfft(desired)[active], regularization, reg_param)
        drives = np.fft.irfft(spectra, n, axis=0).T
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
        if playback is None:
            # Contrast designs are checked twice: transform the impulse responses once.
            playback = WraparoundCheck._trusted(H, n, keep=method in CONTRAST_METHODS)
        if method in CONTRAST_METHODS and playback._exceeds(drives, wraparound_tol)[0]:
            # Noise in a measured H spreads a little of these designs' drive over the
            # whole window (DRIVE_WINDOW_TAPER): taper the window's ends, then check.
            drives = taper_drive_ends(drives, int(np.argmax(np.abs(desired))))
        try:
            fraction = playback.check(drives, tol=wraparound_tol, action="warn" if check_wraparound == "warn" else "raise")
        except CausalityError as exc:
            raise CausalityError(f"{what}: {exc}") from None
    drives, scale, needed = apply_drive_limit(drives, limit_v, on_limit, what)
    if scale_to_limit and method != "time_reversal":
        if needed == 0:
            raise ValidationError(f"{what} gives silent drives: nothing to scale to the limit")
        drives = drives * (limit_v / float(np.max(np.abs(drives))))
        scale = limit_v / needed
    predicted = predict_response(H, drives)
    bound = bound_all = None
    if bounds:
        common = dict(band=band, fs=fs, waveform=target_peak_m * stimulus, taper_octaves=taper_octaves)
        others_loc = np.delete(np.arange(layout.n_locations), target_index)
        if others_loc.size:
            bound = contrast_bound(H, target_index, others_loc, **common)
        bound_all = contrast_bound(H, target_index, np.delete(np.arange(layout.n_points), target_index), **common)
    field_predicted = predict_response(quiet_H, drives) if quiet_H is not None else None
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
        scaled_to_limit=bool(scale_to_limit),
        bound=bound,
        bound_all=bound_all,
        field_predicted=field_predicted,
        target_xy=np.array(layout.points_xy[target_index], dtype=float),
    )


def _model_transfer(model: Any, layout: ArrayLayout, location: int | None, target_xy: Any, fs: float,
                    n_samples: int | None, calibrated_band: tuple[float, float] | None, taper_octaves: float):
    """H of a skin model at the layout's points (the target added as a location).

    Returns ``(H, layout, location, calibrated_band)``; see :func:`render`.
    """
    if target_xy is not None:
        target = as_array(target_xy, "target_xy", ndim=1, shape=(2,))
        if not np.isfinite(target).all():
            raise ValidationError(f"target_xy must be finite, got {target.tolist()}")
        if hasattr(model, "on_skin") and not bool(model.on_skin(target[None])[0]):
            area = model.skin_area_description() if hasattr(model, "skin_area_description") else "its skin area"
            raise ValidationError(f"target_xy=({target[0] * 1e3:g}, {target[1] * 1e3:g}) mm lies outside the "
                                  f"model's skin ({area})")
        same = np.flatnonzero(np.all(np.abs(layout.locations_xy - target) < 1e-9, axis=1))
        if same.size:  # a numbered location: no need for a new one
            location = int(same[0]) + 1
        else:
            layout = ArrayLayout(layout.actuators_xy, np.vstack([layout.locations_xy, target]), layout.guards_xy,
                                 spacing_xy=layout.spacing_xy, actuator_names=layout.actuator_names,
                                 guard_names=layout.guard_names, name=f"{layout.name} + target")
            location = layout.n_locations
    # A model that knows its impulse responses (a simulated forearm) picks a window they fit in.
    own_window = getattr(model, "design_window", None)
    n = (4096 if own_window is None else int(own_window(4096))) if n_samples is None else n_samples
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 16 or n % 2:
        raise ValidationError(f"n_samples must be an even integer >= 16, got {n!r}")
    freqs = np.fft.rfftfreq(int(n), 1 / check_positive(fs, "fs"))
    H = np.asarray(model.transfer(layout.points_xy, freqs))
    band = getattr(model, "band", None)
    if band is not None:
        if calibrated_band is None:
            calibrated_band = tuple(band)
        with np.errstate(over="ignore", divide="ignore"):  # band_taper at 0 Hz
            H = H * band_taper(freqs, band, check_positive(taper_octaves, "taper_octaves", allow_zero=True))[:, None, None]
    return H, layout, location, calibrated_band
