"""Rendering methods as objects (SPEC §2): options fixed at construction, one verb to run.

Each method is a frozen dataclass whose fields are its options, validated when it is made;
``method.design(tm, target)`` designs the drives of one tap through a
:class:`~.transfer.TransferMatrix` and returns a :class:`~.design.Design`. The steps
every method shares (the tap and its band limit, the wrap-around check, the drive limit,
the prediction and the contrast bounds) live in :meth:`Method.design`; a method supplies
only :meth:`Method.solve`. A lab's own method subclasses :class:`Method` and is
registered by name (:func:`~.registry.register_method`).
"""

from __future__ import annotations

from dataclasses import dataclass
from dataclasses import field as _field
from typing import Any, ClassVar

import numpy as np

from .._validation import as_array, check_band, check_choice, check_positive
from ..defaults import BAND_HZ, DRIVE_LIMIT_V, FUNNELING_AMPLITUDE_V, SIGMA_S, TARGET_FRACTION, TARGET_PEAK_M
from ..errors import CausalityError, ValidationError
from ..signals.ricker import ricker
from ._acc import DEFAULT_ACC_REG
from ._checks import as_transfer, check_regularization
from .bound import contrast_bound
from .causality import DEFAULT_WRAPAROUND_TOL
from .combination import combination_target
from .contrast import constrained_drives, contrast_drives, taper_drive_ends
from .design import Design
from .exact_target import exact_target_spectra
from .funneling import funneling_gains
from .inverse import apply_drive_limit, predict_response
from .taper import design_grid
from .time_reversal import time_reversal_drives
from .transfer import TransferMatrix

__all__ = ["Method", "Problem", "Solution", "Funneling", "Inverse", "Combination", "TimeReversal", "Contrast",
           "Constrained", "CONTROL_SETS", "DEFAULT_GUARD_WEIGHT"]

#: Default weight of the quiet control points against the target (see :class:`Inverse`).
DEFAULT_GUARD_WEIGHT = 1.0
#: Which points a design constrains besides the target (see ``control`` of :class:`Inverse`).
CONTROL_SETS = ("guards", "all", "locations", "field")


@dataclass(frozen=True)
class Problem:
    """One tap to design, as :meth:`Method.solve` receives it.

    Attributes
    ----------
    tm : TransferMatrix
        The transfer matrix (validated; ``tm.H`` is read-only).
    location : int
        1-based location number of the target.
    target_index : int
        Row of the target in ``tm.H``.
    stimulus : ndarray, shape (n,)
        Unit-peak base stimulus (the Ricker), centred at ``t0``.
    reference : ndarray, shape (n,)
        The tap asked at the target, band-limited, m: ``target_peak_m * stimulus`` tapered
        to the band.
    band : (float, float)
        Design band, Hz (validated, inside the calibrated band).
    t0 : float
        Centre of the stimulus, s.
    """

    tm: TransferMatrix
    location: int
    target_index: int
    stimulus: np.ndarray
    reference: np.ndarray
    band: tuple[float, float]
    t0: float

    @property
    def fs(self) -> float:
        return self.tm.fs

    @property
    def n(self) -> int:
        return self.tm.n_samples

    def control(self, control: str) -> np.ndarray:
        """The target's row, then :meth:`others` (the points a design constrains)."""
        return np.concatenate([[self.target_index], self.others(control)]).astype(int)

    def others(self, control: str) -> np.ndarray:
        """Rows held at zero or kept quiet besides the target, for a ``control`` set."""
        layout = self.tm.layout
        if control == "guards":
            return np.asarray(layout.guard_indices, int)
        if control == "locations":
            return np.delete(np.arange(layout.n_locations), self.target_index)
        if control == "all":
            return np.delete(np.arange(layout.n_points), self.target_index)
        return np.zeros(0, int)


@dataclass(frozen=True)
class Solution:
    """What :meth:`Method.solve` returns (a bare drive array stands for ``Solution(drives)``).

    Attributes
    ----------
    drives : ndarray, shape (n_actuators, n)
        Drives, V, before the drive limit.
    desired : ndarray, shape (n,), optional
        Waveform the method aims for at the target, m; default the problem's reference.
    control_indices : ndarray of int, optional
        Points the design constrained, target first; default none.
    gains : ndarray, shape (n_actuators,), optional
        Funneling amplitudes, V.
    quiet_H : ndarray, optional
        Transfer to a quiet grid (``control="field"``), m/V; its prediction is kept.
    """

    drives: np.ndarray
    desired: np.ndarray | None = None
    control_indices: np.ndarray | None = None
    gains: np.ndarray | None = None
    quiet_H: np.ndarray | None = None


@dataclass(frozen=True, kw_only=True)
class Method:
    """Base of the rendering methods: the options every method shares.

    Parameters
    ----------
    band : (float, float)
        Design band, Hz; inside the transfer matrix's calibrated band.
    sigma : float
        Ricker spread of the base stimulus, s.
    target_peak_m : float
        Peak displacement asked at the target, m.
    t0 : float, optional
        Centre of the stimulus, s; default ``TARGET_FRACTION`` (half) of the window,
        room for the drive's pre-ringing before it and the medium's ring-down after it.
    form : {"zero_mean", "printed"}
        Ricker form (:func:`~vibrofocus.signals.ricker`).
    taper_octaves : float
        Band taper roll-off, octaves.
    limit_v : float
        Drive limit, V peak.
    on_limit : {"scale", "refuse"}
        A design over the limit is scaled down or refused
        (:class:`~vibrofocus.errors.DriveLimitError`).
    scale_to_limit : bool
        Scale the drives so that their peak is exactly ``limit_v`` (every method then
        plays at equal peak drive); False keeps the design's own level, scaled only down.
    check_wraparound : bool or "warn"
        Check that the drives, played once from silence, fit the window (raise, warn or
        skip).
    wraparound_tol : float
        Tolerated share of the response energy past the window.
    bounds : bool
        Compute the array's energy-contrast bounds (``Design.bound``, ``bound_all``).

    Notes
    -----
    A subclass adds its own options as fields (with defaults), validates them in
    ``__post_init__`` (calling ``super().__post_init__()``) and implements :meth:`solve`.
    """

    #: Name the method is registered under (set by ``register_method``).
    name: ClassVar[str] = ""
    #: Whether the drives are normalized to the limit by the method itself (never
    #: scaled to it afterwards).
    self_normalized: ClassVar[bool] = False
    #: Whether the drives spread over the whole window (energy designs): a design that
    #: does not fit it has its ends tapered before the wrap-around check.
    spreads_over_window: ClassVar[bool] = False

    band: tuple[float, float] = BAND_HZ
    sigma: float = SIGMA_S
    target_peak_m: float = TARGET_PEAK_M
    t0: float | None = None
    form: str = "zero_mean"
    taper_octaves: float = 0.5
    limit_v: float = DRIVE_LIMIT_V
    on_limit: str = "scale"
    scale_to_limit: bool = True
    check_wraparound: bool | str = True
    wraparound_tol: float = DEFAULT_WRAPAROUND_TOL
    bounds: bool = True

    def __post_init__(self) -> None:
        self._set("sigma", check_positive(self.sigma, "sigma"))
        self._set("target_peak_m", check_positive(self.target_peak_m, "target_peak_m"))
        self._set("taper_octaves", check_positive(self.taper_octaves, "taper_octaves", allow_zero=True))
        self._set("limit_v", check_positive(self.limit_v, "limit_v"))
        check_choice(self.form, "form", ("zero_mean", "printed"))
        check_choice(self.on_limit, "on_limit", ("scale", "refuse"))
        check_choice(self.check_wraparound, "check_wraparound", (True, False, "warn"))
        self._set("wraparound_tol", check_positive(self.wraparound_tol, "wraparound_tol", allow_zero=True))

    def _set(self, name: str, value: Any) -> None:
        """Store a validated (normalized) option on the frozen instance."""
        object.__setattr__(self, name, value)

    def solve(self, problem: Problem) -> Solution | np.ndarray:
        """The drives of one tap, before the drive limit.

        Parameters
        ----------
        problem : Problem

        Returns
        -------
        Solution or ndarray, shape (n_actuators, n)
        """
        raise NotImplementedError(f"{type(self).__name__} must implement solve(problem)")

    def problem(self, tm: TransferMatrix, location: int) -> Problem:
        """The :class:`Problem` of a tap at ``location`` through ``tm`` (band checked)."""
        if not isinstance(tm, TransferMatrix):
            raise ValidationError(f"tm must be a TransferMatrix, got {type(tm).__name__}")
        fs, n = tm.fs, tm.n_samples
        band = check_band(self.band, fs)
        if tm.band is not None and (band[0] < tm.band[0] or band[1] > tm.band[1]):
            raise ValidationError(f"band=({band[0]:g}, {band[1]:g}) Hz reaches outside the calibrated band "
                                  f"({tm.band[0]:g}, {tm.band[1]:g}) Hz: H is not known there")
        target_index = tm.layout.location_index(location)
        duration = n / fs
        t0 = TARGET_FRACTION * duration if self.t0 is None else float(self.t0)
        stimulus = ricker(fs, self.sigma, duration, t0, form=self.form)
        taper = design_grid(n, fs, band, self.taper_octaves)[1]
        reference = np.fft.irfft(np.fft.rfft(self.target_peak_m * stimulus) * taper, n)
        return Problem(tm, int(location), target_index, stimulus, reference, band, t0)

    def design(self, tm: TransferMatrix, target: int) -> Design:
        """Design the drives of a tap at location ``target`` through ``tm``.

        Parameters
        ----------
        tm : TransferMatrix
        target : int
            1-based location number.

        Returns
        -------
        Design
        """
        p = self.problem(tm, target)
        found = self.solve(p)
        found = found if isinstance(found, Solution) else Solution(np.asarray(found, float))
        drives = as_array(found.drives, "drives", ndim=2, shape=(tm.n_actuators, tm.n_samples))
        desired = p.reference if found.desired is None else found.desired
        what = f"the {self.name or type(self).__name__} design for location {p.location}"
        fraction = float("nan")
        if self.check_wraparound:
            check = tm.wraparound_check()
            if self.spreads_over_window and check._exceeds(drives, self.wraparound_tol)[0]:
                # Noise in a measured H spreads a little of these designs' drive over the
                # whole window (DRIVE_WINDOW_TAPER): taper the window's ends, then check.
                drives = taper_drive_ends(drives, int(np.argmax(np.abs(desired))))
            try:
                fraction = check.check(drives, tol=self.wraparound_tol,
                                       action="warn" if self.check_wraparound == "warn" else "raise")
            except CausalityError as exc:
                raise CausalityError(f"{what}: {exc}") from None
        drives, scale, needed = apply_drive_limit(drives, self.limit_v, self.on_limit, what)
        if self.scale_to_limit and not self.self_normalized:
            if needed == 0:
                raise ValidationError(f"{what} gives silent drives: nothing to scale to the limit")
            drives = drives * (self.limit_v / float(np.max(np.abs(drives))))
            scale = self.limit_v / needed
        predicted = predict_response(tm.H, drives)
        bound, bound_all = self._bounds(p) if self.bounds else (None, None)
        return Design(
            method=self.name or type(self).__name__, location=p.location, target_index=p.target_index,
            drives=drives, predicted=predicted, desired=desired, reference=p.reference, fs=tm.fs, t0=p.t0,
            sigma=float(self.sigma), band=p.band, scale=scale, needed_peak_v=needed,
            reached_peak_m=float(np.max(np.abs(predicted[p.target_index]))),
            control_indices=np.zeros(0, int) if found.control_indices is None else found.control_indices,
            wraparound_fraction=fraction, gains=found.gains, layout=tm.layout,
            scaled_to_limit=bool(self.scale_to_limit), bound=bound, bound_all=bound_all,
            field_predicted=None if found.quiet_H is None else predict_response(found.quiet_H, drives),
            target_xy=np.array(tm.layout.points_xy[p.target_index], dtype=float),
        )

    def _bounds(self, p: Problem):
        """Energy-contrast bounds at the target against the other locations and all points."""
        layout, ti = p.tm.layout, p.target_index
        common = dict(band=p.band, fs=p.fs, waveform=self.target_peak_m * p.stimulus,
                      taper_octaves=self.taper_octaves)
        others = np.delete(np.arange(layout.n_locations), ti)
        bound = contrast_bound(p.tm, ti, others, **common) if others.size else None
        return bound, contrast_bound(p.tm, ti, np.delete(np.arange(layout.n_points), ti), **common)


def _check_control(method: Method, default: str, field_allowed: bool) -> str:
    """Validate a method's ``control`` (None: ``default``) and return it."""
    control = default if method.control is None else method.control
    check_choice(control, "control", CONTROL_SETS)
    if control == "field" and not field_allowed:
        raise ValidationError(f"control='field' is for the contrast designs (contrast, constrained), "
                              f"not {method.name or type(method).__name__!r}")
    return control


@dataclass(frozen=True, kw_only=True)
class Funneling(Method):
    """Funneling (SPEC §2): every actuator plays the tap, at a gain by its distance.

    Parameters
    ----------
    funneling_law : {"linear", "energy"}
        Gain law (:func:`~vibrofocus.rendering.funneling_gains`).
    funneling_amplitude_v : float
        Funneling amplitude ``A``, V.
    **common
        The options of :class:`Method`.
    """

    funneling_law: str = "linear"
    funneling_amplitude_v: float = FUNNELING_AMPLITUDE_V

    def __post_init__(self) -> None:
        super().__post_init__()
        check_choice(self.funneling_law, "funneling_law", ("linear", "energy"))
        self._set("funneling_amplitude_v", check_positive(self.funneling_amplitude_v, "funneling_amplitude_v"))

    def gains(self, p: Problem) -> np.ndarray:
        """Funneling amplitudes of the actuators for the problem's target, V."""
        layout = p.tm.layout
        return funneling_gains(layout.actuators_xy, layout.locations_xy[p.target_index], self.funneling_amplitude_v,
                               self.funneling_law, spacing_xy=layout.spacing_xy)

    def solve(self, p: Problem) -> Solution:
        gains = self.gains(p)
        return Solution(gains[:, None] * p.stimulus, gains=gains)


@dataclass(frozen=True, kw_only=True)
class Inverse(Method):
    """The inverse filter (SPEC §2): per-frequency pseudo-inverse at the control points.

    Parameters
    ----------
    control : {"guards", "all", "locations"}, optional
        Points held at zero besides the target. ``"guards"`` (default, SPEC §2): the
        guard points, which keeps the system close to square so the target is met.
        ``"all"``: every other calibrated point (a least-squares compromise).
        ``"locations"``: the other locations.
    regularization : {None, "tikhonov", "tsvd"}
    reg_param : float, optional
        See :func:`~vibrofocus.rendering.inverse_filter`.
    guard_weight : float
        Weight of the zero-displacement control points against the target (> 0). The
        default ``DEFAULT_GUARD_WEIGHT = 1.0`` is the source paper's plain pseudo-inverse
        (README, "Choosing the default design").
    exact_target : bool, optional
        Meet the target waveform exactly and fit the other control points in least
        squares, instead of one weighted least-squares fit of all; default False (True
        for :class:`Combination`).
    **common
        The options of :class:`Method`.

    Notes
    -----
    The weighted design goes through the transfer matrix's kept
    :class:`~vibrofocus.rendering.InverseOperator` (``tm.inverse_operator``): a second
    design with the same options reuses its factorization.
    """

    control: str | None = None
    regularization: str | None = None
    reg_param: float | None = None
    guard_weight: float = DEFAULT_GUARD_WEIGHT
    exact_target: bool | None = None
    #: Whether the target is exact when ``exact_target`` is not given.
    exact_by_default: ClassVar[bool] = False

    def __post_init__(self) -> None:
        super().__post_init__()
        self._set("control", _check_control(self, "guards", field_allowed=False))
        self._set("guard_weight", check_positive(self.guard_weight, "guard_weight"))
        reg, param = check_regularization(self.regularization, self.reg_param)
        self._set("regularization", reg)
        self._set("reg_param", param)
        self._set("exact_target", self.exact_by_default if self.exact_target is None else bool(self.exact_target))

    def raw_target(self, p: Problem, gains: np.ndarray | None) -> np.ndarray:
        """The target waveform before the band limit, m."""
        return self.target_peak_m * p.stimulus

    def solve(self, p: Problem) -> Solution:
        control = p.control(self.control)
        others = control[1:]
        gains = self.gains(p) if isinstance(self, Funneling) else None
        raw = self.raw_target(p, gains)
        if self.exact_target:
            n = p.n
            taper = design_grid(n, p.fs, p.band, self.taper_octaves)[1]
            desired = np.fft.irfft(np.fft.rfft(raw) * taper, n)
            active = np.flatnonzero(taper > 0)
            active = slice(int(active[0]), int(active[-1]) + 1)
            spectra = np.zeros((len(taper), p.tm.n_actuators), complex)
            spectra[active] = exact_target_spectra(p.tm.H[active], p.target_index, np.asarray(others, int),
                                                   np.fft.rfft(desired)[active], self.regularization, self.reg_param)
            return Solution(np.fft.irfft(spectra, n, axis=0).T, desired, control, gains)
        weights = np.full(len(control), self.guard_weight)
        weights[0] = 1.0
        operator = p.tm.inverse_operator(control, band=p.band, regularization=self.regularization,
                                         reg_param=self.reg_param, taper_octaves=self.taper_octaves, weights=weights)
        # The operator applies the band taper itself: hand it the raw target waveform.
        desired = operator.band_limit(raw) if gains is not None else p.reference
        return Solution(operator.drives_for_point(p.target_index, raw), desired, control, gains)


@dataclass(frozen=True, kw_only=True)
class Combination(Inverse, Funneling):
    """Funneling and inverse filter combined (SPEC §2): the inverse design asks the target
    for the displacement funneling gives there, and quiet at the control points.

    Parameters
    ----------
    exact_target : bool, optional
        Default True (the paper's condition: the target's displacement is the funneling
        one); the other options are those of :class:`Inverse` and :class:`Funneling`.
    """

    exact_by_default: ClassVar[bool] = True

    def raw_target(self, p: Problem, gains: np.ndarray | None) -> np.ndarray:
        return combination_target(p.tm, p.target_index, gains, p.stimulus, p.fs, band=None)


@dataclass(frozen=True, kw_only=True)
class TimeReversal(Method):
    """Time reversal (SPEC §2): the control points' impulse responses played backwards.

    Parameters
    ----------
    control : {"guards", "all", "locations"}, optional
        Control points besides the target (default ``"guards"``); their targets are zero.
    **common
        The options of :class:`Method`; the drives are normalized to ``limit_v`` by the
        method itself (``Design.scale`` is 1).
    """

    self_normalized: ClassVar[bool] = True
    control: str | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        self._set("control", _check_control(self, "guards", field_allowed=False))

    def solve(self, p: Problem) -> Solution:
        control = p.control(self.control)
        targets = np.zeros((len(control), p.n))
        targets[0] = self.target_peak_m * p.stimulus
        drives = time_reversal_drives(p.tm.rows(control), targets, p.fs, max_drive=self.limit_v, band=p.band,
                                      taper_octaves=self.taper_octaves)
        return Solution(drives, control_indices=control)


@dataclass(frozen=True, kw_only=True)
class Contrast(Method):
    """Acoustic contrast control, phase-aligned so the target receives the tap exactly
    (:func:`~vibrofocus.rendering.contrast_drives`).

    Parameters
    ----------
    control : {"all", "guards", "locations", "field"}, optional
        Points kept quiet (default ``"all"``: every other calibrated point); ``"field"``:
        the points of a dense skin grid given by ``field``.
    acc_reg : float
        Regularization, relative to the mean eigenvalue of the quiet points' Gram matrix.
    field : ndarray or callable, optional
        ``control="field"``: transfer to the grid, complex, shape (n // 2 + 1, n_grid,
        n_actuators), m/V, or a callable ``field(freqs) -> H_grid``.
    field_xy : ndarray, shape (n_grid, 2), optional
        The grid points, m; those within ``field_exclusion_m`` of the target are not
        counted as quiet.
    field_exclusion_m : float
        See ``field_xy``, m.
    **common
        The options of :class:`Method`.
    """

    spreads_over_window: ClassVar[bool] = True
    control: str | None = None
    acc_reg: float = DEFAULT_ACC_REG
    field: Any = _field(default=None, compare=False, repr=False)
    field_xy: Any = _field(default=None, compare=False, repr=False)
    field_exclusion_m: float = 5e-3

    def __post_init__(self) -> None:
        super().__post_init__()
        self._set("control", _check_control(self, "all", field_allowed=True))
        if (self.control == "field") != (self.field is not None):
            raise ValidationError("a dense quiet grid needs both control='field' and field=... (its transfer matrix)")
        self._set("acc_reg", check_positive(self.acc_reg, "acc_reg", allow_zero=True))
        self._set("field_exclusion_m", check_positive(self.field_exclusion_m, "field_exclusion_m", allow_zero=True))

    def quiet_field(self, p: Problem) -> np.ndarray | None:
        """Transfer to the quiet grid points away from the target (``control="field"``)."""
        if self.field is None:
            return None
        H = p.tm.H
        quiet_H = as_transfer(self.field(p.tm.freqs) if callable(self.field) else self.field, "field")
        if quiet_H.shape[0] != H.shape[0] or quiet_H.shape[2] != H.shape[2]:
            raise ValidationError(
                f"field has shape {quiet_H.shape}; it must have shape ({H.shape[0]}, n_grid, {H.shape[2]}) like H")
        if self.field_xy is None:
            return quiet_H
        field_xy = as_array(self.field_xy, "field_xy", ndim=2, shape=(quiet_H.shape[1], 2))
        far = np.linalg.norm(field_xy - p.tm.layout.locations_xy[p.target_index], axis=1) > self.field_exclusion_m
        if not far.any():
            raise ValidationError(f"every field point lies within field_exclusion_m={self.field_exclusion_m:g} m "
                                  "of the target")
        return quiet_H[:, far, :]

    def energy_drives(self, p: Problem, **options: Any) -> np.ndarray:
        return contrast_drives(p.tm, p.target_index, p.fs, **options)

    def solve(self, p: Problem) -> Solution:
        control = p.control(self.control)
        others = control[1:]
        quiet_H = self.quiet_field(p)
        drives = self.energy_drives(p, quiet_indices=others if others.size else None, quiet_H=quiet_H, band=p.band,
                                    sigma=self.sigma, waveform=self.target_peak_m * p.stimulus,
                                    reg_param=self.acc_reg, taper_octaves=self.taper_octaves)
        return Solution(drives, control_indices=control, quiet_H=quiet_H)


@dataclass(frozen=True, kw_only=True)
class Constrained(Contrast):
    """The best fidelity for a required energy contrast, or a weighted trade-off
    (:func:`~vibrofocus.rendering.constrained_drives`).

    Parameters
    ----------
    contrast_weight : float, optional
        Trade-off weight (relative, >= 0; 0 is the exact tap of :class:`Contrast`).
    min_contrast_db : float, optional
        Required energy contrast against the quiet points, dB. At most one of the two
        (neither: ``contrast_weight=1``).
    **common
        The options of :class:`Contrast`.
    """

    contrast_weight: float | None = None
    min_contrast_db: float | None = None

    def energy_drives(self, p: Problem, **options: Any) -> np.ndarray:
        return constrained_drives(p.tm, p.target_index, p.fs, contrast_weight=self.contrast_weight,
                                  min_contrast_db=self.min_contrast_db, **options)
