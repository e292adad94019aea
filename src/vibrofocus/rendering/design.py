"""What a rendering method designs: :class:`Design` (drives, prediction, bounds, metrics).

``Rendering``, its former name, is a deprecated alias (a ``DeprecationWarning`` when used).
"""

from __future__ import annotations

from .._deprecated import module_getattr

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import check_choice
from ..layout import ArrayLayout
from .bound import ContrastBound
from .metrics import focus_metrics

__all__ = ["Design"]


@dataclass(frozen=True, eq=False)
class Design:
    """Drives for one tap and what they are predicted to do: what ``method.design(tm, target)``
    returns (:class:`~vibrofocus.rendering.method.Method`), and :func:`render`.

    The prediction at every calibrated point, the contrast bounds and, through
    :meth:`metrics`, the focus metrics come with the drives.

    Attributes
    ----------
    method : str
        Name the method is registered under (``"funneling"``, ``"inverse"``,
        ``"combination"``, ``"time_reversal"``, ``"contrast"``, ``"constrained"`` or one a
        lab registered).
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
    control_note : str or None
        Set when the control points are not what the method's default names: on a layout
        with no guard points, a default ``control="guards"`` holds down the other
        locations and says so here; a design that controls the target alone is labelled
        ``"no focus control: ..."`` (:data:`~vibrofocus.rendering.methods.NO_FOCUS_CONTROL`).
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
    control_note: str | None = None

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


# ``Rendering``, the former name of :class:`Design`, warns when used (vibrofocus._deprecated).
__getattr__ = module_getattr(__name__, {"Rendering": (__name__, "Design", "vibrofocus.rendering.Design")})
