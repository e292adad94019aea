"""Geometry of an actuator array and its skin points.

The frame (docs/method.md, reference setup): origin at the array centre, x across the arm toward the thumb side,
y along the arm toward the wrist, metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ._validation import as_array, check_positive
from .errors import ValidationError

__all__ = ["ArrayLayout"]


@dataclass(frozen=True, eq=False)
class ArrayLayout:
    """Actuators, numbered skin locations and quiet guard points.

    The control points of a design are the locations followed by the guards; a point
    index used anywhere in vibrofocus (transfer matrices, metrics) refers to
    :attr:`points_xy`.

    Parameters
    ----------
    actuators_xy : ndarray, shape (n_actuators, 2)
        Actuator centres, m.
    locations_xy : ndarray, shape (n_locations, 2)
        Skin locations a participant can name, m. Location numbers are 1-based in the
        order given.
    guards_xy : ndarray, shape (n_guards, 2)
        Quiet points whose target displacement is always zero, m. May be empty.
    spacing_xy : tuple of float, optional
        Actuator spacings ``(D_x, D_y)`` used by the funneling laws, m. Inferred from
        the smallest non-zero coordinate differences of the actuators if omitted.
    actuator_names, guard_names : tuple of str, optional
        Labels; default ``A1..An`` and ``G1..Gn``.
    name : str
        Human-readable name of the layout.
    """

    actuators_xy: np.ndarray
    locations_xy: np.ndarray
    guards_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    spacing_xy: tuple[float, float] | None = None
    actuator_names: tuple[str, ...] | None = None
    guard_names: tuple[str, ...] | None = None
    name: str = "custom"

    def __post_init__(self) -> None:
        act = as_array(self.actuators_xy, "actuators_xy", ndim=2, shape=(None, 2))
        loc = as_array(self.locations_xy, "locations_xy", ndim=2, shape=(None, 2))
        guards = as_array(self.guards_xy, "guards_xy").reshape(-1, 2) if np.size(self.guards_xy) else np.zeros((0, 2))
        guards = as_array(guards, "guards_xy", ndim=2, shape=(None, 2))
        if len(act) == 0:
            raise ValidationError("actuators_xy must hold at least one actuator, got 0")
        if len(loc) == 0:
            raise ValidationError("locations_xy must hold at least one location, got 0")
        if len(np.unique(np.round(act, 9), axis=0)) != len(act):
            raise ValidationError("actuators_xy holds two actuators at the same position")
        spacing = self.spacing_xy if self.spacing_xy is not None else _infer_spacing(act)
        spacing = tuple(check_positive(s, "spacing_xy") for s in spacing)
        a_names = tuple(self.actuator_names) if self.actuator_names else tuple(f"A{i + 1}" for i in range(len(act)))
        g_names = tuple(self.guard_names) if self.guard_names else tuple(f"G{i + 1}" for i in range(len(guards)))
        if len(a_names) != len(act):
            raise ValidationError(f"actuator_names has {len(a_names)} names for {len(act)} actuators")
        if len(g_names) != len(guards):
            raise ValidationError(f"guard_names has {len(g_names)} names for {len(guards)} guards")
        for attr, value in (
            ("actuators_xy", act),
            ("locations_xy", loc),
            ("guards_xy", guards),
            ("spacing_xy", spacing),
            ("actuator_names", a_names),
            ("guard_names", g_names),
        ):
            if isinstance(value, np.ndarray):
                value = value.copy()
                value.setflags(write=False)
            object.__setattr__(self, attr, value)

    # ------------------------------------------------------------------ factories
    @classmethod
    def reference(cls, guard_offset_m: float = 9e-3) -> "ArrayLayout":
        """The reference setup of docs/method.md, reference setup: 2 x 2 actuators at 45 mm, 3 x 3 locations at
        10 mm pitch numbered row by row from the wrist side, four guards 9 mm from each
        actuator's centre toward the array centre.

        Nine millimetres puts a guard outside the 14 mm exciter's footprint (radius 7 mm),
        where a vibrometer looking through the case opening sees the skin. The paper says
        only "in the vicinity of the actuators" (de Vlam et al. 2023, sec. II.C); the
        distance is our assumption."""
        half = 22.5e-3
        act = np.array([[-half, half], [half, half], [-half, -half], [half, -half]])
        pitch = 10e-3
        loc = np.array([[x, y] for y in (pitch, 0.0, -pitch) for x in (-pitch, 0.0, pitch)])
        guards = act - guard_offset_m * act / np.linalg.norm(act, axis=1, keepdims=True)
        return cls(act, loc, guards, spacing_xy=(2 * half, 2 * half), name="reference 2x2")

    @classmethod
    def grid(
        cls,
        n_actuators_xy: tuple[int, int],
        actuator_pitch_m: float | tuple[float, float],
        n_locations_xy: tuple[int, int],
        location_pitch_m: float,
        guard_offset_m: float | None = None,
        name: str | None = None,
    ) -> "ArrayLayout":
        """A rectangular actuator grid with a rectangular location grid, both centred.

        Locations are numbered row by row from +y (wrist side), left to right, as in
        the reference setup. With ``guard_offset_m`` every actuator gets a guard that
        far toward the origin (none for an actuator at the origin).
        """
        px, py = (actuator_pitch_m, actuator_pitch_m) if np.isscalar(actuator_pitch_m) else actuator_pitch_m
        act = _centred_grid(n_actuators_xy, (px, py))
        loc = _centred_grid(n_locations_xy, (location_pitch_m, location_pitch_m))
        guards = np.zeros((0, 2))
        if guard_offset_m is not None:
            r = np.linalg.norm(act, axis=1, keepdims=True)
            keep = r[:, 0] > guard_offset_m
            guards = act[keep] - guard_offset_m * act[keep] / r[keep]
        nx, ny = n_actuators_xy
        return cls(act, loc, guards, spacing_xy=(px, py), name=name or f"grid {nx}x{ny}")

    @classmethod
    def sleeve(cls, n_around: int = 8, n_along: int = 4, circumference_m: float = 0.21,
               pitch_along_m: float = 0.045, location_pitch_m: float = 0.01,
               n_locations_xy: tuple[int, int] = (9, 12)) -> "ArrayLayout":
        """A sleeve of ``n_around * n_along`` actuators (default 32) unrolled onto the
        (x, y) plane: x is arc length around the arm, y along it."""
        return cls.grid((n_around, n_along), (circumference_m / n_around, pitch_along_m),
                        n_locations_xy, location_pitch_m, name=f"sleeve {n_around}x{n_along}")

    # ------------------------------------------------------------------ derived
    @property
    def n_actuators(self) -> int:
        return len(self.actuators_xy)

    @property
    def n_locations(self) -> int:
        return len(self.locations_xy)

    @property
    def n_guards(self) -> int:
        return len(self.guards_xy)

    @property
    def n_points(self) -> int:
        return self.n_locations + self.n_guards

    @property
    def points_xy(self) -> np.ndarray:
        """ndarray, shape (n_points, 2): locations then guards, m."""
        return np.concatenate([self.locations_xy, self.guards_xy])

    @property
    def location_numbers(self) -> tuple[int, ...]:
        return tuple(range(1, self.n_locations + 1))

    @property
    def point_labels(self) -> tuple[str, ...]:
        """Labels of :attr:`points_xy`: ``"1".."9"`` then guard names."""
        return tuple(str(n) for n in self.location_numbers) + self.guard_names

    @property
    def guard_indices(self) -> np.ndarray:
        """ndarray of int: indices of the guards in :attr:`points_xy`."""
        return np.arange(self.n_locations, self.n_points)

    def location_index(self, location: int) -> int:
        """Index in :attr:`points_xy` of 1-based location number ``location``."""
        if isinstance(location, bool) or not isinstance(location, (int, np.integer)):
            raise ValidationError(f"location must be an integer 1..{self.n_locations}, got {location!r}")
        if not 1 <= location <= self.n_locations:
            raise ValidationError(f"location {location} is outside the layout's locations 1..{self.n_locations}")
        return int(location) - 1

    def to_dict(self) -> dict:
        """JSON-serialisable description (metres)."""
        return {
            "name": self.name,
            "actuators_xy": self.actuators_xy.tolist(),
            "locations_xy": self.locations_xy.tolist(),
            "guards_xy": self.guards_xy.tolist(),
            "spacing_xy": list(self.spacing_xy),
            "actuator_names": list(self.actuator_names),
            "guard_names": list(self.guard_names),
        }

    @classmethod
    def from_dict(cls, data: dict) -> "ArrayLayout":
        """Inverse of :meth:`to_dict`."""
        try:
            return cls(
                np.asarray(data["actuators_xy"], float),
                np.asarray(data["locations_xy"], float),
                np.asarray(data.get("guards_xy", []), float).reshape(-1, 2),
                spacing_xy=tuple(data["spacing_xy"]) if data.get("spacing_xy") else None,
                actuator_names=tuple(data["actuator_names"]) if data.get("actuator_names") else None,
                guard_names=tuple(data["guard_names"]) if data.get("guard_names") else None,
                name=data.get("name", "custom"),
            )
        except KeyError as exc:
            raise ValidationError(f"layout description lacks the key {exc.args[0]!r}") from exc

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ArrayLayout):
            return NotImplemented
        return (
            np.array_equal(self.actuators_xy, other.actuators_xy)
            and np.array_equal(self.locations_xy, other.locations_xy)
            and np.array_equal(self.guards_xy, other.guards_xy)
            and self.spacing_xy == other.spacing_xy
        )

    def __repr__(self) -> str:
        return (
            f"ArrayLayout(name={self.name!r}, n_actuators={self.n_actuators}, "
            f"n_locations={self.n_locations}, n_guards={self.n_guards})"
        )


def _centred_grid(n_xy: tuple[int, int], pitch_xy: tuple[float, float]) -> np.ndarray:
    """Grid centred on the origin, rows from +y down, each row from -x to +x."""
    nx, ny = (int(n) for n in n_xy)
    if nx < 1 or ny < 1:
        raise ValidationError(f"grid sizes must be >= 1, got {n_xy}")
    xs = (np.arange(nx) - (nx - 1) / 2) * pitch_xy[0]
    ys = -(np.arange(ny) - (ny - 1) / 2) * pitch_xy[1]
    return np.array([[x, y] for y in ys for x in xs])


def _infer_spacing(act: np.ndarray) -> tuple[float, float]:
    spacing = []
    for axis in (0, 1):
        diffs = np.diff(np.unique(np.round(act[:, axis], 9)))
        spacing.append(float(diffs.min()) if diffs.size else 1.0)
    return spacing[0], spacing[1]
