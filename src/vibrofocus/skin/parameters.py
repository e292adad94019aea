"""Per-participant parameters of the simulated forearm and how a seed draws them.

The skin's wave law is a causal viscoelastic law (:mod:`.viscoelastic`): a fractional
Kelvin-Voigt shear modulus whose nominal values are fitted to published forearm
measurements by ``scripts/fit_skin_model.py`` (data and sources in
``vibrofocus/skin/data/``). Each field documents what it was fitted to or says that it
is an assumption. A participant is the nominal forearm with the modulus, the fractional
order, contact and actuator gain/resonance drawn uniformly within documented spreads.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .._docs import fill_doc
from .._validation import as_array, check_in_range, check_positive
from ..errors import ValidationError
from ..layout import ArrayLayout
from .layered import LayeredLaw
from .presets import skin_preset
from .viscoelastic import RAYLEIGH_FACTOR_INCOMPRESSIBLE, ViscoelasticLaw

__all__ = [
    "ForearmParameters",
    "NOMINAL_LAW",
    "STIFFNESS_SPREAD",
    "VISCOSITY_SPREAD",
    "LOSS_SPREAD",
    "WRIST_CONTACT_RANGE",
    "ELBOW_CONTACT_RANGE",
    "GAIN_SPREAD",
    "RESONANCE_SPREAD",
    "Q_RANGE",
    "attenuation_range_laws",
]

#: The nominal wave law: :func:`vibrofocus.skin.fit.fit_wave_law` on the forearm data
#: (Zhang et al. 2011, Med. Eng. Phys. 33(1):31-37, doi:10.1016/j.medengphy.2010.08.016:
#: 3.25 m/s at 200 Hz and the Voigt fit of their 100-400 Hz dispersion), rounded to three
#: digits. The fit drives the fractional order to 1: those data are a Voigt law.
#: ``scripts/fit_skin_model.py`` prints the points and residuals (largest 0.9 %).
NOMINAL_LAW = ViscoelasticLaw(mu0_pa=8.65e3, eta_pa_sn=5.61, order=0.999)
#: Relative half-width of the uniform draw of a participant's static shear modulus: the
#: relative SD of Zhang et al. 2011's forearm Voigt elasticity (1.86 / 7.86 kPa).
STIFFNESS_SPREAD = 0.237
#: Relative half-width of the uniform draw of the spring-pot (viscosity) coefficient: the
#: relative SD of Zhang et al. 2011's forearm Voigt viscosity (0.60 / 5.03 Pa s).
VISCOSITY_SPREAD = 0.119
#: Relative half-width of the uniform draw of a layered arm's loss tangent (±25 %, an
#: assumed spread of attenuation between participants: docs/skin-model.md).
LOSS_SPREAD = 0.25
#: Coupling of wrist-side actuators, drawn uniformly in this range (an assumption of the
#: model, see :class:`ForearmParameters`).
WRIST_CONTACT_RANGE = (0.4, 1.0)
#: Coupling of the other actuators, which sit on the fleshier, wider part of the arm.
ELBOW_CONTACT_RANGE = (0.85, 1.0)
#: Relative half-width of the uniform draw of each actuator's gain (±10 %, an assumption).
GAIN_SPREAD = 0.10
#: Relative half-width of each actuator's loaded resonance frequency (±10 %); with the
#: Q draw below it gives the actuators different phase responses.
RESONANCE_SPREAD = 0.10
#: Range of each actuator's loaded quality factor.
Q_RANGE = (0.8, 1.25)


def attenuation_range_laws() -> dict[str, ViscoelasticLaw]:
    """Laws at the low and high end of the drawn range of attenuation, and the nominal.

    Attenuation grows with the viscosity and falls with the stiffness, so the ends of the
    participant draw (:meth:`ForearmParameters.draw`) are the stiffest, least viscous
    skin and the softest, most viscous one.

    Returns
    -------
    dict
        ``{"low": ..., "nominal": NOMINAL_LAW, "high": ...}``.
    """
    def scaled(stiffness: float, viscosity: float) -> ViscoelasticLaw:
        return replace(NOMINAL_LAW, mu0_pa=NOMINAL_LAW.mu0_pa * stiffness,
                       eta_pa_sn=NOMINAL_LAW.eta_pa_sn * viscosity)

    return {"low": scaled(1 + STIFFNESS_SPREAD, 1 - VISCOSITY_SPREAD), "nominal": NOMINAL_LAW,
            "high": scaled(1 - STIFFNESS_SPREAD, 1 + VISCOSITY_SPREAD)}


def _frozen(arr: np.ndarray) -> np.ndarray:
    arr = np.array(arr, dtype=float, copy=True)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class ForearmParameters:
    """Physical parameters of one simulated participant's forearm and actuators.

    Parameters
    ----------
    contact : ndarray, shape (n_actuators,)
        Coupling of each actuator to the skin, 0-1 (1 = full contact). Wrist-side
        actuators of a rigid array sit over the narrowing arm and lose contact. The range
        0.4-1.0 per participant is an assumption of the model (docs/skin-model.md), not a
        measurement.
    gains : ndarray, shape (n_actuators,)
        Relative electromechanical gain of each actuator (1 = nominal). The ±10 % spread
        is an assumption for mass-produced exciters of one type.
    f0_hz : ndarray, shape (n_actuators,)
        Loaded resonance frequency of each inertial exciter, Hz. Nominal 500 Hz: an
        assumption (docs/skin-model.md). The TEAX14C02-8 datasheet could not be checked (see
        ``vibrofocus/skin/data/SOURCES.md``), and no value loaded by skin was found in
        the literature.
    q : ndarray, shape (n_actuators,)
        Loaded quality factor of each exciter; nominal 1 (an assumption: skin damping).
    shear_modulus_pa : float
        Relaxed shear modulus ``mu0`` of the fractional Kelvin-Voigt law, Pa. Nominal
        8.65 kPa, fitted to the forearm data of Zhang et al. 2011 (Med. Eng. Phys.
        33(1):31-37, doi:10.1016/j.medengphy.2010.08.016: Voigt elasticity 7.86 ± 1.86
        kPa at their assumed density, 3.25 m/s at 200 Hz); drawn within ±1 SD.
        Literature range for forearm skin: about 5-13 kPa (Zhang 2011 ±1 SD; dermis
        E/3 of a layered Rayleigh-wave inversion, Li et al. 2022, arXiv).
    spring_pot_pa_sn : float
        Spring-pot coefficient ``eta``, Pa s^n. Nominal 5.61 Pa s, fitted to the same
        data (Voigt viscosity 5.03 ± 0.60 Pa s in Zhang et al. 2011); drawn within
        ±1 SD (4.4-6.8 Pa s here).
    fractional_order : float
        Order ``n`` of the spring-pot (0 < n <= 1). The fit to the forearm data drives it
        to 1 (0.999 ± 0.004): those data are a Voigt law. Fractional orders below 1 fit
        skin about as well elsewhere (Kearney et al. 2015, Phys. Med. Biol.
        60(17):6975, doi:10.1088/0031-9155/60/17/6975, abstract), so the order stays a
        parameter.
    unrelaxed_modulus_pa : float
        High-frequency limit of the modulus, Pa; ``inf`` (default) for the fractional
        Kelvin-Voigt law.
    density_kg_m3 : float
        Skin density, kg/m^3. Nominal 1100, inside the single-layer range 1093-1190
        kg/m^3 of Table 1 of the review in Burns 43(5):909-932, 2017
        (doi:10.1016/j.burns.2016.11.014). Only ``mu / rho`` and ``eta / rho`` matter
        for the waves; the fit holds the density fixed.
    rayleigh_factor : float
        Surface over shear wave speed, 0.9553 for an incompressible solid (the root of
        the Rayleigh equation; soft tissue is nearly incompressible).
    contact_radius_m : float
        Radius of the contact patch of a fully coupled actuator, m. Nominal 3 mm: an
        assumption (docs/skin-model.md) for the contactor of a 14 mm exciter; a partly coupled actuator
        touches a patch of radius ``contact_radius_m * sqrt(contact)`` (area in
        proportion).
    circumference_wrist_m, circumference_elbow_m : float
        Forearm circumference at the wrist and near the elbow, m. Nominal 0.17 m and
        0.25 m (docs/skin-model.md). Typical adult values; not checked against an anthropometric
        table (an assumption).
    wrist_y_m, elbow_y_m : float
        Where the wrist and the elbow-side end of the modelled cylinder lie on the
        layout's y axis (y toward the wrist), m. Nominal +0.125 m and -0.125 m: the
        array sits mid-forearm on a 25 cm forearm, where the circumference is 0.21 m.
    layered : LayeredLaw or None
        A layered skin (:mod:`.layered`) whose law replaces the homogeneous one of the
        fields above; None (default) for the homogeneous law.
    skin : str
        Name of the preset these parameters come from (:mod:`.presets`), carried into
        every output made from them; ``"voigt-fit"`` for the homogeneous law.
    seed : int or None
        The seed that drew these parameters (None for hand-made ones).

    Notes
    -----
    The nominal wave law (``shear_modulus_pa``, ``spring_pot_pa_sn``,
    ``fractional_order``) is :data:`NOMINAL_LAW`; its values, the data they are fitted
    to and the residuals are documented in ``docs/skin-model.md`` and printed by
    ``scripts/fit_skin_model.py``.
    """

    contact: np.ndarray
    gains: np.ndarray
    f0_hz: np.ndarray
    q: np.ndarray
    shear_modulus_pa: float = NOMINAL_LAW.mu0_pa
    spring_pot_pa_sn: float = NOMINAL_LAW.eta_pa_sn
    fractional_order: float = NOMINAL_LAW.order
    unrelaxed_modulus_pa: float = NOMINAL_LAW.mu_inf_pa
    density_kg_m3: float = NOMINAL_LAW.density_kg_m3
    rayleigh_factor: float = RAYLEIGH_FACTOR_INCOMPRESSIBLE
    contact_radius_m: float = 3e-3
    circumference_wrist_m: float = 0.17
    circumference_elbow_m: float = 0.25
    wrist_y_m: float = 0.125
    elbow_y_m: float = -0.125
    layered: LayeredLaw | None = None
    skin: str = "voigt-fit"
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
        for name in ("contact_radius_m", "circumference_wrist_m", "circumference_elbow_m", "shear_modulus_pa",
                     "spring_pot_pa_sn", "density_kg_m3"):
            object.__setattr__(self, name, check_positive(getattr(self, name), name))
        if not self.wrist_y_m > self.elbow_y_m:
            raise ValidationError(
                f"wrist_y_m ({self.wrist_y_m}) must be larger than elbow_y_m ({self.elbow_y_m}): y points to the wrist"
            )
        object.__setattr__(self, "fractional_order",
                           check_in_range(self.fractional_order, "fractional_order", 0.0, 1.0, inclusive=False)
                           if self.fractional_order != 1.0 else 1.0)
        if self.layered is not None and not isinstance(self.layered, LayeredLaw):
            raise ValidationError(f"layered must be a LayeredLaw or None, got {type(self.layered).__name__}")
        if not isinstance(self.skin, str) or not self.skin:
            raise ValidationError(f"skin must be a preset name, got {self.skin!r}")
        law = self.layered or ViscoelasticLaw(
            mu0_pa=self.shear_modulus_pa, eta_pa_sn=self.spring_pot_pa_sn, order=self.fractional_order,
            mu_inf_pa=self.unrelaxed_modulus_pa, density_kg_m3=self.density_kg_m3,
            rayleigh_factor=self.rayleigh_factor,
        )
        object.__setattr__(self, "_law", law)

    # ------------------------------------------------------------------ factories
    @classmethod
    def nominal(cls, n_actuators: int, skin: str = "voigt-fit", **overrides: float) -> "ForearmParameters":
        """The nominal forearm of a skin preset: identical, fully coupled actuators.

        Parameters
        ----------
        n_actuators : int
            Number of actuators.
        skin : str
            Skin preset (:data:`vibrofocus.skin.SKIN_PRESETS`); ``"voigt-fit"`` (default)
            is the homogeneous law of the fields.
        **overrides
            Any scalar field (``shear_modulus_pa=8e3``, ...).
        """
        if isinstance(n_actuators, bool) or not isinstance(n_actuators, (int, np.integer)) or n_actuators < 1:
            raise ValidationError(f"n_actuators must be a positive integer, got {n_actuators!r}")
        preset = skin_preset(skin)
        ones = np.ones(int(n_actuators))
        if preset.law is not None:
            overrides.setdefault("layered", preset.law)
        return cls(contact=ones, gains=ones, f0_hz=500.0 * ones, q=ones, skin=preset.name, **overrides)

    @classmethod
    def from_law(cls, law: ViscoelasticLaw, n_actuators: int, **overrides: float) -> "ForearmParameters":
        """The nominal forearm with another wave law (for sensitivity studies)."""
        return cls.nominal(
            n_actuators, shear_modulus_pa=law.mu0_pa, spring_pot_pa_sn=law.eta_pa_sn,
            fractional_order=law.order, unrelaxed_modulus_pa=law.mu_inf_pa,
            density_kg_m3=law.density_kg_m3, rayleigh_factor=law.rayleigh_factor, **overrides,
        )

    @classmethod
    @fill_doc
    def draw(cls, seed: int, layout: ArrayLayout, skin: str = "voigt-fit") -> "ForearmParameters":
        """Draw one participant around the nominal forearm.

        Each quantity is uniform within its spread (module constants): the static shear
        modulus ±``STIFFNESS_SPREAD`` and the spring-pot coefficient ±``VISCOSITY_SPREAD``
        (one SD of the published forearm values either way), contact of wrist-side actuators (y above
        the actuators' mean y) in ``WRIST_CONTACT_RANGE`` and of the others in
        ``ELBOW_CONTACT_RANGE``, gains ±``GAIN_SPREAD``, resonance frequency
        ±``RESONANCE_SPREAD`` and Q in ``Q_RANGE``. On a layered skin the same two draws
        scale both layers' moduli (±``STIFFNESS_SPREAD``) and the loss tangent
        (±``LOSS_SPREAD``).

        Parameters
        ----------
        %(seed)s
        layout : ArrayLayout
            The array (decides which actuators are wrist-side).
        skin : str
            Skin preset around which to draw (:data:`vibrofocus.skin.SKIN_PRESETS`).
        """
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValidationError(f"seed must be a non-negative integer, got {seed!r}")
        rng = np.random.default_rng([int(seed), 0x5117])
        n = layout.n_actuators
        nominal = cls.nominal(n, skin=skin)
        y = layout.actuators_xy[:, 1]
        wrist_side = y > y.mean() + 1e-9
        contact = np.where(
            wrist_side, rng.uniform(*WRIST_CONTACT_RANGE, n), rng.uniform(*ELBOW_CONTACT_RANGE, n)
        )
        # The draws come in a fixed order, so a seed gives the same participant on every skin.
        stiffness = rng.uniform(-STIFFNESS_SPREAD, STIFFNESS_SPREAD)
        viscosity = rng.uniform(-VISCOSITY_SPREAD, VISCOSITY_SPREAD)
        layered = None if nominal.layered is None else nominal.layered.scaled(
            stiffness=1 + stiffness, loss=1 + viscosity * LOSS_SPREAD / VISCOSITY_SPREAD)
        return replace(
            nominal,
            shear_modulus_pa=nominal.shear_modulus_pa * (1 + stiffness),
            spring_pot_pa_sn=nominal.spring_pot_pa_sn * (1 + viscosity),
            layered=layered,
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

    @property
    def law(self) -> ViscoelasticLaw:
        """The participant's wave law."""
        return self._law

    def wavenumber(self, freqs: np.ndarray) -> np.ndarray:
        """Physics-convention complex wavenumber ``2 pi f / c(f) + i alpha(f)``, see
        :meth:`ViscoelasticLaw.wavenumber`."""
        return self._law.wavenumber(freqs)

    def phase_speed(self, freqs: np.ndarray) -> np.ndarray:
        """Phase speed ``c(f)``, m/s, for ``freqs`` > 0 Hz (from the wave law)."""
        return self._law.phase_speed(freqs)

    def group_speed(self, freqs: np.ndarray) -> np.ndarray:
        """Group speed, m/s, for ``freqs`` > 0 Hz (from the wave law)."""
        return self._law.group_speed(freqs)

    def attenuation(self, freqs: np.ndarray) -> np.ndarray:
        """Attenuation ``alpha(f)``, Np/m (from the wave law)."""
        return self._law.attenuation(freqs)

    @property
    def c250_m_s(self) -> float:
        """Phase speed at 250 Hz, m/s (derived; for display)."""
        return float(self.phase_speed(np.array([250.0]))[0])

    @property
    def alpha250_np_m(self) -> float:
        """Attenuation at 250 Hz, Np/m (derived; for display)."""
        return float(self.attenuation(np.array([250.0]))[0])

    def to_dict(self) -> dict:
        """JSON-serialisable description (SI units; an infinite modulus is None)."""
        out = {}
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            if isinstance(value, np.ndarray):
                value = value.tolist()
            elif isinstance(value, LayeredLaw):
                value = value.to_dict()
            elif isinstance(value, float) and np.isinf(value):
                value = None
            out[name] = value
        return out
