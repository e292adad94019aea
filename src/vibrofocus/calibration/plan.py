"""What a calibration will play, and for how long: :func:`plan_calibration`.

Also the choice of points and actuators a calibration measures (a subset of the layout).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._docs import fill_doc
from .._validation import check_band, check_choice
from ..defaults import BAND_HZ
from ..errors import ValidationError
from ..layout import ArrayLayout
from ..rigs.base import Rig
from .excitation import METHODS, SweepSettings, default_settings, hadamard_codes

__all__ = ["DEFAULT_METHOD", "CalibrationPlan", "plan_calibration", "subset_points", "MIN_MEASURED_POINTS"]

#: Method of :func:`~.calibrate.calibrate` when none is given.
DEFAULT_METHOD = "mimo"


#: Fewest points a calibration of a subset measures: the skin model's fit
#: (:func:`~.fitmodel.fit_model`) needs two at least, and five (with four actuators:
#: every actuator seen from near and far) kept the inverse filter's fidelity within
#: 0.03 of the full calibration on simulated participants (docs/method.md).
MIN_MEASURED_POINTS = 2


@fill_doc
def subset_points(layout: ArrayLayout, k: int) -> np.ndarray:
    """Which ``k`` points of a layout to measure when the rest are predicted.

    The points spread over the array (a greedy farthest-point choice): first the point
    nearest the actuators' centroid, then each time the point farthest from every point
    already chosen (ties: the lower index). On the reference layout that is location
    5, the four guards (9 mm from each actuator), then the edge locations 2, 4, 6, 8,
    then the corners: each actuator is seen close by and from across the array, which
    the fit of its contact and resonance needs.

    Parameters
    ----------
    %(layout)s
    k : int
        Points to measure, ``MIN_MEASURED_POINTS`` .. ``layout.n_points``.

    Returns
    -------
    ndarray of int, shape (k,)
        Indices into ``layout.points_xy``, sorted.
    """
    n = layout.n_points
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not MIN_MEASURED_POINTS <= k <= n:
        raise ValidationError(f"the number of points to measure must be an integer from {MIN_MEASURED_POINTS} to "
                              f"the layout's {n} points, got {k!r}")
    pts = layout.points_xy
    centre = layout.actuators_xy.mean(axis=0)
    chosen = [int(np.argmin(np.linalg.norm(pts - centre, axis=1)))]
    nearest = np.linalg.norm(pts - pts[chosen[0]], axis=1)
    while len(chosen) < k:
        nxt = int(np.argmax(np.where(np.isin(np.arange(n), chosen), -np.inf, np.round(nearest, 9))))
        chosen.append(nxt)
        nearest = np.minimum(nearest, np.linalg.norm(pts - pts[nxt], axis=1))
    return np.sort(np.asarray(chosen, dtype=int))


def measured_indices(layout: ArrayLayout, measure) -> np.ndarray:
    """``measure`` (a count, or point indices) as sorted indices into ``layout.points_xy``."""
    if isinstance(measure, (int, np.integer)) and not isinstance(measure, bool):
        return subset_points(layout, int(measure))
    idx = _indices(measure, layout.n_points, "measure", "points of the layout")
    if idx.size < MIN_MEASURED_POINTS:
        raise ValidationError(f"measure must name at least {MIN_MEASURED_POINTS} points (the model's fit needs "
                              f"them), got {list(idx)}")
    return idx


def _sub_layout(layout: ArrayLayout, points: Sequence[int] | None, actuators: Sequence[int] | None):
    """The layout restricted to chosen point and actuator indices (order kept)."""
    p_idx = _indices(points, layout.n_points, "points", "points of the layout")
    a_idx = _indices(actuators, layout.n_actuators, "actuators", "actuators of the layout")
    if points is None and actuators is None:
        return layout, p_idx, a_idx
    loc = p_idx[p_idx < layout.n_locations]
    grd = p_idx[p_idx >= layout.n_locations] - layout.n_locations
    if loc.size == 0:
        raise ValidationError("points must include at least one location (not only guard points)")
    sub = ArrayLayout(
        layout.actuators_xy[a_idx], layout.locations_xy[loc], layout.guards_xy[grd],
        spacing_xy=layout.spacing_xy, actuator_names=tuple(layout.actuator_names[i] for i in a_idx),
        guard_names=tuple(layout.guard_names[i] for i in grd), name=f"{layout.name} (subset)",
    )
    # Locations come first in a layout, so keep that order for the recordings too.
    return sub, np.concatenate([loc, grd + layout.n_locations]), a_idx


def _indices(sel: Sequence[int] | None, n: int, name: str, what: str) -> np.ndarray:
    if sel is None:
        return np.arange(n)
    idx = np.asarray(list(sel))
    if idx.size == 0 or not np.issubdtype(idx.dtype, np.integer):
        raise ValidationError(f"{name} must be a non-empty sequence of integer indices, got {sel!r}")
    if idx.min() < 0 or idx.max() >= n:
        raise ValidationError(f"{name} holds an index outside the {n} {what} (valid: 0..{n - 1}): {sel!r}")
    if len(np.unique(idx)) != idx.size:
        raise ValidationError(f"{name} lists an index twice: {sel!r}")
    return np.sort(idx)


@dataclass(frozen=True)
class CalibrationPlan:
    """What a calibration will play and how long the takes last (:func:`plan_calibration`).

    Attributes
    ----------
    method : {"h1", "paper", "mimo"}
    settings : SweepSettings
    point_indices : tuple of int
        Points of the rig's layout calibrated, in recording order.
    actuator_indices : tuple of int
        Actuators of the rig's layout calibrated.
    positions : int
        Vibrometer positions: 1 for a rig that records every point in each take, else
        one per group of points it can record at once (the operator aims at each).
    predicted_indices : tuple of int
        Points of the rig's layout not measured but predicted from the skin model
        fitted to the measured ones (``measure=``); empty when every point is measured.
    positions_saved : int
        Vibrometer positions the predicted points save against measuring every point.
    pause_s : float
        Silence after each take's sweep before the next, s: 0, or what the rig's RMS
        limits over time need for these sweeps (:func:`vibrofocus.rigs.safety.plan_pause_s`).
    pause_note : str
        Why there is a pause, and the ``amplitude_v`` that would need none ("" without a pause).
    """

    method: str
    settings: SweepSettings
    point_indices: tuple[int, ...]
    actuator_indices: tuple[int, ...]
    positions: int
    predicted_indices: tuple[int, ...] = ()
    positions_saved: int = 0
    pause_s: float = 0.0
    pause_note: str = ""

    @property
    def seconds_saved(self) -> float:
        """Sweep time the predicted points save, s (aiming saved comes on top)."""
        return self.positions_saved * self.takes_per_position * self.settings.take_s

    @property
    def takes_per_position(self) -> int:
        """Takes at each vibrometer position: ``repeats`` per actuator, or ``repeats`` for
        all actuators at once (``mimo``)."""
        n_a = 1 if self.method == "mimo" else len(self.actuator_indices)
        return n_a * self.settings.repeats

    @property
    def takes(self) -> int:
        """Takes in all (without re-recordings after dropouts)."""
        return self.positions * self.takes_per_position

    @property
    def duration_s(self) -> float:
        """Real duration of the takes (silence, sweep and tail each) and of the pauses
        between them (at most), s; aiming the vibrometer and re-recordings after dropouts
        come on top."""
        return self.takes * self.settings.take_s + max(0, self.takes - 1) * self.pause_s

    def describe(self) -> str:
        """The plan in one line, e.g. ``"mimo: 8 takes of 2.4 s (...) = 19.2 s of sweeps"``."""
        n_a, n_r = len(self.actuator_indices), self.settings.repeats
        who = (f"all {n_a} actuators at once, {n_r} Hadamard-coded repeats" if self.method == "mimo"
               else f"{n_a} actuator(s) one at a time x {n_r} repeat(s)")
        where = ("every point in each take" if self.positions == 1
                 else f"at each of {self.positions} vibrometer positions")
        text = (f"{self.method}: {self.takes} takes of {self.settings.take_s:.3g} s ({who}, {where}) = "
                f"{_format_duration(self.duration_s)} of sweeps")
        if self.pause_s:
            text += f", with {self.pause_note}"
        if self.positions > 1:
            text += f", plus aiming the vibrometer {self.positions} times"
        if self.predicted_indices:
            n = len(self.point_indices) + len(self.predicted_indices)
            text += (f"; measures {len(self.point_indices)} of {n} points and predicts the other "
                     f"{len(self.predicted_indices)} from the fitted skin model")
            if self.positions_saved:
                text += (f" ({self.positions_saved} aiming(s) and {_format_duration(self.seconds_saved)} "
                         "of sweeps saved)")
        return text


def _format_duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.1f} s"
    minutes, rest = divmod(int(round(seconds)), 60)
    return f"{minutes} min {rest:02d} s"


def plan_calibration(
    rig: Rig,
    *,
    method: str = DEFAULT_METHOD,
    points: Sequence[int] | None = None,
    actuators: Sequence[int] | None = None,
    band: tuple[float, float] = BAND_HZ,
    sweep_s: float | None = None,
    repeats: int | None = None,
    amplitude_v: float = 5.0,
    measure: int | Sequence[int] | None = None,
) -> CalibrationPlan:
    """The takes :func:`calibrate` will record with these arguments, and their real duration.

    Parameters
    ----------
    rig, method, points, actuators, band, sweep_s, repeats, amplitude_v, measure
        As for :func:`calibrate`.

    Returns
    -------
    CalibrationPlan
        ``plan.duration_s`` (s) and ``plan.describe()`` say how long the sweeps take.

    Raises
    ------
    ValidationError
        Bad arguments (nothing is played).
    SafetyError
        No pause between takes brings the sweeps within the rig's limits.
    """
    return _paced(_takes_plan(rig, method=method, points=points, actuators=actuators, band=band, sweep_s=sweep_s,
                              repeats=repeats, amplitude_v=amplitude_v, measure=measure), rig)


def _takes_plan(rig: Rig, *, method: str, points: Sequence[int] | None, actuators: Sequence[int] | None,
                band: tuple[float, float], sweep_s: float | None, repeats: int | None, amplitude_v: float,
                measure: int | Sequence[int] | None) -> CalibrationPlan:
    """:func:`plan_calibration` before its pauses: the takes only (cheap; no limit is checked)."""
    if not isinstance(rig, Rig):
        raise ValidationError(f"rig must be a vibrofocus Rig, got {type(rig).__name__}")
    check_choice(method, "method", METHODS)
    band = check_band(band, rig.fs)
    settings = default_settings(method, rig.fs, band, sweep_s=sweep_s, repeats=repeats, amplitude_v=amplitude_v)
    if measure is not None and points is not None:
        raise ValidationError("give points (a smaller layout) or measure (predict the rest), not both")
    layout, p_idx, a_idx = _sub_layout(rig.layout, points, actuators)
    predicted = np.zeros(0, int)
    if measure is not None:
        rows = measured_indices(layout, measure)
        predicted = np.setdiff1d(p_idx, p_idx[rows])
        p_idx = p_idx[rows]
    if method == "mimo":
        hadamard_codes(len(a_idx), settings.repeats)  # refuses repeats that cannot separate them
    limit = rig.max_points_per_recording

    def positions(n_points: int) -> int:
        return 1 if limit is None else -(-n_points // limit)

    plan = CalibrationPlan(method=method, settings=settings, point_indices=tuple(int(i) for i in p_idx),
                           actuator_indices=tuple(int(i) for i in a_idx), positions=positions(len(p_idx)),
                           predicted_indices=tuple(int(i) for i in predicted),
                           positions_saved=positions(len(p_idx) + len(predicted)) - positions(len(p_idx)))
    return plan


def plan_for_arguments(rig: Rig, plan: CalibrationPlan | None, **arguments: Any) -> CalibrationPlan:
    """``plan`` when :func:`plan_calibration` made it for these ``arguments`` on this rig, else a new one.

    The limits check (the pause search) is the costly part of a plan; a caller that has
    shown the plan passes it on rather than having it searched again.

    Raises
    ------
    ValidationError
        ``plan`` was made for other arguments.
    """
    from dataclasses import replace

    takes = _takes_plan(rig, **arguments)
    if plan is None:
        return _paced(takes, rig)
    if not isinstance(plan, CalibrationPlan) or replace(plan, pause_s=0.0, pause_note="") != takes:
        raise ValidationError("plan must be the CalibrationPlan that plan_calibration gives for the same rig and "
                              "arguments")
    return plan


def _take_drives(plan: CalibrationPlan, n_actuators: int) -> list[np.ndarray]:
    """The drive of every take of ``plan`` in order (one array per distinct take, repeated)."""
    from .excitation import make_excitation

    excitation = make_excitation(plan.settings)
    a_idx = np.asarray(plan.actuator_indices)
    n_r = plan.settings.repeats
    if plan.method == "mimo":
        codes = hadamard_codes(len(a_idx), n_r).astype(float)
        distinct = [np.zeros((n_actuators, excitation.size)) for _ in range(n_r)]
        for r, drive in enumerate(distinct):
            drive[a_idx] = codes[r][:, None] * excitation[None, :]
        per_position = distinct
    else:
        per_position = []
        for channel in a_idx:
            drive = np.zeros((n_actuators, excitation.size))
            drive[channel] = excitation
            per_position += [drive] * n_r
    return per_position * plan.positions


def _paced(plan: CalibrationPlan, rig: Rig) -> CalibrationPlan:
    """``plan`` with the pause after each take that the rig's RMS limits need; refused when none does.

    The takes are placed back to back, as fast as a rig could play them, and measured
    with the rig's own energy budget (:func:`vibrofocus.rigs.safety.plan_levels`).
    """
    from dataclasses import replace

    from ..errors import SafetyError
    from ..rigs.safety import plan_levels, plan_pause_s

    drives = _take_drives(plan, rig.layout.n_actuators)
    levels = plan_levels(drives, rig.fs, rig.limits)
    if levels.fits:
        return plan
    amplitude = plan.settings.amplitude_v * levels.scale_to_fit
    fitting = f"--amplitude-v {math.floor(amplitude * 100) / 100:g}"
    pause = plan_pause_s(drives, rig.fs, rig.limits) if levels.peak_v <= rig.limits.peak_v else None
    if pause is None:
        raise SafetyError(
            f"the calibration plan ({plan.takes} takes of {plan.settings.amplitude_v:g} V peak sweeps) breaks the "
            f"{rig.kind} rig's limits, nothing was played: {levels.broken()}, and no pause between takes helps; "
            f"the largest amplitude that fits is {fitting}")
    note = (f"a pause of {pause:.1f} s after each sweep for the actuators to cool (back to back, the sweeps reach "
            f"{levels.broken()}; {fitting} needs no pause)")
    return replace(plan, pause_s=pause, pause_note=note)
