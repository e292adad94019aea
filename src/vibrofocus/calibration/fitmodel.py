"""Fit the causal skin model to a measured transfer matrix, and predict it anywhere.

A calibration measures ``H`` at a few skin points. :func:`fit_model` fits the
per-participant parameters of the simulated forearm's model (docs/skin-model.md) to
that measurement: the wave law and, per actuator, its amplitude (gain times contact),
contact radius and the resonance frequency and quality factor of the inertial exciter.
Two wave laws (``law=``): ``"layered"`` (default; the law of the ``nominal``, ``low``
and ``high`` skins, :class:`~vibrofocus.skin.LayeredLaw`: the top layer's and the
substrate's shear moduli, the top layer's effective depth and the constant loss
tangent) and ``"homogeneous"`` (the ``voigt-fit`` skin's fractional Kelvin-Voigt law:
static shear modulus ``mu0`` and spring-pot coefficient ``eta``). The
fitted :class:`FittedSkin` then predicts ``H`` at any point of the skin
(:meth:`FittedSkin.transfer`), for a tap where nothing was measured
(``render(..., target_xy=...)``).

The fit is a weighted complex least-squares fit (``scipy.optimize.least_squares``) over
every point, actuator and frequency of the calibrated band at once, in log-parameters
(so every parameter stays positive and its uncertainty is relative). Each bin is
weighted by the inverse of the random error of the H estimate that its coherence
implies (Bendat & Piersol, *Random Data*, 4th ed., 2010, eq. 9.52 for one input and
eq. 9.97 for the partial coherence of several inputs):
``eps = sqrt((1 - g2) / (2 n_d g2))``, ``sigma = sqrt((eps |H|)^2 + (DYNAMIC_RANGE max_p |H|)^2)`` with ``n_d`` the averages
(the repeats, less the number of actuators for the ``mimo`` estimate).
Uncertainties are the usual linearised ones, ``cov = s^2 (J^T J)^-1`` with
``s^2 = sum(r^2) / (m - n)``.

Held fixed (not fitted), each an assumption stated where its value is defined: the
density and Rayleigh factor (only moduli over density matter for the waves), the
homogeneous law's fractional order and the layered law's reference frequency, the
arm's geometry (nominal circumferences and ends, :class:`~vibrofocus.skin.ForearmParameters`),
and the drive sensitivity ``K``.

The layered law's transfer is the causal part of its surface mode (the precursor taken
out, :mod:`vibrofocus.skin.precursor`), which costs a fine time grid per evaluation.
The fit iterates on the mode itself (:meth:`~vibrofocus.skin.SimulatedArm.mode_transfer`,
0.1-0.4 % away) and then once more with the precursor of its first answer held fixed,
so the answer is the causal model's.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._validation import as_array, check_band
from ..errors import ValidationError
from ..layout import ArrayLayout
from .quality import FIT_RESIDUAL_MAX

__all__ = ["FittedSkin", "fit_model", "FIT_LAWS", "FIT_RESIDUAL_MAX", "FIT_LAW_PARAMETERS",
           "FIT_ACTUATOR_PARAMETERS", "parameter_names", "true_parameters"]

#: The wave laws :func:`fit_model` fits; the first is the default.
FIT_LAWS = ("layered", "homogeneous")
#: Wave-law parameters fitted once per participant, per law (SI units; the loss tangent
#: is a ratio).
FIT_LAW_PARAMETERS = {
    "layered": ("top_shear_pa", "substrate_shear_pa", "top_depth_m", "loss_tangent"),
    "homogeneous": ("shear_modulus_pa", "spring_pot_pa_sn"),
}
#: Parameters fitted per actuator: amplitude (gain x contact, 1 = nominal), contact radius
#: (m), exciter resonance (Hz) and quality factor.
FIT_ACTUATOR_PARAMETERS = ("amplitude", "contact_radius_m", "f0_hz", "q")
#: Smallest relative random error given to a bin (an assumption): H is estimated from
#: sampled, windowed recordings whose in-band agreement with the model's spectrum is about
#: 1e-3 at high coherence (the impulse-invariance aliases and the faded responses of the
#: simulator, docs/skin-model.md), so no bin is trusted beyond that.
MIN_RELATIVE_ERROR = 1e-3
#: Absolute error floor of a bin, relative to the largest ``|H|`` over the points at that
#: frequency and actuator (an assumption: the dynamic range of a swept-sine estimate,
#: 100 dB; noise-free simulated calibrations agree with the model's spectrum to about
#: 1e-6 of that peak above 100 Hz). Bins where the wave has died out below it carry no
#: information about the law, whatever their coherence.
DYNAMIC_RANGE = 1e-5
#: Lowest frequency fitted by default, Hz. Noise-free simulated calibrations (window
#: ``n_fft / fs`` = 0.41 s, a few cycles at 10-30 Hz) differ from the model's spectrum by
#: 0.3-1 % of ``|H|`` at 10-30 Hz but about 1e-4 from 30 Hz up (measured with
#: ``calibrate(SimulatedForearm(seed=0, noise_m=0, dropout_rate=0))``); fitting that
#: systematic error biased ``mu0`` and ``eta`` by 10-20 standard errors, so the fit
#: starts at 30 Hz unless told otherwise (an assumption for hardware too).
FIT_LOW_HZ = 30.0
#: Coherence below this counts as this (a bin of pure noise keeps a tiny, finite weight).
_MIN_COHERENCE = 1e-4
#: Relative grid of the starting search over (mu0, eta): the participant draw spans
#: +-23.7 % and +-11.9 % (docs/skin-model.md); the grid reaches a little beyond.
_START_MU0 = np.linspace(-0.35, 0.35, 11)
_START_ETA = np.linspace(-0.2, 0.2, 5)
#: The same for the layered law: both moduli scaled together (the draw spans +-23.7 %)
#: and the loss tangent (the draw spans +-25 %; the presets' loss tangents 0.07-0.42
#: are reached by the least-squares stage).
_START_STIFFNESS = np.linspace(-0.35, 0.35, 11)
_START_LOSS = np.linspace(-0.4, 0.4, 5)
#: Largest loss tangent the layered fit may reach (:class:`~vibrofocus.skin.LayeredLaw` takes < 10).
_MAX_LOSS_TANGENT = 9.0
#: Starting contact of every actuator: the middle of the drawn ranges (an assumption).
_START_CONTACT = 0.85


def _check_law(law: str) -> str:
    from .._validation import check_choice

    return check_choice(law, "law", FIT_LAWS)


def parameter_names(actuator_names, law: str = "layered") -> tuple[str, ...]:
    """Names of the fitted parameters, in the order of :attr:`FittedSkin.values`.

    Parameters
    ----------
    actuator_names : sequence of str
    law : {"layered", "homogeneous"}
        The fitted wave law (:data:`FIT_LAWS`).

    Returns
    -------
    tuple of str
        ``FIT_LAW_PARAMETERS[law]`` then ``"<parameter>[<actuator>]"`` for each actuator
        parameter and actuator.
    """
    return FIT_LAW_PARAMETERS[_check_law(law)] + tuple(
        f"{p}[{a}]" for p in FIT_ACTUATOR_PARAMETERS for a in actuator_names)


@dataclass(frozen=True, eq=False)
class FittedSkin:
    """The skin model fitted to one calibration: predicts H anywhere on the arm.

    Parameters
    ----------
    layout : ArrayLayout
        The calibrated array (its actuators are the sources).
    fs : float
        Sample rate of the calibration, Hz (sets the model's drive sensitivity).
    band : (float, float)
        Calibrated band of the measurement the model was fitted to, Hz (the band fitted,
        which may be narrower, is ``info["fit_band"]``); predictions outside it are
        extrapolations.
    values : ndarray, shape (n_params,)
        Fitted parameters, SI units, in the order of :attr:`names`
        (:func:`parameter_names`).
    log_covariance : ndarray, shape (n_params, n_params)
        Covariance of the natural logarithms of the parameters (so ``sqrt`` of the
        diagonal is each parameter's relative standard error).
    residual : ndarray, shape (n_points,)
        Relative fit residual per calibrated point,
        ``sqrt(sum w |H_fit - H| ^ 2 / sum w |H| ^ 2)`` over actuators and band
        frequencies, with ``w`` the coherence-based weights of the fit (1 = nothing
        explained); NaN at a point whose ``H`` was not measured (NaN in the calibration).
    fixed : dict
        The model's fixed settings: ``law`` (:data:`FIT_LAWS`; ``"homogeneous"`` when
        absent, as in files written before the layered fit), ``skin`` (the preset whose
        drive sensitivity the model uses), ``density_kg_m3``, ``rayleigh_factor``,
        ``fractional_order`` (homogeneous) or ``reference_hz`` (layered),
        ``circumference_wrist_m``, ``circumference_elbow_m``, ``wrist_y_m``,
        ``elbow_y_m``, ``geometry``, ``n_images``.
    info : dict
        Fit diagnostics: ``chi2_per_dof`` (``s^2``), ``n_residuals``, ``nfev``, ``status``,
        ``message``, ``points`` (indices fitted) and ``fit_band`` (Hz).
    """

    layout: ArrayLayout
    fs: float
    band: tuple[float, float]
    values: np.ndarray
    log_covariance: np.ndarray
    residual: np.ndarray
    fixed: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(parameter_names(self.layout.actuator_names, self.law))
        values = as_array(self.values, "values", ndim=1, shape=(n,))
        if np.any(values <= 0):
            raise ValidationError(f"values must be > 0 (every fitted parameter is positive), got {values.tolist()}")
        cov = as_array(self.log_covariance, "log_covariance", ndim=2, shape=(n, n))
        res = as_array(self.residual, "residual", ndim=1, shape=(self.layout.n_points,), finite=False)
        for name, arr in (("values", values), ("log_covariance", cov), ("residual", res)):
            arr = arr.copy()
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "band", tuple(float(b) for b in self.band))
        object.__setattr__(self, "fixed", {**_default_fixed(self.law), **dict(self.fixed)})
        # A model that cannot be built (a stored fit's settings edited) is refused here,
        # not at its first prediction.
        from ..skin import skin_preset

        try:
            skin_preset(self.fixed["skin"])
            _participant(np.log(self.values), self.layout.n_actuators, self.fixed)
        except (TypeError, ValueError, KeyError) as exc:
            raise ValidationError(f"fixed settings {self.fixed} do not make a skin model: {exc}") from None

    # ------------------------------------------------------------------ parameters
    @property
    def law(self) -> str:
        """str: the fitted wave law, ``"layered"`` or ``"homogeneous"`` (:data:`FIT_LAWS`)."""
        return _check_law(dict(self.fixed).get("law", "homogeneous"))

    @property
    def names(self) -> tuple[str, ...]:
        """tuple of str: names of :attr:`values` (:func:`parameter_names`)."""
        return parameter_names(self.layout.actuator_names, self.law)

    @property
    def std(self) -> np.ndarray:
        """ndarray, shape (n_params,): standard errors of :attr:`values`, same units
        (first-order, ``value * sqrt(var(log value))``)."""
        return self.values * np.sqrt(np.clip(np.diag(self.log_covariance), 0, None))

    def parameters(self) -> dict[str, tuple[float, float]]:
        """``{name: (value, standard error)}`` of every fitted parameter, SI units."""
        return {n: (float(v), float(s)) for n, v, s in zip(self.names, self.values, self.std)}

    @property
    def participant(self):
        """The fitted parameters as a :class:`~vibrofocus.skin.ForearmParameters`.

        Contact radius and amplitude map onto the simulator's parameters as
        ``contact = (radius / max radius)^2`` (the largest fitted radius is the full
        contact) and ``gains = amplitude / contact``; the prediction is the same.
        """
        return _participant(np.log(self.values), self.layout.n_actuators, self.fixed)

    def forearm(self):
        """A noise-free :class:`~vibrofocus.rigs.SimulatedForearm` with the fitted
        parameters (to play drives through the fitted model)."""
        return _forearm(self.participant, self.layout, self.fs, self.fixed)

    # ------------------------------------------------------------------ prediction
    def transfer(self, points_xy, freqs) -> np.ndarray:
        """Predicted transfer from every actuator's voltage to displacement at points.

        Parameters
        ----------
        points_xy : ndarray, shape (n_points, 2)
            Skin points in the layout frame, m.
        freqs : ndarray, shape (n_freqs,)
            Frequencies, Hz, >= 0.

        Returns
        -------
        ndarray, complex, shape (n_freqs, n_points, n_actuators)
            m/V, NumPy's FFT sign convention.
        """
        points = as_array(points_xy, "points_xy", ndim=2, shape=(None, 2))
        bad = ~self.on_skin(points)
        if bad.any():
            raise ValidationError(f"points_xy {points[bad][0].tolist()} m lies outside the modelled skin "
                                  f"({self.skin_area_description()})")
        return self.forearm().transfer(points, freqs)

    def transfer_std(self, points_xy, freqs) -> np.ndarray:
        """Standard error of :meth:`transfer` from the fit's parameter uncertainty.

        First order: along each principal direction of :attr:`log_covariance` (eigenvector
        ``v_k``, variance ``l_k``), the change of the prediction over one standard error,
        ``dH_k = H(log values + sqrt(l_k) v_k) - H``; the variance of ``H`` is
        ``sum_k |dH_k|^2``. The changes are those of the surface mode
        (:meth:`~vibrofocus.skin.SimulatedArm.mode_transfer`, some 20 times faster than the
        causal transfer; the precursor, 0.1-0.4 % of ``|H|``, changes by as little again of
        ``dH``): one evaluation per parameter (4 + 4 ``n_actuators`` for the layered law),
        a few seconds at the reference layout's 14 points. The robust minimax design
        bounds its quiet peaks over it when it designs from the fit
        (:meth:`~vibrofocus.rendering.Minimax.h_radius`).

        Parameters
        ----------
        points_xy, freqs
            As :meth:`transfer` (m, Hz).

        Returns
        -------
        ndarray, real, shape (n_freqs, n_points, n_actuators)
            m/V, the rms size of the complex error of :meth:`transfer`.
        """
        points = as_array(points_xy, "points_xy", ndim=2, shape=(None, 2))
        if not self.on_skin(points).all():
            self.transfer(points, freqs[:1])  # the same refusal
        freqs = np.asarray(freqs, float)

        def mode(log_values):
            rig = _forearm(_participant(log_values, self.layout.n_actuators, self.fixed), self.layout, self.fs,
                           self.fixed)
            return rig.mode_transfer(points, freqs)

        lam, vec = np.linalg.eigh(self.log_covariance)
        x0 = np.log(self.values)
        base = mode(x0)
        var = np.zeros(base.shape)
        for k in np.flatnonzero(lam > 0):
            var += np.abs(mode(x0 + np.sqrt(lam[k]) * vec[:, k]) - base) ** 2
        return np.sqrt(var)

    @property
    def verdict(self) -> str | None:
        """None when the model describes every measured point; else one line saying where
        it misses: the largest relative residual (:attr:`residual`) over
        :data:`FIT_RESIDUAL_MAX`. A design from such a model is not to be trusted
        (``render`` warns): the skin is likely outside the model's family (another law)."""
        res = np.where(np.isfinite(self.residual), self.residual, -np.inf)
        worst = int(np.argmax(res))
        if not res[worst] > FIT_RESIDUAL_MAX:
            return None
        bad = int(np.sum(res > FIT_RESIDUAL_MAX))
        return (f"the {self.law} skin model misses the measured H by up to {res[worst]:.1%} (point "
                f"{self.layout.point_labels[worst]}; {bad} point(s) over {FIT_RESIDUAL_MAX:.0%}): the skin is "
                "likely outside the model's family, so its predictions (taps anywhere) are not to be trusted; "
                "fit the other law (law=...) or design from the measured points")

    def on_skin(self, points_xy) -> np.ndarray:
        """Whether points lie on the modelled forearm surface.

        The surface is the tapered cylinder between the elbow-side end and the wrist
        (``elbow_y_m <= y <= wrist_y_m``), ``x`` being arc length from the volar midline
        (``|x| <= C(y) / 2``).

        Parameters
        ----------
        points_xy : ndarray, shape (n_points, 2)
            m.

        Returns
        -------
        ndarray of bool, shape (n_points,)
        """
        p = as_array(points_xy, "points_xy", ndim=2, shape=(None, 2))
        geometry = self.forearm().geometry
        inside_y = (p[:, 1] >= geometry.elbow_y_m) & (p[:, 1] <= geometry.wrist_y_m)
        return inside_y & (np.abs(p[:, 0]) <= geometry.circumference(p[:, 1]) / 2)

    def skin_area_description(self) -> str:
        """One line naming the modelled skin area, for error messages."""
        f = self.fixed
        return (f"y from {f['elbow_y_m'] * 1e3:g} to {f['wrist_y_m'] * 1e3:g} mm, |x| within half the "
                f"circumference, {f['circumference_elbow_m'] * 1e3:g}-{f['circumference_wrist_m'] * 1e3:g} mm")

    def table(self, truth: dict[str, float] | None = None) -> str:
        """Markdown table of the fitted parameters.

        Parameters
        ----------
        truth : dict, optional
            ``{name: true value}`` (e.g. :func:`true_parameters` of a simulated
            participant): adds the truth and ``z = (fitted - truth) / std``.

        Returns
        -------
        str
        """
        head = "| parameter | fitted | std | relative std |" + (" truth | z |" if truth else "")
        rows = [head, "|---" * (6 if truth else 4) + "|"]
        for n, v, s in zip(self.names, self.values, self.std):
            row = f"| {n} | {v:.4g} | {s:.2g} | {s / v:.2%} |"
            if truth:
                row += f" {truth[n]:.4g} | {(v - truth[n]) / s:+.2f} |"
            rows.append(row)
        return "\n".join(rows)

    def to_dict(self) -> dict:
        """JSON-ready description (values, standard errors, residuals, settings)."""
        return {"names": list(self.names), "values": self.values.tolist(), "std": self.std.tolist(),
                "residual": self.residual.tolist(), "band": list(self.band), "fs": self.fs,
                "fixed": dict(self.fixed), "info": dict(self.info)}

    def __repr__(self) -> str:
        short = {"shear_modulus_pa": "mu0", "spring_pot_pa_sn": "eta", "top_shear_pa": "mu_top",
                 "substrate_shear_pa": "mu_sub", "top_depth_m": "h", "loss_tangent": "tan_delta"}
        law = ", ".join(f"{short[n]}={v:.4g} ± {s:.2g}" for n, v, s in
                        zip(FIT_LAW_PARAMETERS[self.law], self.values, self.std))
        return (f"FittedSkin({self.law}: {law} (SI), median residual={np.nanmedian(self.residual):.3g}, "
                f"band={self.band})")


def _default_fixed(law: str = "layered") -> dict:
    from ..skin import ForearmParameters

    law = _check_law(law)
    skin = "nominal" if law == "layered" else "voigt-fit"
    nominal = ForearmParameters.nominal(1, skin=skin)
    out = {name: float(getattr(nominal, name)) for name in (
        "density_kg_m3", "rayleigh_factor", "circumference_wrist_m", "circumference_elbow_m", "wrist_y_m",
        "elbow_y_m")}
    if law == "layered":
        out |= {"density_kg_m3": float(nominal.layered.density_kg_m3),
                "rayleigh_factor": float(nominal.layered.rayleigh_factor),
                "reference_hz": float(nominal.layered.reference_hz)}
    else:
        out["fractional_order"] = float(nominal.fractional_order)
    return {"law": law, "skin": skin, **out, "geometry": "cylinder", "n_images": 2}


def true_parameters(participant, actuator_names) -> dict[str, float]:
    """The fitted parameters' true values for a simulated participant.

    Parameters
    ----------
    participant : ForearmParameters
        A layered participant gives the layered law's parameters, a homogeneous one
        the homogeneous law's.
    actuator_names : sequence of str

    Returns
    -------
    dict
        ``{name: value}`` in the order of :func:`parameter_names`.
    """
    p = participant
    per = {"amplitude": p.gains * p.contact, "contact_radius_m": p.contact_radius_m * np.sqrt(p.contact),
           "f0_hz": p.f0_hz, "q": p.q}
    if p.layered is not None:
        law = "layered"
        values = [getattr(p.layered, name) for name in FIT_LAW_PARAMETERS[law]]
    else:
        law = "homogeneous"
        values = [p.shear_modulus_pa, p.spring_pot_pa_sn]
    values += [v for name in FIT_ACTUATOR_PARAMETERS for v in per[name]]
    return dict(zip(parameter_names(actuator_names, law), map(float, values)))


def _participant(log_values: np.ndarray, n_act: int, fixed: dict):
    from ..skin import ForearmParameters, LayeredLaw

    law = fixed.get("law", "homogeneous")
    n_law = len(FIT_LAW_PARAMETERS[law])
    v = np.exp(log_values)
    amp, radius, f0, q = v[n_law:].reshape(len(FIT_ACTUATOR_PARAMETERS), n_act)
    r_max = float(radius.max())
    contact = (radius / r_max) ** 2
    geo = {k: fixed[k] for k in ("circumference_wrist_m", "circumference_elbow_m", "wrist_y_m", "elbow_y_m")}
    common = dict(contact=contact, gains=amp / contact, f0_hz=f0, q=q, density_kg_m3=fixed["density_kg_m3"],
                  rayleigh_factor=fixed["rayleigh_factor"], contact_radius_m=r_max, **geo)
    if law == "layered":
        top, sub, depth, tan_delta = (float(x) for x in v[:4])
        # The law needs a stiff layer over a soft one: a trial step past that sees the
        # two moduli equal (a flat cost there, which the fit leaves).
        layered = LayeredLaw(top_shear_pa=top, substrate_shear_pa=min(sub, top), top_depth_m=depth,
                             loss_tangent=min(tan_delta, _MAX_LOSS_TANGENT), reference_hz=fixed["reference_hz"],
                             density_kg_m3=fixed["density_kg_m3"], rayleigh_factor=fixed["rayleigh_factor"])
        return ForearmParameters(**common, layered=layered, skin=fixed["skin"])
    return ForearmParameters(**common, shear_modulus_pa=float(v[0]), spring_pot_pa_sn=float(v[1]),
                             fractional_order=fixed["fractional_order"], skin=fixed.get("skin", "voigt-fit"))


def _forearm(participant, layout: ArrayLayout, fs: float, fixed: dict):
    from ..rigs.simulated import SimulatedForearm

    return SimulatedForearm(layout=layout, fs=fs, noise_m=0.0, dropout_rate=0.0, participant=participant,
                            geometry=fixed["geometry"], n_images=int(fixed["n_images"]))


def _bin_errors(cal, coherence: np.ndarray) -> np.ndarray:
    """Relative random error of band bins of ``cal.H`` from their ``coherence``, same shape."""
    g2 = np.asarray(coherence, dtype=float)
    g2 = np.where(np.isfinite(g2), g2, 1.0)  # not assessable (one repeat): trust as measured
    g2 = np.clip(g2, _MIN_COHERENCE, 1.0)
    repeats = int(getattr(cal.sweep, "repeats", 1) or 1)
    n_d = max(repeats - (cal.n_actuators if cal.method == "mimo" else 0), 1)
    eps = np.sqrt((1 - g2) / (2 * n_d * g2))
    return np.maximum(eps, MIN_RELATIVE_ERROR)


def fit_model(cal, *, law: str = "layered", points=None, band=None, max_nfev: int = 200) -> FittedSkin:
    """Fit the skin model's per-participant parameters to a calibration.

    Parameters
    ----------
    cal : Calibration
        A measured transfer matrix with its layout, band and coherence.
    law : {"layered", "homogeneous"}
        Wave law of the model (:data:`FIT_LAWS`): ``"layered"`` (default), a stiff top
        layer over a soft substrate with one constant loss tangent, the law of the
        simulated arm's ``nominal``, ``low`` and ``high`` skins; ``"homogeneous"``, the
        fractional Kelvin-Voigt law of the ``voigt-fit`` skin.
    points : sequence of int, optional
        Indices (into ``cal.layout.points_xy``) of the points to fit; default all.
        Leaving one out is how ``scripts/validate_fit_model.py`` validates the
        prediction at an unmeasured point. The residual of a left-out point is still
        reported.
    band : (float, float), optional
        Band to fit, Hz, inside ``cal.band``; default ``cal.band`` with its low edge
        raised to ``FIT_LOW_HZ`` (30 Hz).
    max_nfev : int
        Most model evaluations of each least-squares stage.

    Returns
    -------
    FittedSkin

    Raises
    ------
    ValidationError
        ``cal`` is not a calibration, holds NaN/Inf at a fitted point, has fewer than
        two points to fit, an unknown ``law``, or no band frequency with a usable weight.

    Notes
    -----
    Steps: (1) a grid over the law's stiffness and loss around its nominal values
    (:data:`~vibrofocus.skin.LAYERED_NOMINAL` or :data:`~vibrofocus.skin.NOMINAL_LAW`),
    each actuator's amplitude solved in closed form (a real factor of its column),
    picks the start; (2) ``least_squares`` (trust-region reflective, ``x_scale="jac"``)
    refines all log-parameters (4 + 4 ``n_actuators`` layered, 2 + 4 ``n_actuators``
    homogeneous) on the complex residuals ``(H_model - H) / sigma`` of every band bin,
    vectorized over frequencies; (3) layered only: the same again from (2)'s answer
    with the precursor of (2)'s model held fixed (see the module docstring).
    """
    from scipy import optimize

    from .result import Calibration

    law = _check_law(law)
    if not isinstance(cal, Calibration):
        raise ValidationError(f"cal must be a Calibration, got {type(cal).__name__}")
    layout = cal.layout
    n_act = layout.n_actuators
    idx = np.arange(layout.n_points) if points is None else np.unique(np.asarray(points, dtype=int))
    if idx.size < 2 or idx.min() < 0 or idx.max() >= layout.n_points:
        raise ValidationError(f"points must name at least two of the {layout.n_points} calibrated points, got "
                              f"{None if points is None else list(points)}")
    H = np.asarray(cal.H)
    finite_rows = np.isfinite(H).all(axis=(0, 2))
    if not finite_rows[idx].all():
        raise ValidationError("cal.H holds NaN/Inf at a fitted point: the fit needs a finite transfer matrix")
    # A row not fitted may hold NaN (not measured); it counts as zero and gets no residual.
    H = np.where(finite_rows[None, :, None], H, 0.0)
    cal_band = check_band(cal.band, cal.fs, name="cal.band")
    if band is None:
        band = (min(max(cal_band[0], FIT_LOW_HZ), cal_band[1] / 2), cal_band[1])
    band = check_band(band, cal.fs)
    if band[0] < cal_band[0] or band[1] > cal_band[1]:
        raise ValidationError(f"band=({band[0]:g}, {band[1]:g}) Hz reaches outside the calibrated band "
                              f"({cal_band[0]:g}, {cal_band[1]:g}) Hz")
    freqs = np.asarray(cal.freqs, float)
    bins = np.flatnonzero((freqs >= band[0]) & (freqs <= band[1]) & (freqs > 0))
    f = freqs[bins]
    Hb = H[bins]
    peak = np.abs(Hb).max(axis=1, keepdims=True)
    sigma = np.hypot(_bin_errors(cal, cal.coherence[bins]) * np.abs(Hb), DYNAMIC_RANGE * peak)
    weight = np.where(sigma > 0, 1.0 / np.where(sigma > 0, sigma, 1.0), 0.0)
    weight[:, np.setdiff1d(np.arange(layout.n_points), idx)] = 0.0
    use = weight > 0
    if not use.any():
        raise ValidationError("no band frequency of cal has a usable weight (|H| is zero everywhere)")
    fixed = _default_fixed(law)
    pts = layout.points_xy
    wH = (weight * Hb)[use]
    precursor = np.zeros_like(Hb)  # the causal correction held fixed in stage (3)

    def model(log_values):
        rig = _forearm(_participant(log_values, n_act, fixed), layout, cal.fs, fixed)
        return rig.mode_transfer(pts, f) + precursor

    def residuals(log_values):
        r = (weight * model(log_values))[use] - wH
        return np.concatenate([r.real, r.imag])

    # (1) the start: a grid over the law, amplitudes in closed form.
    n_law = len(FIT_LAW_PARAMETERS[law])
    base = np.concatenate([
        np.log(_nominal_law_values(law)), np.zeros(n_act),
        np.full(n_act, np.log(3e-3 * np.sqrt(_START_CONTACT))), np.full(n_act, np.log(500.0)), np.zeros(n_act)])
    best = (np.inf, base)
    for steps in _start_grid(law):
        x = base.copy()
        x[:n_law] += np.log1p(steps)
        m = weight * model(x)
        num = np.einsum("fpa,fpa->a", m.conj(), weight * Hb).real
        den = np.einsum("fpa,fpa->a", m.conj(), m).real
        amp = np.clip(num / np.where(den > 0, den, 1.0), 1e-6, None)
        x[n_law:n_law + n_act] = np.log(amp)
        cost = float(np.sum(np.abs((m * amp - weight * Hb)[use]) ** 2))
        if cost < best[0]:
            best = (cost, x)
    # (2) all parameters; (3) layered: again with the precursor of (2)'s answer.
    solve = dict(method="trf", x_scale="jac", max_nfev=max_nfev, xtol=1e-10, ftol=1e-10, gtol=1e-10)
    res = optimize.least_squares(residuals, best[1], **solve)
    nfev = int(res.nfev)
    if law == "layered":
        arm = _forearm(_participant(res.x, n_act, fixed), layout, cal.fs, fixed)
        precursor = arm.transfer(pts, f) - arm.mode_transfer(pts, f)
        res = optimize.least_squares(residuals, res.x, **solve)
        nfev += int(res.nfev)
    m_res = res.fun.size
    dof = max(m_res - res.x.size, 1)
    s2 = 2 * res.cost / dof
    _, sv, vt = np.linalg.svd(res.jac, full_matrices=False)
    keep = sv > sv[0] * 1e-12
    cov = (vt[keep].T / sv[keep] ** 2) @ vt[keep] * s2
    # Residual per point, over every point (left-out ones too, where they were measured).
    w2 = np.where(sigma > 0, 1.0 / np.where(sigma > 0, sigma, 1.0), 0.0) ** 2
    diff = np.abs(model(res.x) - Hb) ** 2
    residual = np.full(layout.n_points, np.nan)
    residual[finite_rows] = np.sqrt(np.sum((w2 * diff)[:, finite_rows], axis=(0, 2)) / np.maximum(
        np.sum((w2 * np.abs(Hb) ** 2)[:, finite_rows], axis=(0, 2)), 1e-300))
    info = {"chi2_per_dof": float(s2), "n_residuals": int(m_res), "nfev": nfev, "status": int(res.status),
            "message": str(res.message), "points": idx.tolist(), "fit_band": list(band)}
    return FittedSkin(layout=layout, fs=float(cal.fs), band=cal_band, values=np.exp(res.x), log_covariance=cov,
                      residual=residual, fixed=fixed, info=info)


def _nominal_law_values(law: str) -> list[float]:
    """The law's fitted parameters at their nominal values (the start's centre), SI units."""
    from ..skin import LAYERED_NOMINAL, NOMINAL_LAW

    if law == "layered":
        return [getattr(LAYERED_NOMINAL, name) for name in FIT_LAW_PARAMETERS[law]]
    return [NOMINAL_LAW.mu0_pa, NOMINAL_LAW.eta_pa_sn]


def _start_grid(law: str):
    """Relative steps of the law's parameters tried for the start, one array per try."""
    if law == "layered":  # both moduli together, and the loss tangent; the depth stays
        return (np.array([ds, ds, 0.0, dl]) for ds in _START_STIFFNESS for dl in _START_LOSS)
    return (np.array([dm, de]) for dm in _START_MU0 for de in _START_ETA)
