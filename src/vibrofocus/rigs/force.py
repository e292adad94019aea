"""Strap force sensors: force-sensing resistors (FSRs) under each strap of the array.

Each strap carries an FSR in a voltage divider read by an analog input. Before a
calibration the experimenter tightens every strap to a target force (1 N by default), so
that the coupling of the actuators to the skin is the same from session to session; the
reading is stored with the calibration.

Calibration curve
-----------------
An FSR's resistance falls roughly as ``1 / F``. In a divider with a fixed resistor
``R_m`` to ground and supply ``V_s`` the input reads ``V = V_s R_m / (R_m + R_fsr)``, so
with ``R_fsr = k / F``::

    F = k V / (R_m (V_s - V))

The curve used in practice is a table of (volts, newtons) measured once per sensor by
loading it with known weights, interpolated piecewise-linearly
(:class:`ForceCurve`); :meth:`ForceCurve.default` tabulates the divider model above for
an Interlink FSR 402 class sensor (``k`` = 10 kΩ·N, ``R_m`` = 10 kΩ, ``V_s`` = 5 V), a
starting point until a lab calibrates its own sensors. Readings below the first table
entry are 0 N; above the last one they are flagged as out of range.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime, timezone

import numpy as np

from .._validation import as_array, check_positive
from ..errors import ValidationError

__all__ = ["ForceCurve", "StrapSensors", "StrapReading", "check_straps", "evaluate_straps"]


@dataclass(frozen=True, eq=False)
class ForceCurve:
    """Piecewise-linear calibration of a force-sensing resistor: volts -> newtons.

    Parameters
    ----------
    volts : array_like, shape (n,)
        Input voltages, V, strictly increasing, n >= 2.
    newtons : array_like, shape (n,)
        Forces at those voltages, N, non-decreasing and >= 0.
    """

    volts: np.ndarray
    newtons: np.ndarray

    def __post_init__(self) -> None:
        v = as_array(self.volts, "volts", ndim=1)
        f = as_array(self.newtons, "newtons", ndim=1)
        if len(v) < 2 or len(v) != len(f):
            raise ValidationError(
                f"a force curve needs at least 2 (volts, newtons) pairs of equal length, got {len(v)} volts "
                f"and {len(f)} newtons"
            )
        if np.any(np.diff(v) <= 0):
            raise ValidationError(f"force curve volts must be strictly increasing, got {v.tolist()}")
        if np.any(np.diff(f) < 0) or f.min() < 0:
            raise ValidationError(f"force curve newtons must be >= 0 and non-decreasing, got {f.tolist()}")
        object.__setattr__(self, "volts", v)
        object.__setattr__(self, "newtons", f)

    @classmethod
    def default(cls, *, k_ohm_n: float = 10e3, r_measure_ohm: float = 10e3, supply_v: float = 5.0) -> "ForceCurve":
        """Tabulate the divider model ``F = k V / (R_m (V_s - V))`` from 0 to 20 N."""
        forces = np.array([0.0, 0.1, 0.2, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 3.0, 5.0, 10.0, 20.0])
        r_fsr = np.divide(k_ohm_n, forces, out=np.full_like(forces, np.inf), where=forces > 0)
        volts = supply_v * r_measure_ohm / (r_measure_ohm + r_fsr)
        return cls(volts, forces)

    def __call__(self, volts: np.ndarray) -> np.ndarray:
        """Forces for input voltages, N (same shape as ``volts``)."""
        v = as_array(volts, "volts")
        return np.interp(v, self.volts, self.newtons, left=0.0, right=np.nan)

    def to_dict(self) -> dict:
        return {"volts": self.volts.tolist(), "newtons": self.newtons.tolist()}


@dataclass(frozen=True)
class StrapReading:
    """Strap forces at one moment, with a verdict against the target.

    Attributes
    ----------
    names : tuple of str
    forces_n : ndarray, shape (n_straps,)
        Force per strap, N (NaN where the sensor reads above its calibrated range).
    target_n, tolerance_n : float
        Target strap force and accepted deviation, N.
    verdicts : tuple of str
        Per strap: ``"ok"``, ``"too loose"``, ``"too tight"`` or ``"out of range"``.
    ok : bool
        Every strap is within the tolerance.
    time_utc : str
        ISO 8601 time of the reading.
    simulated : bool
        The forces come from a simulated rig.
    """

    names: tuple[str, ...]
    forces_n: np.ndarray
    target_n: float
    tolerance_n: float
    verdicts: tuple[str, ...]
    ok: bool
    time_utc: str = field(default_factory=lambda: datetime.now(timezone.utc).isoformat(timespec="seconds"))
    simulated: bool = False

    @property
    def message(self) -> str:
        """One line for the experimenter."""
        if self.ok:
            return f"all {len(self.names)} straps within {self.target_n:g} ± {self.tolerance_n:g} N"
        bad = [f"{n}: {v} ({f:.2f} N)" for n, v, f in zip(self.names, self.verdicts, self.forces_n) if v != "ok"]
        return f"adjust before calibrating (target {self.target_n:g} ± {self.tolerance_n:g} N): " + "; ".join(bad)

    def to_dict(self) -> dict:
        """JSON-serialisable form, e.g. for a calibration file's attributes."""
        return {
            "names": list(self.names),
            "forces_n": [None if not np.isfinite(f) else float(f) for f in self.forces_n],
            "target_n": self.target_n,
            "tolerance_n": self.tolerance_n,
            "verdicts": list(self.verdicts),
            "ok": self.ok,
            "time_utc": self.time_utc,
            "simulated": self.simulated,
        }

    def to_dataset(self):
        """An ``xarray.Dataset`` with ``strap_force`` (strap) N, for a calibration file group."""
        import xarray as xr

        return xr.Dataset(
            {
                "strap_force": ("strap", np.asarray(self.forces_n, float), {"units": "N"}),
                "strap_verdict": ("strap", np.asarray(self.verdicts, dtype=str)),
            },
            coords={"strap": list(self.names)},
            attrs={"target_n": self.target_n, "tolerance_n": self.tolerance_n, "ok": int(self.ok),
                   "time_utc": self.time_utc, "simulated": int(self.simulated)},
        )


def evaluate_straps(
    forces_n: np.ndarray, *, names: tuple[str, ...] | None = None, target_n: float = 1.0,
    tolerance_n: float = 0.25, simulated: bool = False,
) -> StrapReading:
    """Compare strap forces with the target and return a :class:`StrapReading`.

    Parameters
    ----------
    forces_n : array_like, shape (n_straps,)
        Force per strap, N; NaN means above the sensor's calibrated range.
    names : tuple of str, optional
    target_n, tolerance_n : float
        Target and accepted deviation, N.
    simulated : bool
    """
    f = as_array(forces_n, "forces_n", ndim=1, finite=False)
    if np.isinf(f).any():
        raise ValidationError("forces_n must not contain Inf")
    target_n = check_positive(target_n, "target_n")
    tolerance_n = check_positive(tolerance_n, "tolerance_n")
    names = tuple(names) if names is not None else tuple(f"strap {i + 1}" for i in range(len(f)))
    if len(names) != len(f):
        raise ValidationError(f"names has {len(names)} entries but there are {len(f)} forces")
    verdicts = []
    for value in f:
        if np.isnan(value):
            verdicts.append("out of range")
        elif value < target_n - tolerance_n:
            verdicts.append("too loose")
        elif value > target_n + tolerance_n:
            verdicts.append("too tight")
        else:
            verdicts.append("ok")
    return StrapReading(names, f, target_n, tolerance_n, tuple(verdicts), all(v == "ok" for v in verdicts),
                        simulated=simulated)


@dataclass(frozen=True)
class StrapSensors:
    """The strap force sensors of a rig: names, calibration curve, target.

    A rig that has them exposes ``read_strap_forces() -> ndarray (n_straps,)`` in N.

    Attributes
    ----------
    names : tuple of str
        One per strap.
    curve : ForceCurve
        Volts to newtons.
    target_n : float
        Strap force asked for, N.
    tolerance_n : float
        Accepted deviation from the target, N.
    """

    names: tuple[str, ...]
    curve: ForceCurve
    target_n: float = 1.0
    tolerance_n: float = 0.25

    def reading(self, volts: np.ndarray) -> StrapReading:
        """Turn mean input voltages, shape (n_straps,), V, into a reading."""
        forces = self.curve(as_array(volts, "volts", ndim=1, shape=(len(self.names),)))
        return evaluate_straps(forces, names=self.names, target_n=self.target_n, tolerance_n=self.tolerance_n)


def has_strap_sensors(rig) -> bool:
    """Whether a rig can read strap forces.

    Parameters
    ----------
    rig : Rig
        Any rig. It can if it offers ``read_strap_forces`` and, where it says which
        sensors it has (``strap_sensors``, e.g. an NI rig without ``force_sensors``), has
        some.

    Returns
    -------
    bool
    """
    return getattr(rig, "read_strap_forces", None) is not None and getattr(rig, "strap_sensors", True) is not None


def check_straps(rig, *, target_n: float | None = None, tolerance_n: float | None = None) -> StrapReading:
    """Read the strap forces of a rig and judge them against the target (default 1 N).

    Parameters
    ----------
    rig : Rig
        Any rig with a ``read_strap_forces()`` method returning N per strap (the NI-DAQ
        rig with ``force_sensors`` configured; the simulated forearm may simulate them).
    target_n, tolerance_n : float, optional
        Override the rig's target and tolerance, N.

    Raises
    ------
    DeviceError
        If the rig has no strap force sensors.
    """
    from .devices import DeviceError

    if not has_strap_sensors(rig):
        raise DeviceError(
            f"the {getattr(rig, 'kind', type(rig).__name__)} rig has no strap force sensors "
            "(configure force_sensors on an nidaq rig)"
        )
    forces = np.asarray(rig.read_strap_forces(), dtype=float)
    sensors = getattr(rig, "strap_sensors", None)
    names = getattr(sensors, "names", None)
    target = target_n if target_n is not None else getattr(sensors, "target_n", 1.0)
    tol = tolerance_n if tolerance_n is not None else getattr(sensors, "tolerance_n", 0.25)
    return evaluate_straps(forces, names=names, target_n=target, tolerance_n=tol,
                           simulated=getattr(rig, "kind", "") == "simulated")
