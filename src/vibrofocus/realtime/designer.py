"""Designs ready before the tap is asked: :class:`TapDesigner`.

A live server (``vibrofocus serve-osc``) must start a tap within milliseconds of the
message. Designing a tap at a layout location through a :class:`TransferMatrix` takes a
few tens of milliseconds with every check, and evaluating a skin model at a new point
takes about as long again; neither fits. So the designer

- designs every layout location once per method, when the method is chosen, with the
  method's full checks (the wrap-around check included), and keeps the drives;
- evaluates the skin model once, on a grid over the calibrated area (the locations'
  bounding box, widened by half the location pitch), and for a tap anywhere in it
  interpolates the target's transfer row bilinearly between the four grid points
  around it, then designs through a small transfer matrix (the target and the guards)
  with the method's energy bounds and wrap-around check left out: what remains is one
  batched solve and an inverse FFT.

The drive limit is part of every design (the method scales to ``limit_v``), and the rig's
safety layer still checks every drive when it plays.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._docs import fill_doc
from .._validation import as_array, check_positive
from ..errors import CausalityError, ValidationError
from ..layout import ArrayLayout
from ..rendering import TransferMatrix, available_methods, make_method, method_class
from ..rendering.taper import design_grid

__all__ = ["TapDesigner", "CalibratedArea", "GRID_PITCH_M"]

#: Pitch of the grid the skin model is evaluated on for taps anywhere, m. Bilinear
#: interpolation of the complex transfer between points 2.5 mm apart: the shortest
#: wavelength in the 50-400 Hz band on the model skin is several centimetres.
GRID_PITCH_M = 2.5e-3


@dataclass(frozen=True)
class CalibratedArea:
    """The rectangle taps anywhere may be asked in, m (layout frame).

    Attributes
    ----------
    x_m, y_m : (float, float)
        Its extent along x and y, m: the locations' bounding box widened by half the
        location pitch on each side.
    """

    x_m: tuple[float, float]
    y_m: tuple[float, float]

    @classmethod
    @fill_doc
    def of_layout(cls, layout: ArrayLayout) -> "CalibratedArea":
        """The area of a layout's locations.

        Parameters
        ----------
        %(layout)s

        Returns
        -------
        CalibratedArea
        """
        loc = np.asarray(layout.locations_xy, float)
        margin = 0.5 * _pitch(loc)
        lo, hi = loc.min(axis=0) - margin, loc.max(axis=0) + margin
        return cls((float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1])))

    def contains(self, xy: np.ndarray) -> bool:
        """Whether the point ``xy`` (m, shape (2,)) lies in the area (edges included)."""
        return bool(self.x_m[0] - 1e-12 <= xy[0] <= self.x_m[1] + 1e-12
                    and self.y_m[0] - 1e-12 <= xy[1] <= self.y_m[1] + 1e-12)

    def describe(self) -> str:
        """The area in millimetres, as people read it."""
        return (f"x {self.x_m[0] * 1e3:g} to {self.x_m[1] * 1e3:g} mm, "
                f"y {self.y_m[0] * 1e3:g} to {self.y_m[1] * 1e3:g} mm")


def _pitch(points: np.ndarray) -> float:
    """Smallest distance between two distinct points, m (10 mm for a single point)."""
    if len(points) < 2:
        return 10e-3
    d = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=-1)
    d = d[d > 1e-9]
    return float(d.min()) if d.size else 10e-3


class TapDesigner:
    """Drives for taps at layout locations and anywhere in the calibrated area, fast.

    Parameters
    ----------
    tm : TransferMatrix
        Transfer matrix at the layout's points (a calibration's, or a model's), m/V.
    model : object with ``transfer(points_xy, freqs)``, optional
        A skin model (a calibration's ``fit``, or the simulated arm) for taps anywhere;
        without it, :meth:`drives_xy` is refused.
    method : str
        A registered rendering method.
    limit_v : float
        Drive limit, V peak: every design is scaled to at most this.
    grid_pitch_m : float
        Pitch of the model grid, m.

    Attributes
    ----------
    area : CalibratedArea
        Where taps anywhere may be asked.
    method : str
        The method in use.
    """

    def __init__(self, tm: TransferMatrix, model: Any = None, *, method: str = "inverse", limit_v: float,
                 grid_pitch_m: float = GRID_PITCH_M) -> None:
        if not isinstance(tm, TransferMatrix):
            raise ValidationError(f"tm must be a TransferMatrix, got {type(tm).__name__}")
        self.tm = tm
        self.layout = tm.layout
        self.limit_v = check_positive(limit_v, "limit_v")
        self.area = CalibratedArea.of_layout(self.layout)
        self._model = model
        self._pitch = check_positive(grid_pitch_m, "grid_pitch_m")
        self._grid_H: np.ndarray | None = None
        self._guards_H = np.ascontiguousarray(tm.H[:, self.layout.guard_indices, :])
        self._single: dict[tuple[float, float], ArrayLayout] = {}
        self._drives: dict[tuple[str, int], np.ndarray] = {}
        self.method = ""
        self.set_method(method)

    # -- the method ----------------------------------------------------------------------
    def designed_ahead(self, name: str) -> bool:
        """Whether method ``name``'s designs at every location are made (switching to it is free).

        Parameters
        ----------
        name : str

        Returns
        -------
        bool
        """
        return all((name, loc) in self._drives for loc in self.layout.location_numbers)

    @property
    def live(self) -> bool:
        """Whether the method in use designs in milliseconds (:attr:`Method.live`), so a tap
        at a new point (:meth:`drives_xy`) can be designed when it is asked."""
        return type(self._full).live

    def set_method(self, name: str, *, serving: bool = False) -> None:
        """Use method ``name`` from now on; its designs at every location are made now (once:
        a method used before is switched back to at no cost).

        Parameters
        ----------
        name : str
            A registered method's name.
        serving : bool
            Taps are being served: a method whose designs take seconds (not
            :attr:`Method.live`) is taken only if its location designs were made ahead, since
            making nine of them now would hold every tap asked meanwhile.

        Raises
        ------
        ValidationError
            For an unknown name, or a slow method not made ahead while serving (nothing
            changes).
        """
        if not isinstance(name, str) or name not in available_methods():
            raise ValidationError(f"unknown method {str(name)[:80]!r}; known: {', '.join(available_methods())}")
        if serving and not method_class(name).live and not self.designed_ahead(name):
            raise ValidationError(f"{name} designs take seconds each, too long to make while serving; start "
                                  f"serve-osc with --method {name} to have them made ahead")
        options: dict[str, Any] = {"limit_v": self.limit_v, "bounds": False}
        if self.tm.band is not None:
            options["band"] = self.tm.band
        full = make_method(name, **options)
        fast = make_method(name, **options, check_wraparound=False)
        if not self.designed_ahead(name):  # made once: switching back to a method is free
            tapered = None
            drives = {}
            for loc in self.layout.location_numbers:
                try:
                    drives[loc] = full.design(self.tm, loc).drives
                except CausalityError:
                    # As render_fitted (render, the studies): noise in a measured H spreads a
                    # little drive over the whole window; made again with its ends tapered.
                    tapered = tapered or make_method(name, **options, taper_ends=True)
                    drives[loc] = tapered.design(self.tm, loc).drives
            self._drives.update({(name, loc): np.ascontiguousarray(d) for loc, d in drives.items()})
        self._full, self._fast, self.method = full, fast, name
        self._active = design_grid(self.tm.n_samples, self.tm.fs, full.band, full.taper_octaves)[1] > 0

    # -- taps -----------------------------------------------------------------------------
    def drives_at(self, location: int) -> np.ndarray:
        """The drives of a tap at a layout location (designed when the method was chosen).

        Parameters
        ----------
        location : int
            1-based location number.

        Returns
        -------
        ndarray, shape (n_actuators, n_samples)
            V, within ``limit_v``.
        """
        self.layout.location_index(location)  # the message names an unknown location
        return self._drives[(self.method, int(location))]

    def drives_xy(self, xy_m: Any) -> np.ndarray:
        """The drives of a tap at a point of the calibrated area.

        Parameters
        ----------
        xy_m : (float, float)
            The point, m, in the layout frame.

        Returns
        -------
        ndarray, shape (n_actuators, n_samples)
            V, within ``limit_v``.

        Raises
        ------
        ValidationError
            For a point that is not finite or lies off the area, or without a model.
        """
        xy = as_array(xy_m, "xy", ndim=1, shape=(2,))
        if not self.live:
            raise ValidationError(f"a {self.method} design takes seconds, too long for a tap asked live at a new "
                                  "point; tap a location (designed ahead) or use a method designed in milliseconds, "
                                  "such as inverse")
        if not self.area.contains(xy):
            raise ValidationError(f"the point ({xy[0] * 1e3:g}, {xy[1] * 1e3:g}) mm is off the calibrated area "
                                  f"({self.area.describe()})")
        if self._model is None:
            raise ValidationError("taps anywhere need a model of the skin; this calibration has none (fit one with "
                                  "fit_model and save it with the calibration), so give a location instead")
        row = self.transfer_row(xy)
        H = np.concatenate([row[:, None, :], self._guards_H], axis=1)
        layout = ArrayLayout(self.layout.actuators_xy, xy[None, :], self.layout.guards_xy,
                             spacing_xy=self.layout.spacing_xy, actuator_names=self.layout.actuator_names,
                             guard_names=self.layout.guard_names, name="tap")
        # Values from the grid, checked finite when it was made: no second pass over them.
        H.flags.writeable = False
        tm = TransferMatrix._trusted(H, self.tm.fs, layout, self.tm.n_samples, self.tm.band)
        return self._fast.design(tm, 1).drives

    def transfer_row(self, xy_m: np.ndarray) -> np.ndarray:
        """The model's transfer to one point, interpolated on the grid, m/V.

        Parameters
        ----------
        xy_m : ndarray, shape (2,)
            A point of the calibrated area, m.

        Returns
        -------
        ndarray, complex, shape (n_freqs, n_actuators)
        """
        grid = self.prepare_grid()
        gx, gy = self._grid_x, self._grid_y
        fx = float(np.clip((xy_m[0] - gx[0]) / self._dx, 0, len(gx) - 1 - 1e-9))
        fy = float(np.clip((xy_m[1] - gy[0]) / self._dy, 0, len(gy) - 1 - 1e-9))
        i, j = int(fx), int(fy)
        ax, ay = fx - i, fy - j
        corners = (grid[j, i], grid[j, i + 1], grid[j + 1, i], grid[j + 1, i + 1])
        weights = ((1 - ax) * (1 - ay), ax * (1 - ay), (1 - ax) * ay, ax * ay)
        # Outside the design's band its taper zeroes the design: the nearest corner's values.
        row = corners[int(np.argmax(weights))].copy()
        # Inside it, amplitude and phase are interpolated (the log of each corner's ratio
        # to the first): a wave's phase turns across the cell, which a plain mix of complex
        # values would average away.
        active = self._active
        base = corners[0][active]
        with np.errstate(divide="ignore", invalid="ignore"):
            log_ratio = weights[1] * np.log(corners[1][active] / base)
            log_ratio += weights[2] * np.log(corners[2][active] / base)
            log_ratio += weights[3] * np.log(corners[3][active] / base)
            polar = base * np.exp(log_ratio)
        mixed = sum(w * c[active] for w, c in zip(weights, corners))
        row[active] = np.where(np.isfinite(polar), polar, mixed)
        return row

    def prepare_grid(self, progress: Callable[[int, int], Any] | None = None) -> np.ndarray:
        """Evaluate the model on the grid over the area (once; a second call returns it).

        Parameters
        ----------
        progress : callable, optional
            Called with ``(rows done, rows)`` as the grid's rows are evaluated (the
            simulated arm takes tens of seconds over the whole grid).

        Returns
        -------
        ndarray, complex, shape (n_y, n_x, n_freqs, n_actuators)
            m/V.
        """
        if self._grid_H is None:
            if self._model is None:
                raise ValidationError("no model of the skin to evaluate on the grid")
            nx = max(2, int(np.ceil((self.area.x_m[1] - self.area.x_m[0]) / self._pitch)) + 1)
            ny = max(2, int(np.ceil((self.area.y_m[1] - self.area.y_m[0]) / self._pitch)) + 1)
            self._grid_x = np.linspace(*self.area.x_m, nx)
            self._grid_y = np.linspace(*self.area.y_m, ny)
            self._dx, self._dy = self._grid_x[1] - self._grid_x[0], self._grid_y[1] - self._grid_y[0]
            X, Y = np.meshgrid(self._grid_x, self._grid_y)
            points = np.column_stack([X.ravel(), Y.ravel()])
            # A few rows at a time, so that a front-end can say how far it got; each
            # point's transfer is its own, so the rows give the same values as one call.
            step = max(1, ny // 16)
            parts = []
            if progress is not None:
                progress(0, ny)
            for j in range(0, ny, step):
                parts.append(np.asarray(self._model.transfer(points[j * nx:(j + step) * nx], self.tm.freqs)))
                if progress is not None:
                    progress(min(j + step, ny), ny)
            H = np.concatenate(parts, axis=1)  # (n_freqs, n_points, n_actuators)
            if not np.isfinite(H).all():
                raise ValidationError("the skin model's transfer on the grid is not finite")
            self._grid_H = np.ascontiguousarray(np.moveaxis(H, 1, 0).reshape(ny, nx, *H[:, 0].shape))
        return self._grid_H
