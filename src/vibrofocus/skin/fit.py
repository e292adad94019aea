"""Fit the skin's wave law to published forearm measurements.

The published points live in ``vibrofocus/skin/data/forearm_waves.csv`` (one row per
number, with its source and where in the paper it stands) and the sources in
``vibrofocus/skin/data/SOURCES.md``. :func:`fit_wave_law` fits a fractional
Kelvin-Voigt law (:class:`~vibrofocus.skin.viscoelastic.ViscoelasticLaw`) to them by
weighted least squares on log-ratios, so a point's residual is its relative misfit;
``scripts/fit_skin_model.py`` prints the points, the fitted curves and the residuals.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from typing import TYPE_CHECKING

import numpy as np

from ..errors import ValidationError
from .viscoelastic import RAYLEIGH_FACTOR_INCOMPRESSIBLE, ViscoelasticLaw

if TYPE_CHECKING:  # pandas and scipy.optimize load with a fit, not with the arm (a second of start-up)
    import pandas as pd

__all__ = ["load_forearm_data", "points_from_published_fits", "fit_wave_law", "WaveLawFit", "FITTED_QUANTITIES"]

#: Quantities of the data file the fit uses, and how the law predicts each (per Hz).
FITTED_QUANTITIES = {
    "phase_speed_m_s": lambda law, f: law.phase_speed(f),
    "attenuation_np_m": lambda law, f: law.attenuation(f),
    "shear_storage_pa": lambda law, f: law.modulus(f).real,
    "shear_loss_pa": lambda law, f: law.modulus(f).imag,
}
# A published Voigt fit (shear elasticity mu1, viscosity mu2) stands for the speed
# dispersion it was fitted to: frequencies of that band, and the density and
# Rayleigh factor the conversion assumes. Zhang et al. 2011 fitted 100-400 Hz; their
# density is not in the abstract: 1000 kg/m^3 is an assumption, supported by the one
# measured point (3.25 m/s at 200 Hz), which these values reproduce within 1 %.
_VOIGT_BANDS_HZ = {"zhang2011": np.arange(100.0, 401.0, 50.0)}
_VOIGT_DENSITY_KG_M3 = 1000.0
# Relative uncertainty given to a point that reports none (an assumption: the typical
# between-subject spread of skin wave speeds is 10-30 %).
_DEFAULT_RELATIVE_SPREAD = 0.2


def points_from_published_fits(data: pd.DataFrame) -> pd.DataFrame:
    """Speed and attenuation points implied by published Voigt fits.

    Where a source reports only a Voigt shear elasticity and viscosity fitted to its
    dispersion data (Zhang et al. 2011), the fit's speed and attenuation at the
    frequencies of the fitted band stand in for the data, labelled
    ``how_read = "derived from the published Voigt fit"``. Their spreads propagate the
    published spreads of both parameters (one-sided differences, added in quadrature).

    Parameters
    ----------
    data : pandas.DataFrame
        As returned by :func:`load_forearm_data`.

    Returns
    -------
    pandas.DataFrame
        Rows in the same columns, ``use`` true.
    """
    import pandas as pd

    rows = []
    for key, freqs in _VOIGT_BANDS_HZ.items():
        src = data[data["source_key"] == key].set_index("quantity")
        if not {"voigt_shear_elasticity_pa", "voigt_shear_viscosity_pa_s"} <= set(src.index):
            continue
        mu, dmu = src.loc["voigt_shear_elasticity_pa", ["value", "spread"]].astype(float)
        eta, deta = src.loc["voigt_shear_viscosity_pa_s", ["value", "spread"]].astype(float)

        def voigt(m: float, e: float) -> ViscoelasticLaw:
            return ViscoelasticLaw(mu0_pa=m, eta_pa_sn=e, order=1.0, density_kg_m3=_VOIGT_DENSITY_KG_M3)

        base = voigt(mu, eta)
        for quantity, of in (("phase_speed_m_s", ViscoelasticLaw.phase_speed),
                             ("attenuation_np_m", ViscoelasticLaw.attenuation)):
            value = of(base, freqs)
            spread = np.hypot(of(voigt(mu + dmu, eta), freqs) - value, of(voigt(mu, eta + deta), freqs) - value)
            for f, v, sp in zip(freqs, value, spread):
                rows.append({
                    "quantity": quantity, "frequency_hz": f, "value": v, "spread": sp, "distance_m": np.nan,
                    "body_site": src["body_site"].iloc[0], "source_key": key,
                    "where": f"Voigt fit of the abstract (mu1 = {mu:g} Pa, mu2 = {eta:g} Pa s), "
                             f"rho = {_VOIGT_DENSITY_KG_M3:g} kg/m^3 and xi = {base.rayleigh_factor} assumed",
                    "how_read": "derived from the published Voigt fit", "use": True,
                })
    return pd.DataFrame(rows, columns=list(data.columns))


def load_forearm_data() -> pd.DataFrame:
    """The published points the wave law is fitted to.

    Returns
    -------
    pandas.DataFrame
        One row per published number: ``quantity``, ``frequency_hz``, ``value``,
        ``spread`` (SD or half-range, NaN if none was given), ``distance_m``,
        ``body_site``, ``source_key``, ``where``, ``how_read`` and ``use``.
    """
    import pandas as pd

    path = resources.files("vibrofocus.skin") / "data" / "forearm_waves.csv"
    with resources.as_file(path) as p:
        return pd.read_csv(p, comment="#")


@dataclass(frozen=True)
class WaveLawFit:
    """Result of :func:`fit_wave_law`.

    Attributes
    ----------
    law : ViscoelasticLaw
        The fitted law.
    relative_std : dict
        Standard error of each fitted parameter relative to its value (``mu0_pa``,
        ``eta_pa_sn``) or absolute (``order``), from the Jacobian at the optimum
        scaled by the residual variance.
    points : pandas.DataFrame
        The fitted points with ``model`` (the law's value) and ``residual_pct``
        (``100 (model / value - 1)``).
    rms_log_residual : float
        Root mean square of ``log(model / value)`` over the points (unweighted).
    """

    law: ViscoelasticLaw
    relative_std: dict
    points: pd.DataFrame
    rms_log_residual: float

    @property
    def max_abs_residual_pct(self) -> float:
        """Largest misfit of a point, percent."""
        return float(np.abs(self.points["residual_pct"]).max())


def _predict(law: ViscoelasticLaw, data: pd.DataFrame) -> np.ndarray:
    out = np.empty(len(data))
    for quantity, rows in data.groupby("quantity").indices.items():
        f = data["frequency_hz"].to_numpy(float)[rows]
        out[rows] = FITTED_QUANTITIES[quantity](law, f)
    return out


def fit_wave_law(
    data: pd.DataFrame | None = None,
    *,
    density_kg_m3: float = 1100.0,
    rayleigh_factor: float = RAYLEIGH_FACTOR_INCOMPRESSIBLE,
    initial: ViscoelasticLaw | None = None,
    order_bounds: tuple[float, float] = (0.05, 1.0),
) -> WaveLawFit:
    """Fit a fractional Kelvin-Voigt law to published wave measurements.

    Minimises ``sum_i (log(model_i / value_i) / s_i)^2`` with ``s_i`` the point's
    relative spread (``spread / value``, or 20 % where the source gives none) over
    ``log mu0``, ``log eta`` and the order ``n``.

    Parameters
    ----------
    data : pandas.DataFrame, optional
        Points in the columns of :func:`load_forearm_data`; default the published
        points and :func:`points_from_published_fits`. Only rows whose ``use`` is true
        and whose ``quantity`` is in :data:`FITTED_QUANTITIES` are fitted.
    density_kg_m3, rayleigh_factor : float
        Held fixed: only ``mu0 / rho`` and ``eta / rho`` are identifiable from speeds.
    initial : ViscoelasticLaw, optional
        Start of the search.
    order_bounds : (float, float)
        Bounds of the fractional order.

    Returns
    -------
    WaveLawFit
    """
    import pandas as pd
    from scipy import optimize

    if data is None:
        published = load_forearm_data()
        data = pd.concat([published, points_from_published_fits(published)], ignore_index=True)
    rows = data[data["quantity"].isin(FITTED_QUANTITIES)]
    if "use" in rows:
        rows = rows[rows["use"].astype(bool)]
    rows = rows.reset_index(drop=True)
    if len(rows) < 3:
        raise ValidationError(f"fit_wave_law needs at least 3 usable points, got {len(rows)}")
    values = rows["value"].to_numpy(float)
    spread = rows["spread"].to_numpy(float) if "spread" in rows else np.full(len(rows), np.nan)
    rel = np.where(np.isfinite(spread) & (spread > 0), spread / values, _DEFAULT_RELATIVE_SPREAD)
    start = initial or ViscoelasticLaw(mu0_pa=5e3, eta_pa_sn=100.0, order=0.6)

    def law_of(x: np.ndarray) -> ViscoelasticLaw:
        return ViscoelasticLaw(mu0_pa=float(np.exp(x[0])), eta_pa_sn=float(np.exp(x[1])), order=float(x[2]),
                               density_kg_m3=density_kg_m3, rayleigh_factor=rayleigh_factor)

    def residuals(x: np.ndarray) -> np.ndarray:
        return np.log(_predict(law_of(x), rows) / values) / rel

    x0 = np.array([np.log(start.mu0_pa), np.log(start.eta_pa_sn), np.clip(start.order, *order_bounds)])
    lower = [np.log(1.0), np.log(1e-6), order_bounds[0]]
    upper = [np.log(1e7), np.log(1e7), order_bounds[1]]
    result = optimize.least_squares(residuals, x0, bounds=(lower, upper), x_scale="jac")
    law = law_of(result.x)
    dof = max(len(rows) - 3, 1)
    variance = float(np.sum(result.fun**2) / dof)
    try:
        cov = np.linalg.inv(result.jac.T @ result.jac) * variance
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        std = np.full(3, np.inf)
    model = _predict(law, rows)
    points = rows.assign(model=model, residual_pct=100 * (model / values - 1))
    rms = float(np.sqrt(np.mean(np.log(model / values) ** 2)))
    return WaveLawFit(
        law=law,
        relative_std={"mu0_pa": float(std[0]), "eta_pa_sn": float(std[1]), "order": float(std[2])},
        points=points,
        rms_log_residual=rms,
    )
