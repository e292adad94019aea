"""The built-in rendering methods (docs/method.md, "Rendering methods"), as objects: :class:`Funneling`,
:class:`Inverse`, :class:`Combination`, :class:`TimeReversal`, :class:`Contrast` and
:class:`Constrained`, each a :class:`~.method.Method` with its own options.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from dataclasses import field as _field
from typing import Any, ClassVar

import numpy as np

from .._validation import as_array, check_choice, check_in_range, check_positive
from ..defaults import FUNNELING_AMPLITUDE_V
from ..errors import ValidationError
from ._acc import DEFAULT_ACC_REG
from ._checks import as_transfer, check_regularization
from .combination import combination_target
from .contrast import constrained_drives, contrast_drives
from .exact_target import exact_target_spectra
from .funneling import funneling_gains
from .inverse import predict_response
from .method import Method, Problem, Solution
from .metrics import zero_lag_fidelity
from .minimax import MinimaxFrontier, coherence_radius, minimax_filter, minimax_frontier
from .taper import design_grid
from .time_reversal import time_reversal_drives
from .transfer import TransferMatrix

__all__ = ["NO_FOCUS_CONTROL", "Method", "Problem", "Solution", "Funneling", "Inverse", "Combination", "TimeReversal", "Contrast",
           "Constrained", "Minimax", "CONTROL_SETS", "DEFAULT_GUARD_WEIGHT"]

#: Default weight of the quiet control points against the target (see :class:`Inverse`).
DEFAULT_GUARD_WEIGHT = 1.0
#: Which points a design constrains besides the target (see ``control`` of :class:`Inverse`).
CONTROL_SETS = ("guards", "all", "locations", "field")


#: What a design that holds nothing down besides the target is labelled (``Design.control_note``).
NO_FOCUS_CONTROL = "no focus control"


def _check_control(method: Method, default: str, field_allowed: bool) -> str:
    """Validate a method's ``control`` (None: ``default``) and return it."""
    if method.control is None:
        object.__setattr__(method, "_control_defaulted", True)
    control = default if method.control is None else method.control
    check_choice(control, "control", CONTROL_SETS)
    if control == "field" and not field_allowed:
        raise ValidationError(f"control='field' is for the contrast designs (contrast, constrained), "
                              f"not {method.name or type(method).__name__!r}")
    return control


def _control_of(method: Method, p: Problem) -> tuple[np.ndarray, str | None]:
    """The points a design controls (target first) and what to say about them: a default
    ``"guards"`` on a layout with no guards holds down the calibrated area (the other
    locations) instead, and says so; a set with the target alone is "no focus control"."""
    control = method.control
    note = None
    if (getattr(method, "_control_defaulted", False) and control == "guards" and p.tm.layout.n_guards == 0
            and p.tm.layout.n_locations > 1):
        control = "locations"
        note = ("the layout has no guard points: the default holds down the calibrated area instead "
                "(control='locations', the other locations)")
    rows = p.control(control)
    if rows.size == 1:
        note = (f"{NO_FOCUS_CONTROL}: control={control!r} leaves no point besides the target on this layout "
                "(the tap is met there; nothing is held down)")
    return rows, note


@dataclass(frozen=True, kw_only=True)
class Funneling(Method):
    """Funneling (docs/method.md, "Rendering methods"): every actuator plays the tap, at a gain by its distance.

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
    """The inverse filter (docs/method.md, "Rendering methods"): per-frequency pseudo-inverse at the control points.

    Parameters
    ----------
    control : {"guards", "all", "locations"}, optional
        Points held at zero besides the target. ``"guards"`` (default, the paper's): the
        guard points, which keeps the system close to square so the target is met; on a
        layout with no guards the default holds down the other locations instead
        (``Design.control_note`` says so), and a design left with the target alone is
        labelled "no focus control".
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
        control, note = _control_of(self, p)
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
            return Solution(np.fft.irfft(spectra, n, axis=0).T, desired, control, gains, note=note)
        weights = np.full(len(control), self.guard_weight)
        weights[0] = 1.0
        operator = p.tm.inverse_operator(control, band=p.band, regularization=self.regularization,
                                         reg_param=self.reg_param, taper_octaves=self.taper_octaves, weights=weights)
        # The operator applies the band taper itself: hand it the raw target waveform.
        desired = operator.band_limit(raw) if gains is not None else p.reference
        return Solution(operator.drives_for_point(p.target_index, raw), desired, control, gains, note=note)


@dataclass(frozen=True, kw_only=True)
class Combination(Inverse, Funneling):
    """Funneling and inverse filter combined (docs/method.md, "Rendering methods"): the inverse design asks the target
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
    """Time reversal (docs/method.md, "Rendering methods"): the control points' impulse responses played backwards.

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
        control, note = _control_of(self, p)
        targets = np.zeros((len(control), p.n))
        targets[0] = self.target_peak_m * p.stimulus
        drives = time_reversal_drives(p.tm.rows(control), targets, p.fs, max_drive=self.limit_v, band=p.band,
                                      taper_octaves=self.taper_octaves)
        return Solution(drives, control_indices=control, note=note)


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


def _measured(tm: TransferMatrix) -> bool:
    """Whether ``tm`` is a measurement: a coherence with any finite value."""
    return tm.coherence is not None and bool(np.isfinite(tm.coherence).any())


@dataclass(frozen=True, kw_only=True)
class Minimax(Method):
    """Peak-contrast (minimax) design (:func:`~vibrofocus.rendering.minimax_filter`): the
    least largest ``|displacement|`` at the quiet points at a given target fidelity.

    Seconds per design (no extra needed); :meth:`frontier` gives peak contrast against fidelity.

    Parameters
    ----------
    control : {"all", "guards", "locations"}, optional
        Points kept quiet (default ``"all"``: every other calibrated point).
    min_fidelity : float, optional
        Least target fidelity, in (0, 1); default the pseudo-inverse's own (predicted
        through the same ``H``, at most 0.999): equal fidelity, the peak contrast decides.
    support_s : (float, float), optional
        Drive support before and after the tap, s; default from ``H``, as
        :func:`~vibrofocus.rendering.minimax_filter` picks it (twice the waves' arrival at
        the target before the tap, at least 10 ms; 5 ms after).
    drive_budget : float or "auto", optional
        The drive's peak is at most this times the pseudo-inverse's for the same tap (a
        constraint of the program). It keeps the design off the directions where ``H`` is
        small and a measured one is mostly noise; ``None``: unconstrained. ``"auto"``
        (default): 1 (no more drive than the pseudo-inverse) for the nominal program and the
        robust one from a fitted model, none for the robust one from a measurement (its
        norm term already keeps the drive off those directions).
        One solve: where no drive within the budget reaches the fidelity at this tap, the
        design takes twice the least drive that does and warns (``UserWarning``) with the
        cost at ``limit_v``: the tap's peak at the target (um) and the peak contrast,
        beside the inverse filter's. A default support that the program's size limit cut,
        or made per-actuator supports, also warns.
    robust : float, optional
        Designing from a measured ``H`` (one with a coherence): the quiet peak is bounded
        over every ``H`` within ``robust`` standard errors of the measurement (default 1;
        :func:`~vibrofocus.rendering.coherence_radius` with the calibration's averages;
        ``h_radius`` of :func:`~vibrofocus.rendering.minimax_filter`); designing from a
        fitted skin model, over every ``H`` within ``robust`` of its standard errors
        (``TransferMatrix.h_std``). ``None``, or a transfer matrix with no known
        uncertainty (the true ``H``, a single repeat): the nominal program.
    **common
        The options of :class:`Method`; the drives are then scaled to ``limit_v`` (the
        design's contrast and fidelity do not depend on its level).

    Notes
    -----
    Opt-in (:attr:`Method.opt_in`): the demo's default table leaves it out; name it
    (``run_demo(methods=[..., "minimax"])``, ``render("minimax", ...)``).
    """

    opt_in: ClassVar[bool] = True  # seconds per design
    live: ClassVar[bool] = False  # ... so a live server makes its designs ahead, at the locations
    control: str | None = None
    min_fidelity: float | None = None
    support_s: tuple[float, float] | None = None
    drive_budget: float | str | None = "auto"
    robust: float | None = 1.0

    def __post_init__(self) -> None:
        super().__post_init__()
        self._set("control", _check_control(self, "all", field_allowed=False))
        if self.min_fidelity is not None:
            self._set("min_fidelity", check_in_range(self.min_fidelity, "min_fidelity", 0.0, 1.0, inclusive=False))
        if self.support_s is not None:
            support = tuple(check_positive(s, "support_s") for s in self.support_s)
            if len(support) != 2:
                raise ValidationError(f"support_s must be (before, after) in s, got {self.support_s!r}")
            self._set("support_s", support)
        if self.drive_budget is not None and not (isinstance(self.drive_budget, str) and self.drive_budget == "auto"):
            self._set("drive_budget", check_positive(self.drive_budget, "drive_budget"))
        if self.robust is not None:
            self._set("robust", check_positive(self.robust, "robust", allow_zero=True))

    def h_radius(self, tm: TransferMatrix) -> np.ndarray | None:
        """The uncertainty radius of ``tm.H`` the design bounds its quiet peak over (unit of
        ``H``, shape of ``tm.H``): ``robust`` standard errors from the coherence and the
        calibration's averages (``tm.provenance["averages"]``, else 1); without a
        coherence, ``robust`` times a fitted model's standard error (``tm.h_std``,
        :meth:`~vibrofocus.calibration.FittedSkin.transfer_std`); both for a calibration
        that measured a subset of its points: the coherence's radius at the measured ones,
        the fit's standard error at those its fit predicted; ``None`` with no
        ``robust`` or no uncertainty known (a true ``H``, a single repeat)."""
        if self.robust is None:
            return None
        if not _measured(tm):
            # A fitted model's standard error; none known (a true H, one repeat): nominal.
            return None if tm.h_std is None else self.robust * tm.h_std
        radius = coherence_radius(tm.H, tm.coherence, averages=int(tm.provenance.get("averages", 1)))
        if tm.h_std is not None:  # points a subset calibration's fit predicted (no coherence there)
            radius = np.hypot(radius, tm.h_std)
        return self.robust * radius

    def pinv(self, p: Problem) -> tuple[float, float]:
        """Fidelity and peak drive (V) of the paper's pseudo-inverse (:class:`Inverse` with
        its defaults: target and guards controlled) for this tap through ``p.tm``."""
        control = p.control("guards")
        op = p.tm.inverse_operator(control, band=p.band, taper_octaves=self.taper_octaves)
        drives = op.drives_for_point(p.target_index, self.target_peak_m * p.stimulus)
        y = predict_response(p.tm.H, drives)[p.target_index]
        return zero_lag_fidelity(y, p.reference), float(np.max(np.abs(drives)))

    def _targets(self, p: Problem) -> np.ndarray:
        targets = np.zeros((p.tm.n_points, p.n))
        targets[p.target_index] = self.target_peak_m * p.stimulus
        return targets

    def frontier(self, tm: TransferMatrix, target: int, fidelities: Any) -> MinimaxFrontier:
        """Peak contrast against fidelity for the tap at location ``target`` through ``tm``
        (:func:`~vibrofocus.rendering.minimax_frontier`, with this method's quiet points,
        support and taper; no drive limit: contrast and fidelity do not depend on the level).

        Parameters
        ----------
        tm : TransferMatrix
        target : int
            1-based location number.
        fidelities : sequence of float
            Least fidelities, each in (0, 1).

        Returns
        -------
        MinimaxFrontier
        """
        p = self.problem(tm, target)
        return minimax_frontier(p.tm.H, self._targets(p), p.fs, fidelities, band=p.band,
                                quiet=p.control(self.control)[1:], taper_octaves=self.taper_octaves,
                                support_s=self.support_s)

    def solve(self, p: Problem) -> Solution:
        control = p.control(self.control)
        h_radius = self.h_radius(p.tm)
        # "auto": the norm term of a measurement's radius keeps the drive down by itself; a
        # fitted model's standard error is too small to (it needed 8x the true-H design's drive).
        measured = h_radius is not None and _measured(p.tm)
        budget = self.drive_budget if self.drive_budget != "auto" else (None if measured else 1.0)
        fid, peak = self.pinv(p) if (self.min_fidelity is None or budget is not None) else (0.0, 0.0)
        fidelity = self.min_fidelity if self.min_fidelity is not None else min(fid, 0.999)
        max_drive = None if budget is None else budget * peak
        targets = self._targets(p)
        # One solve: the budget is a constraint of the program; where no drive within it
        # reaches the fidelity at this tap, the design takes the least drive that does, and
        # says what that costs at the drive limit (no silent drop of the budget).
        drives, rep = minimax_filter(p.tm.H, targets, p.fs, band=p.band, min_fidelity=fidelity, quiet=control[1:],
                                     max_drive=max_drive, taper_octaves=self.taper_octaves, support_s=self.support_s,
                                     h_radius=h_radius, on_max_drive="least", full_output=True)
        if rep.size_limit:
            warnings.warn(f"minimax at location {p.location}: {rep.size_limit}", UserWarning, stacklevel=3)
        if rep.drive_limited:
            warnings.warn(self._budget_cost(p, rep, max_drive, control), UserWarning, stacklevel=3)
        return Solution(drives, control_indices=control)

    def _budget_cost(self, p: Problem, rep: Any, budget: float, control: np.ndarray) -> str:
        """What a design over the drive budget costs at ``limit_v``: the tap's peak at the
        target (um) and the peak contrast over the quiet points, minimax against the
        pseudo-inverse (scaled to the same limit)."""
        quiet = control[1:]
        op = p.tm.inverse_operator(p.control("guards"), band=p.band, taper_octaves=self.taper_octaves)
        inv = op.drives_for_point(p.target_index, self.target_peak_m * p.stimulus)
        y_inv = predict_response(p.tm.H, inv)
        ti = p.target_index

        def at_limit(y: np.ndarray, peak_drive: float) -> tuple[float, float]:
            tap = float(np.max(np.abs(y[ti])))
            return tap * self.limit_v / peak_drive * 1e6, 20 * np.log10(tap / float(np.max(np.abs(y[quiet]))))

        mm_um, mm_db = at_limit(rep.predicted, rep.peak_drive)
        budget_x = 1.0 if self.drive_budget == "auto" else float(self.drive_budget)
        inv_um, inv_db = at_limit(y_inv, float(np.max(np.abs(inv))))
        return (f"minimax at location {p.location}: fidelity {rep.fidelity:.3f} needs a peak drive of "
                f"{rep.least_drive:.3g} V for the {self.target_peak_m * 1e6:g} um tap, {rep.least_drive / budget:.3g}x "
                f"the drive budget ({budget:.3g} V, {budget_x:g} x the pseudo-inverse's); the design takes twice that; "
                f"at limit_v="
                f"{self.limit_v:g} V its tap peaks at {mm_um:.3g} um with {mm_db:.1f} dB peak contrast, the inverse "
                f"filter's at {inv_um:.3g} um with {inv_db:.1f} dB; lower min_fidelity to keep the budget")
