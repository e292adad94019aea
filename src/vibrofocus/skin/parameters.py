"""Per-participant parameters of the simulated forearm and how a seed draws them.

The nominal values follow SPEC §3; each field documents its literature source and the
range reported there. A participant is the nominal forearm with speed, attenuation,
contact and actuator gain/resonance drawn uniformly within documented spreads.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .._validation import as_array, check_in_range, check_positive
from ..errors import ValidationError
from ..layout import ArrayLayout

__all__ = [
    "ForearmParameters",
    "SPEED_SPREAD",
    "ATTENUATION_SPREAD",
    "WRIST_CONTACT_RANGE",
    "ELBOW_CONTACT_RANGE",
    "GAIN_SPREAD",
    "RESONANCE_SPREAD",
    "Q_RANGE",
]

#: Relative half-width of the uniform draw of the 250 Hz phase speed (±15 %, SPEC §3).
SPEED_SPREAD = 0.15
#: Relative half-width of the uniform draw of the 250 Hz attenuation (±25 %, SPEC §3).
ATTENUATION_SPREAD = 0.25
#: Coupling of wrist-side actuators, drawn uniformly in this range (SPEC §3: 0.4-1.0).
WRIST_CONTACT_RANGE = (0.4, 1.0)
#: Coupling of the other actuators, which sit on the fleshier, wider part of the arm.
ELBOW_CONTACT_RANGE = (0.85, 1.0)
#: Relative half-width of the uniform draw of each actuator's gain (±10 %, SPEC §3).
GAIN_SPREAD = 0.10
#: Relative half-width of each actuator's loaded resonance frequency (±10 %); with the
#: Q draw below it gives the actuators different phase responses.
RESONANCE_SPREAD = 0.10
#: Range of each actuator's loaded quality factor.
Q_RANGE = (0.8, 1.25)


def _frozen(arr: np.ndarray) -> np.ndarray:
    arr = np.array(arr, dtype=float, copy=True)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class ForearmParameters:
    """Physical parameters of one simulated participant's forearm and actuators.

    Parameters
    ----------
    c250_m_s : float
        Phase speed of the surface wave at 250 Hz, m/s. Nominal 3.5 m/s (SPEC §3).
        Skin surface-wave speeds reported in the literature lie between about 2 and
        7 m/s and increase with frequency: Manfredi et al. 2012 (PLoS ONE 7:e31203,
        primate glabrous skin), Shao, Hayward & Visell 2016 (PNAS 113:4188, whole hand,
        about 5-7 m/s), Sofia & Jones 2013 (IEEE Trans. Haptics 6:320, forearm) and
        Dandu et al. 2019 (IEEE World Haptics, forearm, dispersive).
    beta : float
        Dispersion exponent, ``c(f) = c250 (f / 250 Hz)^beta``. Nominal 0.3; the
        literature above implies values between 0 (no dispersion) and about 0.55.
    alpha250_np_m : float
        Attenuation at 250 Hz, Np/m, growing in proportion to frequency. Nominal
        60 Np/m (SPEC §3; reported 30-200 Np/m on the arm, Sofia & Jones 2013,
        Dandu et al. 2019, Shah et al. 2019, Exp. Brain Res.): a 250 Hz wave loses
        about 15 dB to attenuation alone over 30 mm.
    contact_radius_m : float
        Radius of the contact patch of a fully coupled actuator, m. Nominal 3 mm
        (SPEC §3: a contactor on a 14 mm exciter); a partly coupled actuator touches a
        patch of radius ``contact_radius_m * sqrt(contact)`` (area in proportion).
    contact : ndarray, shape (n_actuators,)
        Coupling of each actuator to the skin, 0-1 (1 = full contact). Wrist-side
        actuators of a rigid array sit over the narrowing arm and lose contact
        (SPEC §3: 0.4-1.0 per participant).
    gains : ndarray, shape (n_actuators,)
        Relative electromechanical gain of each actuator (1 = nominal), ±10 % as for
        mass-produced exciters of one type (SPEC §3).
    f0_hz : ndarray, shape (n_actuators,)
        Loaded resonance frequency of each inertial exciter, Hz. Nominal 500 Hz
        (SPEC §3; small 14 mm exciters resonate at a few hundred Hz, and the skin load
        shifts and damps the resonance).
    q : ndarray, shape (n_actuators,)
        Loaded quality factor of each exciter; nominal 1 (skin damping, SPEC §3).
    circumference_wrist_m, circumference_elbow_m : float
        Forearm circumference at the wrist and near the elbow, m. Nominal 0.17 m and
        0.25 m (SPEC §3), typical adult values (ANSUR II anthropometric survey, Gordon
        et al. 2014: wrist about 15-19 cm, forearm about 24-32 cm).
    wrist_y_m, elbow_y_m : float
        Where the wrist and the elbow-side end of the modelled cylinder lie on the
        layout's y axis (y toward the wrist), m. Nominal +0.125 m and -0.125 m: the
        array sits mid-forearm on a 25 cm forearm, where the circumference is 0.21 m.
    seed : int or None
        The seed that drew these parameters (None for hand-made ones).
    """

    contact: np.ndarray
    gains: np.ndarray
    f0_hz: np.ndarray
    q: np.ndarray
    c250_m_s: float = 3.5
    beta: float = 0.3
    alpha250_np_m: float = 60.0
    contact_radius_m: float = 3e-3
    circumference_wrist_m: float = 0.17
    circumference_elbow_m: float = 0.25
    wrist_y_m: float = 0.125
    elbow_y_m: float = -0.125
    seed: int | None = field(default=None)

    def __post_init__(self) -> None:
        contact = as_array(self.contact, "contact", ndim=1)
        n = contact.size
        if n == 0:
            raise ValidationError("contact must hold one value per actuator, got 0")
        if np.any(contact <= 0) or np.any(contact > 1):
            raise ValidationError(f"contact must lie in (0, 1] for every actuator, got {contact.tolist()}")
        arrays = {"contact": contact}
        for name in ("gains", "f0_hz", "q"):
            arr = as_array(getattr(self, name), name, ndim=1, shape=(n,))
            if np.any(arr <= 0):
                raise ValidationError(f"{name} must be > 0 for every actuator, got {arr.tolist()}")
            arrays[name] = arr
        for name, arr in arrays.items():
            object.__setattr__(self, name, _frozen(arr))
        for name in ("c250_m_s", "alpha250_np_m", "contact_radius_m", "circumference_wrist_m",
                     "circumference_elbow_m"):
            object.__setattr__(self, name, check_positive(getattr(self, name), name))
        object.__setattr__(self, "beta", check_in_range(self.beta, "beta", 0.0, 1.0))
        if not self.wrist_y_m > self.elbow_y_m:
            raise ValidationError(
                f"wrist_y_m ({self.wrist_y_m}) must be larger than elbow_y_m ({self.elbow_y_m}): y points to the wrist"
            )

    # ------------------------------------------------------------------ factories
    @classmethod
    def nominal(cls, n_actuators: int, **overrides: float) -> "ForearmParameters":
        """The nominal forearm: identical, fully coupled actuators, SPEC §3 values.

        Parameters
        ----------
        n_actuators : int
            Number of actuators.
        **overrides
            Any scalar field (``c250_m_s=5.0``, ...).
        """
        if isinstance(n_actuators, bool) or not isinstance(n_actuators, (int, np.integer)) or n_actuators < 1:
            raise ValidationError(f"n_actuators must be a positive integer, got {n_actuators!r}")
        ones = np.ones(int(n_actuators))
        return cls(contact=ones, gains=ones, f0_hz=500.0 * ones, q=ones, **overrides)

    @classmethod
    def draw(cls, seed: int, layout: ArrayLayout) -> "ForearmParameters":
        """Draw one participant around the nominal forearm.

        Each quantity is uniform within its spread (module constants): phase speed
        ±``SPEED_SPREAD``, attenuation ±``ATTENUATION_SPREAD``, contact of wrist-side
        actuators (y above the actuators' mean y) in ``WRIST_CONTACT_RANGE`` and of the
        others in ``ELBOW_CONTACT_RANGE``, gains ±``GAIN_SPREAD``, resonance frequency
        ±``RESONANCE_SPREAD`` and Q in ``Q_RANGE``.

        Parameters
        ----------
        seed : int
            Participant seed (>= 0); the same seed always gives the same participant.
        layout : ArrayLayout
            The array (decides which actuators are wrist-side).
        """
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValidationError(f"seed must be a non-negative integer, got {seed!r}")
        rng = np.random.default_rng([int(seed), 0x5117])
        n = layout.n_actuators
        nominal = cls.nominal(n)
        y = layout.actuators_xy[:, 1]
        wrist_side = y > y.mean() + 1e-9
        contact = np.where(
            wrist_side, rng.uniform(*WRIST_CONTACT_RANGE, n), rng.uniform(*ELBOW_CONTACT_RANGE, n)
        )
        return replace(
            nominal,
            c250_m_s=nominal.c250_m_s * (1 + rng.uniform(-SPEED_SPREAD, SPEED_SPREAD)),
            alpha250_np_m=nominal.alpha250_np_m * (1 + rng.uniform(-ATTENUATION_SPREAD, ATTENUATION_SPREAD)),
            contact=contact,
            gains=1 + rng.uniform(-GAIN_SPREAD, GAIN_SPREAD, n),
            f0_hz=nominal.f0_hz * (1 + rng.uniform(-RESONANCE_SPREAD, RESONANCE_SPREAD, n)),
            q=rng.uniform(*Q_RANGE, n),
            seed=int(seed),
        )

    # ------------------------------------------------------------------ derived
    @property
    def n_actuators(self) -> int:
        return int(self.contact.size)

    def phase_speed(self, freqs: np.ndarray) -> np.ndarray:
        """Phase speed ``c(f) = c250 (f / 250 Hz)^beta``, m/s, for ``freqs`` > 0 Hz."""
        return self.c250_m_s * (np.asarray(freqs, dtype=float) / 250.0) ** self.beta

    def attenuation(self, freqs: np.ndarray) -> np.ndarray:
        """Attenuation ``alpha(f) = alpha250 (f / 250 Hz)``, Np/m."""
        return self.alpha250_np_m * np.asarray(freqs, dtype=float) / 250.0

    def to_dict(self) -> dict:
        """JSON-serialisable description (SI units)."""
        out = {}
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            out[name] = value.tolist() if isinstance(value, np.ndarray) else value
        return out
