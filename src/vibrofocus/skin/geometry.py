"""Surface geometry of the simulated forearm: a tapered cylinder, or a flat plane.

Layout coordinates are surface coordinates: ``x`` is arc length around the arm from
the volar midline (toward the thumb side), ``y`` is length along the arm toward the
wrist, both in metres. On the cylinder a wave that leaves a source can reach a point
the short way or after going once or more around the arm; these paths are the periodic
images of the source at circumferential offsets ``m * C`` (``m = -n .. n``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validation import as_array, check_choice
from ..errors import ValidationError
from .parameters import ForearmParameters

__all__ = ["ForearmGeometry"]


@dataclass(frozen=True)
class ForearmGeometry:
    """Path lengths on the skin surface between sources and points.

    Parameters
    ----------
    circumference_wrist_m, circumference_elbow_m : float
        Circumference at ``wrist_y_m`` and ``elbow_y_m``, m (linear taper between them,
        held constant beyond).
    wrist_y_m, elbow_y_m : float
        Positions of the two ends on the layout's y axis, m.
    kind : {"cylinder", "plane"}
        ``"plane"`` unrolls the arm onto an infinite plane (no wave comes back); it is
        the reference for checks of the propagation law.
    n_images : int
        Number of turns around the arm taken into account in each direction.
    """

    circumference_wrist_m: float = 0.17
    circumference_elbow_m: float = 0.25
    wrist_y_m: float = 0.125
    elbow_y_m: float = -0.125
    kind: str = "cylinder"
    n_images: int = 2

    def __post_init__(self) -> None:
        check_choice(self.kind, "geometry", ("cylinder", "plane"))
        if isinstance(self.n_images, bool) or not isinstance(self.n_images, (int, np.integer)) or self.n_images < 0:
            raise ValidationError(f"n_images must be a non-negative integer, got {self.n_images!r}")

    @classmethod
    def from_parameters(cls, params: ForearmParameters, kind: str = "cylinder", n_images: int = 2) -> "ForearmGeometry":
        """The geometry of a participant's forearm."""
        return cls(params.circumference_wrist_m, params.circumference_elbow_m, params.wrist_y_m,
                   params.elbow_y_m, kind=kind, n_images=n_images)

    @property
    def image_orders(self) -> np.ndarray:
        """ndarray of int: the turn numbers ``m`` summed over (``[0]`` on the plane)."""
        if self.kind == "plane":
            return np.zeros(1, dtype=int)
        return np.arange(-self.n_images, self.n_images + 1)

    def circumference(self, y: np.ndarray) -> np.ndarray:
        """Circumference of the arm at position ``y`` along it, m."""
        y = np.clip(np.asarray(y, dtype=float), self.elbow_y_m, self.wrist_y_m)
        frac = (y - self.elbow_y_m) / (self.wrist_y_m - self.elbow_y_m)
        return self.circumference_elbow_m + frac * (self.circumference_wrist_m - self.circumference_elbow_m)

    def path_lengths(self, points_xy: np.ndarray, sources_xy: np.ndarray) -> np.ndarray:
        """Surface path lengths from every source to every point, per image.

        On the cylinder, a point's angle around the arm is ``x / r(y)``; the
        circumferential path between a source and a point is measured at the radius
        midway between theirs and the along-arm path follows the cone's slope (the
        unrolled, slowly tapering cone), so the distance is symmetric in source and
        point and never shorter than the straight line through the arm:
        ``d_m = sqrt(((phi_p - phi_s) r_mid + m C_mid)^2 + (y_p - y_s)^2 + (r_p - r_s)^2)``.

        Parameters
        ----------
        points_xy : ndarray, shape (n_points, 2)
            Receiving points, m.
        sources_xy : ndarray, shape (n_sources, 2)
            Source centres, m.

        Returns
        -------
        ndarray, shape (n_points, n_sources, n_images_total)
            Path lengths, m; ``n_images_total = 2 n_images + 1`` on the cylinder, 1 on
            the plane.
        """
        p = as_array(points_xy, "points_xy", ndim=2, shape=(None, 2))
        s = as_array(sources_xy, "sources_xy", ndim=2, shape=(None, 2))
        dy = p[:, None, 1] - s[None, :, 1]
        if self.kind == "plane":
            dx = p[:, None, 0] - s[None, :, 0]
            return np.hypot(dx, dy)[..., None]
        r_p = self.circumference(p[:, 1]) / (2 * np.pi)
        r_s = self.circumference(s[:, 1]) / (2 * np.pi)
        r_mid = 0.5 * (r_p[:, None] + r_s[None, :])
        arc = (p[:, None, 0] / r_p[:, None] - s[None, :, 0] / r_s[None, :]) * r_mid
        m = self.image_orders
        arc_m = arc[..., None] + m * (2 * np.pi * r_mid)[..., None]
        along = np.hypot(dy, r_p[:, None] - r_s[None, :])
        return np.hypot(arc_m, along[..., None])

    def to_3d(self, points_xy: np.ndarray) -> np.ndarray:
        """Positions in space of surface points, m.

        Parameters
        ----------
        points_xy : ndarray, shape (n_points, 2)

        Returns
        -------
        ndarray, shape (n_points, 3)
            ``(r sin phi, y, r cos phi)`` with the arm's axis on the y axis; on the plane
            ``(x, y, 0)``.
        """
        p = as_array(points_xy, "points_xy", ndim=2, shape=(None, 2))
        if self.kind == "plane":
            return np.column_stack([p, np.zeros(len(p))])
        r = self.circumference(p[:, 1]) / (2 * np.pi)
        phi = p[:, 0] / r
        return np.column_stack([r * np.sin(phi), p[:, 1], r * np.cos(phi)])
