"""The base of the rendering methods: :class:`Method`, what it solves (:class:`Problem`)
and what its ``solve`` returns (:class:`Solution`).

A method is a frozen dataclass whose fields are its options, validated when it is made;
``method.design(tm, target)`` designs the drives of one tap through a
:class:`~.transfer.TransferMatrix` and returns a :class:`~.design.Design`. The steps every
method shares (the tap and its band limit, the wrap-around check, the drive limit, the
prediction and the contrast bounds) live in :meth:`Method.design`; a method supplies only
:meth:`Method.solve`. The built-in methods are in :mod:`.methods`; a lab's own subclasses
:class:`Method` and is registered by name (:func:`~.registry.register_method`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .._validation import as_array, check_band, check_choice, check_positive
from ..defaults import BAND_HZ, DRIVE_LIMIT_V, SIGMA_S, TARGET_FRACTION, TARGET_PEAK_M
from ..errors import CausalityError, ValidationError
from ..signals.ricker import ricker
from .bound import contrast_bound
from .causality import DEFAULT_WRAPAROUND_TOL
from .contrast import taper_drive_ends
from .design import Design
from .inverse import apply_drive_limit, predict_response, scale_to_peak
from .taper import design_grid
from .transfer import TransferMatrix

__all__ = ["Method", "Problem", "Solution"]


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
    note : str, optional
        What the design's control points are when a default could not be used as it
        stands (``Design.control_note``).
    """

    drives: np.ndarray
    desired: np.ndarray | None = None
    control_indices: np.ndarray | None = None
    gains: np.ndarray | None = None
    quiet_H: np.ndarray | None = None
    note: str | None = None


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
    taper_ends : bool
        A design that does not fit its window has the window's ends tapered (a Tukey
        window over ``DRIVE_WINDOW_TAPER`` of it, centred on the tap) before the
        wrap-around check, as the energy designs always do: noise in a measured ``H``
        spreads a little of an inverse design's drive over the whole window. Default
        False: such a design is refused (or warned about).

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
    #: Whether the method is left out of the default runs (the demo's table) unless named:
    #: a slow design, or one that needs an optional extra.
    opt_in: ClassVar[bool] = False
    #: Whether one design takes milliseconds (closed form per frequency), so a live server
    #: may design a tap at a new point when it is asked (``serve-osc``'s ``/tap_xy``).
    live: ClassVar[bool] = True

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
    taper_ends: bool = False

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
            if (self.spreads_over_window or self.taper_ends) and check._exceeds(drives, self.wraparound_tol)[0]:
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
            drives = scale_to_peak(drives, self.limit_v)
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
            control_note=found.note,
        )

    def _bounds(self, p: Problem):
        """Energy-contrast bounds at the target against the other locations and all points."""
        layout, ti = p.tm.layout, p.target_index
        common = dict(band=p.band, fs=p.fs, waveform=self.target_peak_m * p.stimulus,
                      taper_octaves=self.taper_octaves)
        others = np.delete(np.arange(layout.n_locations), ti)
        bound = contrast_bound(p.tm, ti, others, **common) if others.size else None
        return bound, contrast_bound(p.tm, ti, np.delete(np.arange(layout.n_points), ti), **common)
