"""Point answers: where on a picture of the arm area a participant felt the tap, mm.

A block with ``response = "point"`` (docs/protocols.md) asks the participant to point at
the felt place on a picture of the arm area: the location grid, the actuators and a
margin around them (:func:`point_area`). The point is stored in the layout frame in
millimetres, beside its nearest location, which is the answer's ``response``
(:func:`check_point`). The picture's area is stored with the session when it is planned,
so that every answer is checked against the picture the participant saw.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from .._validation import shorten
from ..errors import StudyError
from ..layout import ArrayLayout

__all__ = ["point_area", "check_point", "nearest_location", "MARGIN_PITCHES"]

#: The picture's margin around the actuators and the locations, in location pitches.
MARGIN_PITCHES = 1.0


def _pitch_m(points: np.ndarray) -> float:
    """Smallest distance between two distinct points, m (10 mm for a single point)."""
    if len(points) < 2:
        return 10e-3
    d = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=-1)
    d = d[d > 1e-9]
    return float(d.min()) if d.size else 10e-3


def point_area(layout: ArrayLayout | None = None, locations: Any = None) -> dict[str, Any]:
    """The picture a point answer is given on, in mm (JSON-serialisable; stored with the session).

    Parameters
    ----------
    layout : ArrayLayout, optional
        The array (default :meth:`ArrayLayout.reference`).
    locations : iterable of int, optional
        The location numbers a point may stand for (default all of the layout's).

    Returns
    -------
    dict
        ``x_mm`` and ``y_mm`` (the picture's extent ``[lo, hi]``: the bounding box of the
        actuators and the locations widened by :data:`MARGIN_PITCHES` location pitches),
        ``locations_mm`` (location number as text -> ``[x, y]``) and ``actuators_mm``
        (``[[x, y], ...]``), all in the layout frame.
    """
    layout = layout if layout is not None else ArrayLayout.reference()
    loc = np.asarray(layout.locations_xy, dtype=float)
    act = np.asarray(layout.actuators_xy, dtype=float)
    numbers = tuple(layout.location_numbers) if locations is None else tuple(int(n) for n in locations)
    for n in numbers:
        if not 1 <= n <= len(loc):
            raise StudyError(f"location {n} is not in the layout {layout.name!r} (locations 1-{len(loc)})")
    both = np.vstack([loc, act])
    margin = MARGIN_PITCHES * _pitch_m(loc)
    lo, hi = both.min(axis=0) - margin, both.max(axis=0) + margin

    def mm(v: float) -> float:
        return round(float(v) * 1e3, 6)

    return {
        "x_mm": [mm(lo[0]), mm(hi[0])],
        "y_mm": [mm(lo[1]), mm(hi[1])],
        "locations_mm": {str(n): [mm(loc[n - 1, 0]), mm(loc[n - 1, 1])] for n in numbers},
        "actuators_mm": [[mm(x), mm(y)] for x, y in act],
    }


def nearest_location(point_mm: tuple[float, float], area: Mapping[str, Any]) -> int:
    """The location of ``area`` nearest the point (ties: the lower number)."""
    best, best_d = 0, math.inf
    for key, (x, y) in sorted(area["locations_mm"].items(), key=lambda kv: int(kv[0])):
        d = math.hypot(point_mm[0] - x, point_mm[1] - y)
        if d < best_d - 1e-12:
            best, best_d = int(key), d
    return best


def check_point(point_mm: Any, area: Mapping[str, Any]) -> tuple[tuple[float, float], int]:
    """Validate a point answer against the picture's area; return it and its nearest location.

    Parameters
    ----------
    point_mm : pair of float
        ``(x, y)`` in the layout frame, mm.
    area : mapping
        :func:`point_area`'s dict (the session's).

    Returns
    -------
    ((float, float), int)
        The point, mm, and the nearest location number.

    Raises
    ------
    StudyError
        Not two finite numbers, or outside the picture's area.
    """
    try:
        if isinstance(point_mm, (str, bytes, Mapping)):
            raise TypeError
        items = list(point_mm)
        if len(items) != 2 or any(isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating))
                                  for v in items):
            raise TypeError
        x, y = float(items[0]), float(items[1])
    except TypeError:
        raise StudyError(f"a point answer must be two numbers [x, y] in mm, got {shorten(point_mm)}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise StudyError(f"a point answer must be finite numbers in mm, got [{x!r}, {y!r}]")
    (x0, x1), (y0, y1) = area["x_mm"], area["y_mm"]
    if not (x0 - 1e-9 <= x <= x1 + 1e-9 and y0 - 1e-9 <= y <= y1 + 1e-9):
        raise StudyError(f"the point ({x:g}, {y:g}) mm is outside the picture's area "
                         f"(x {x0:g} to {x1:g} mm, y {y0:g} to {y1:g} mm)")
    return (x, y), nearest_location((x, y), area)
