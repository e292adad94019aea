"""A causal viscoelastic law for skin: speed and attenuation from one shear modulus.

The skin's surface wave is modelled as a shear (Rayleigh-type) wave in a viscoelastic
medium whose complex shear modulus is a *fractional Zener* law (a spring in parallel
with a spring-pot, in series with an unrelaxed limit):

``G(s) = (mu0 + eta s^n) / (1 + (eta / mu_inf) s^n)``

with ``s = i omega`` in NumPy's convention (``exp(+i omega t)``). ``mu_inf = inf`` gives
the fractional Kelvin-Voigt law ``G = mu0 + eta (i omega)^n`` (the "fractional Voigt"
model that Kearney et al. 2015 fitted to human skin); ``n = 1`` gives the classical
Voigt and standard linear solid laws.

Why this is causal. ``G`` is the Laplace transform of a causal relaxation function:
as a function of ``s`` it is analytic with a positive real part for ``Re s > 0``
(``s^n`` maps the right half plane into the sector ``|arg| < n pi / 2``). So the
wavenumber ``k = omega sqrt(rho / G) / xi`` is analytic in the same half plane and
grows at most like ``|omega|^(1 - n/2)``; a wave ``exp(-i k r)`` then vanishes before
``t = 0`` at every distance (Paley-Wiener). Speed and attenuation are a Kramers-Kronig
pair by construction: neither can be chosen without the other.

All functions take frequencies in Hz and return NumPy-convention quantities unless
said otherwise; :meth:`ViscoelasticLaw.wavenumber` returns the *physics-convention*
wavenumber (``Re k > 0``, ``Im k = alpha > 0``) that :mod:`.propagation` expects.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validation import check_in_range, check_positive
from ..errors import ValidationError
from .wavelaw import WaveNumberMixin

__all__ = ["ViscoelasticLaw", "RAYLEIGH_FACTOR_INCOMPRESSIBLE"]

#: Rayleigh wave speed over shear wave speed for an incompressible solid (Poisson's ratio
#: 0.5): the root of the Rayleigh equation, 0.9553 (a textbook result; e.g. Graff, *Wave
#: Motion in Elastic Solids*, 1975, sec. 6.3). Soft tissue is nearly incompressible.
RAYLEIGH_FACTOR_INCOMPRESSIBLE = 0.9553


@dataclass(frozen=True)
class ViscoelasticLaw(WaveNumberMixin):
    """A fractional Zener shear modulus and the surface wave it carries.

    Parameters
    ----------
    mu0_pa : float
        Relaxed (static) shear modulus, Pa.
    eta_pa_sn : float
        Spring-pot coefficient, Pa s^n (for ``n = 1`` a viscosity in Pa s).
    order : float
        Fractional order ``n`` of the spring-pot, 0 < n <= 1.
    mu_inf_pa : float
        Unrelaxed (high-frequency) shear modulus, Pa; ``inf`` for no limit (fractional
        Kelvin-Voigt).
    density_kg_m3 : float
        Mass density, kg/m^3.
    rayleigh_factor : float
        Surface wave speed over shear wave speed (0 < xi <= 1).
    """

    mu0_pa: float
    eta_pa_sn: float
    order: float
    mu_inf_pa: float = float("inf")
    density_kg_m3: float = 1100.0
    rayleigh_factor: float = RAYLEIGH_FACTOR_INCOMPRESSIBLE

    def __post_init__(self) -> None:
        for name in ("mu0_pa", "eta_pa_sn", "density_kg_m3"):
            object.__setattr__(self, name, check_positive(getattr(self, name), name))
        object.__setattr__(self, "order", check_in_range(self.order, "order", 0.0, 1.0))
        if self.order == 0.0:
            raise ValidationError("order must be > 0 (order 0 is a second spring, not a loss)")
        object.__setattr__(self, "rayleigh_factor", check_in_range(self.rayleigh_factor, "rayleigh_factor", 0.0, 1.0))
        mu_inf = float(self.mu_inf_pa)
        if not mu_inf > self.mu0_pa:
            raise ValidationError(f"mu_inf_pa must be larger than mu0_pa ({self.mu0_pa:g} Pa), got {mu_inf:g}")
        object.__setattr__(self, "mu_inf_pa", mu_inf)

    # ------------------------------------------------------------------ the modulus
    def _modulus_of_s(self, s: np.ndarray) -> np.ndarray:
        x = s**self.order
        num = self.mu0_pa + self.eta_pa_sn * x
        if np.isinf(self.mu_inf_pa):
            return num
        return num / (1 + (self.eta_pa_sn / self.mu_inf_pa) * x)

    def modulus(self, freqs: np.ndarray) -> np.ndarray:
        """Complex shear modulus ``G(f) = G' + i G''`` in NumPy's convention, Pa.

        Parameters
        ----------
        freqs : ndarray
            Frequencies, Hz, >= 0.

        Returns
        -------
        ndarray, complex, same shape as ``freqs``
            Storage modulus (real part) and loss modulus (imaginary part, >= 0), Pa.
        """
        f = np.asarray(freqs, dtype=float)
        return self._modulus_of_s(2j * np.pi * f + 0.0j)

    def _wavenumber(self, f: np.ndarray) -> np.ndarray:
        """Physics-convention wavenumber at ``f`` (float array, Hz); see :meth:`wavenumber`."""
        omega = 2 * np.pi * f
        # Physics convention exp(-i omega t) is the complex conjugate of NumPy's.
        g_phys = np.conj(self.modulus(f))
        return omega * np.sqrt(self.density_kg_m3 / g_phys) / self.rayleigh_factor

    def group_speed(self, freqs: np.ndarray) -> np.ndarray:
        """Group speed ``d omega / d Re k``, m/s, from the analytic derivative of ``k``.

        ``k = (omega / xi) sqrt(rho) G^(-1/2)``, so
        ``dk/d omega = k / omega - (k / 2) (dG/d omega) / G``.
        """
        f = np.asarray(freqs, dtype=float)
        omega = 2 * np.pi * f
        s = -1j * omega + 0.0j  # physics convention: s = -i omega
        n = self.order
        x = s**n
        b = 0.0 if np.isinf(self.mu_inf_pa) else self.eta_pa_sn / self.mu_inf_pa
        g = (self.mu0_pa + self.eta_pa_sn * x) / (1 + b * x)
        dg_dx = (self.eta_pa_sn - b * self.mu0_pa) / (1 + b * x) ** 2
        dg_domega = dg_dx * n * s ** (n - 1) * (-1j)
        k = omega * np.sqrt(self.density_kg_m3 / g) / self.rayleigh_factor
        dk = k / omega - 0.5 * k * dg_domega / g
        return 1.0 / dk.real

    def plateau_speed(self) -> float:
        """High-frequency limit of the phase speed, m/s (``inf`` without ``mu_inf``)."""
        if np.isinf(self.mu_inf_pa):
            return float("inf")
        return float(self.rayleigh_factor * np.sqrt(self.mu_inf_pa / self.density_kg_m3))

    def to_dict(self) -> dict:
        """JSON-ready parameters (SI units; ``mu_inf_pa`` None when infinite)."""
        return {
            "mu0_pa": self.mu0_pa,
            "eta_pa_sn": self.eta_pa_sn,
            "order": self.order,
            "mu_inf_pa": None if np.isinf(self.mu_inf_pa) else self.mu_inf_pa,
            "density_kg_m3": self.density_kg_m3,
            "rayleigh_factor": self.rayleigh_factor,
        }
