"""The simulated participants' perceptual model, version 3 (a MODEL, not data).

A stimulus is felt in two stages: a peripheral one computed once per stimulus
(:func:`felt_energy`, :func:`actuator_energy`) and a central one drawn per trial
(:func:`central_percepts`, :func:`draw_answers`), with the parameters and their sources in
:class:`PerceptualModel` and ``simulation/data/SOURCES.md``. The method, its stages and
what is published, assumed or fitted: docs/simulated-participants.md, "The model". Every
random draw is seeded (:class:`Traits`, :func:`draw_answers`).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from importlib import resources
from typing import Any, Callable

import numpy as np

from ..errors import StudyError, ValidationError

__all__ = [
    "STUDY_SKIN",
    "MODEL_VERSION",
    "MODEL_LABEL",
    "PerceptualModel",
    "Traits",
    "psychophysics_data",
    "threshold_db",
    "threshold_weight",
    "skin_grid",
    "felt_energy",
    "reference_felt_energy",
    "Percepts",
    "TrialPosteriors",
    "trial_posteriors",
    "unfuse",
    "unfused_probability",
    "location_distances",
    "select_locations",
    "posterior_ratio_rule",
    "central_percepts",
    "draw_answers",
    "study2_rt",
    "band_transfer",
    "actuator_energy",
    "own_transfer",
    "PARAMETER_SOURCES",
]

#: Version of the perceptual model; bump it whenever answers for the same seeds change.
MODEL_VERSION = "3.0"
#: Skin preset of the simulated participants' forearms: the nominal layered arm, the one
#: checked against the paper's own vibrometer recordings (docs/simulated-arm-truth.md).
#: The perceptual model and its feature bank are fitted on it (a model, not data; see
#: docs/simulated-participants.md).
STUDY_SKIN = "nominal"
#: The label every report made from simulated data carries.
MODEL_LABEL = f"simulated participants: model v{MODEL_VERSION}, not data"


@lru_cache(maxsize=1)
def psychophysics_data() -> dict[str, Any]:
    """The published points the model uses (``simulation/data/psychophysics.json``)."""
    text = resources.files("vibrofocus.simulation").joinpath("data/psychophysics.json").read_text(encoding="utf-8")
    return json.loads(text)


def threshold_db(freqs_hz: np.ndarray) -> np.ndarray:
    """Vibrotactile (Pacinian) detection threshold relative to 250 Hz, dB (displacement).

    Piecewise linear in log-frequency through the points of ``psychophysics.json``: flat
    below 40 Hz, -12 dB/octave from 40 to 250 Hz (Verrillo 1963 via Gescheider & Verrillo
    1979), +12 dB/octave above 250 Hz (assumption); constant beyond the end points.

    Parameters
    ----------
    freqs_hz : ndarray, shape (n,)
        Frequencies, Hz, > 0.

    Returns
    -------
    ndarray, shape (n,)
        Threshold re its value at 250 Hz, dB (0 at 250 Hz).
    """
    f = np.asarray(freqs_hz, dtype=float)
    if np.any(~np.isfinite(f)) or np.any(f <= 0):
        raise ValidationError("freqs_hz must be finite and > 0 Hz")
    pts = psychophysics_data()["pacinian_threshold_db_re_250hz"]
    return np.interp(np.log2(f), np.log2(pts["freq_hz"]), pts["threshold_db"])


def threshold_weight(freqs_hz: np.ndarray) -> np.ndarray:
    """Power weight ``10^(-threshold_db/10)`` (1 at 250 Hz; 0 at 0 Hz), shape of ``freqs_hz``."""
    f = np.asarray(freqs_hz, dtype=float)
    out = np.zeros_like(f)
    pos = f > 0
    out[pos] = 10.0 ** (-threshold_db(f[pos]) / 10.0)
    return out


@dataclass(frozen=True)
class PerceptualModel:
    """Parameters of the perceptual model v3 (SI units). Each says where it comes from.

    Attributes
    ----------
    grid_half_width_m, grid_step_m : float
        Skin grid of the peripheral stage, m (assumption: covers the array, 5 mm is half the
        location pitch).
    band_hz : (float, float)
        Frequencies counted, Hz (the vibrotactile range; the U-curve weights within it).
    integration_s : float or None
        Temporal integration of the felt intensity, s: a point's felt intensity is the
        largest threshold-weighted displacement energy in any window of this length.
        ``None`` (default) integrates the whole stimulus: the felt *energy* the model was
        fitted with. Short windows (a few ms) make the intensity follow the displacement's
        peak, which favours a focus that is sharp in time. *Assumption*, explored in
        docs/history-simulated-participants.md ("What the model does not reproduce").
    sl_ref_db : float
        Sensation level of the reference tap (2 µm peak Ricker), dB. *Fitted.*
    central_weight : float
        ``beta``: weight of the drive cue (the actuators' delivered energies) against the
        skin cue in the percept's place, 0-1. *Fitted* (the paper's Sec. IV: central coding).
    conflict_gain : float
        Extra localization noise SD per metre of distance between the skin cue and the
        drive cue: two cues that disagree make a less certain percept. *Assumption* of
        the form (cue conflict, as in causal-inference models of cue combination, Körding
        et al. 2007, PLoS ONE 2(9):e943, doi:10.1371/journal.pone.0000943); size *fitted*.
    funneling_exponent : float
        ``gamma`` of the central integration weights ``w_p = (E_p / E_thr - 1)^gamma``:
        1 is the energy law of funneling (Alles 1970; Israr & Poupyrev 2011); smaller
        values compress intensity (the felt area counts more than its peak). *Fitted.*
    threshold_sd_db : float
        SD across participants of the threshold offset, dB. *Assumption.*
    acuity_sd_m : (float, float)
        Range (uniform) of a participant's localization noise SD, m. *Fitted* (order of the
        location pitch: Cholewiak & Collins 2003).
    spread_gain : (float, float)
        Range (uniform) of a participant's ``k_i``: extra noise SD per metre of percept
        spread (how much a diffuse, phantom-like percept degrades that participant's
        localization). *Fitted.*
    prior_sd_m : (float, float)
        Range (uniform) of a participant's central-prior SD, m. *Fitted.*
    bias_mean_m : (float, float)
        Population mean of the participants' constant bias (x, y), m. Direction of y toward
        the elbow (-y) from Cholewiak et al. 2020; sizes *fitted*.
    bias_sd_m : float
        SD of a participant's bias around the mean, per axis, m. *Fitted.*
    select_kappa : (float, float)
        Range (uniform) of a participant's Study 2 criterion (fraction of the largest
        posterior density). *Fitted.*
    select_log_sd : float
        Per-trial log-normal jitter of the criterion. *Fitted.*
    unfused_per_m : float
        Probability per metre of cue conflict that a trial's percept is *unfused*
        (capped at 1): the skin cue and the drive cue are not felt as one tap, and the tap
        is felt at another place. 0 (default): every percept is fused. *Assumption* of the
        form (in causal inference, cues that disagree are attributed to separate causes
        instead of being averaged, Körding et al. 2007); size *fitted*.
    unfused_jump_m : float
        How far from the fused percept an unfused one is felt, m, in a direction the
        participant cannot sense (uniform). *Assumption* of the form; size *fitted*.
    unfused_width : float
        Factor on the posterior SD with which the participant selects points on an unfused
        trial (it felt odd, so the participant is less sure); it widens the selection only
        (the jump, not the width, moves the answer). *Fitted.*
    intensity_half_db : float
        Under the ``intensity`` hypothesis only: the sensation level (dB SL, of the most
        intense felt point) at which the sensed position's noise variance is doubled;
        reliability ``1 / (1 + 10**((intensity_half_db - L) / 10))``. Weaker taps are
        localized less consistently and pulled more to the centre ("Tactile localization depends on
        stimulus intensity", Exp. Brain Res. 232(2):597-607, 2014; Brooks et al., J. Neurophysiol. 2019). *Assumption*
        of the form; size *fitted*. Inert under every other hypothesis.
    conflict_awareness : float
        ``lambda``: how the Study 2 selection reads the trial's own cue discrepancy. 0
        (default, as in v3): the selection's width carries the conflict noise's expected
        variance ``(conflict_gain * c)**2``, the same on every trial of a stimulus. Above
        0: it carries ``lambda**2 * |v|**2 / 2`` per axis, ``v`` this trial's displacement by
        the conflict noise, so a trial on which the two cues happened to disagree more is
        felt less certain and selected wider, while the place (the answer) is read as
        before. *Assumption* of the form (confidence follows the trial's sensed
        uncertainty, read heuristically rather than as the posterior: Adler & Ma 2018,
        PLoS Comput. Biol. 14(11):e1006572, doi:10.1371/journal.pcbi.1006572); size
        *fitted*. Draws one more standard-normal pair per trial (after the unfused ones),
        so answers of a model without it are unchanged.
    rt_median_s, rt_log_sd, rt_per_extra_location_s
        Response times (an assumption).
    version : str
        Version of the model (:data:`MODEL_VERSION`), kept with the parameters in every
        record of simulated data.
    """

    grid_half_width_m: float = 25e-3
    grid_step_m: float = 5e-3
    band_hz: tuple[float, float] = (10.0, 1000.0)
    integration_s: float | None = None
    # Fitted by scripts/fit_participants.py (docs/simulated-participants.md, "The fit"),
    # rounded to 3 digits.
    sl_ref_db: float = 42.5
    central_weight: float = 0.0
    conflict_gain: float = 1.06
    funneling_exponent: float = 0.665
    threshold_sd_db: float = 3.0
    acuity_sd_m: tuple[float, float] = (0.00322, 0.00737)
    spread_gain: tuple[float, float] = (0.0662, 0.0842)
    prior_sd_m: tuple[float, float] = (0.0144, 0.0242)
    bias_mean_m: tuple[float, float] = (-0.00357, -0.00583)
    bias_sd_m: float = 0.0013
    select_kappa: tuple[float, float] = (0.248, 0.922)
    select_log_sd: float = 0.454
    unfused_per_m: float = 0.0
    unfused_jump_m: float = 0.02
    unfused_width: float = 1.0
    conflict_awareness: float = 0.0
    intensity_half_db: float = 10.0
    rt_median_s: tuple[float, float] = (0.9, 1.4)
    rt_log_sd: float = 0.3
    rt_per_extra_location_s: float = 0.35
    version: str = field(default=MODEL_VERSION)

    def to_dict(self) -> dict[str, Any]:
        """Parameters as a JSON-ready dict."""
        return asdict(self)

    def replace(self, **changes: Any) -> "PerceptualModel":
        """A copy with some parameters changed."""
        d = self.to_dict()
        unknown = set(changes) - set(d)
        if unknown:
            raise ValidationError(f"unknown perceptual model parameter(s): {', '.join(sorted(unknown))}")
        d.update(changes)
        return PerceptualModel(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})


#: Where each parameter of :class:`PerceptualModel` comes from: ``(kind, note)`` with kind
#: ``"assumption"``, ``"fitted"`` (by ``scripts/fit_participants.py`` to the paper's
#: statistics) or ``"source + fitted"`` (direction read from a source, size fitted).
#: ``docs/simulated-participants.md`` lists them with their values (generated).
PARAMETER_SOURCES: dict[str, tuple[str, str]] = {
    "grid_half_width_m": ("assumption", "covers the array's area"),
    "grid_step_m": ("assumption", "half the 10 mm location pitch"),
    "band_hz": ("assumption", "the vibrotactile range; the U-curve weights within it"),
    "integration_s": ("assumption", "None: the whole stimulus (felt energy); short windows explored, not adopted"),
    "sl_ref_db": ("fitted", "sensation level of the reference tap; range from published thresholds for brief taps "
                  "and the forearm"),
    "central_weight": ("fitted", "place coded from the actuators' delivered energies (the paper, Sec. IV: central coding)"),
    "conflict_gain": ("fitted", "form an assumption: cues that disagree add uncertainty (Körding et al. 2007)"),
    "funneling_exponent": ("fitted", "0.5 the linear, 1 the energy law (Alles 1970; Israr & Poupyrev 2011)"),
    "threshold_sd_db": ("assumption", "spread of detection thresholds across people"),
    "acuity_sd_m": ("fitted", "poor localization on the mid-forearm (Cholewiak & Collins 2003)"),
    "spread_gain": ("fitted", "diffuse phantoms are localized worse (Park & Choi 2018)"),
    "prior_sd_m": ("fitted", "strength of the pull to the centre"),
    "bias_mean_m": ("source + fitted", "y toward the elbow, at most 3 mm (Cholewiak et al. 2020); x 0 (no source)"),
    "bias_sd_m": ("fitted", "spread of the participants' biases"),
    "select_kappa": ("fitted", "Study 2 criterion"),
    "select_log_sd": ("fitted", "Study 2 per-trial jitter of the criterion"),
    "unfused_per_m": ("assumption", "off (0) under every shipped hypothesis; form: conflicting cues felt apart "
                      "(Körding et al. 2007); explored, not adopted (docs/history-simulated-participants.md)"),
    "unfused_jump_m": ("assumption", "how far away an unfused tap is felt (used only when unfused_per_m > 0)"),
    "unfused_width": ("assumption", "how much wider an unfused trial's selection is (used only when unfused_per_m > 0)"),
    "conflict_awareness": ("assumption", "off (0) under every shipped hypothesis; form: the selection's width reads "
                           "the trial's own cue discrepancy (Adler & Ma 2018); explored, not adopted"),
    "intensity_half_db": ("fitted", "intensity hypothesis only: level at which localization variance doubles "
                          "(weak taps localized less consistently, Exp. Brain Res. 2014; Brooks et al. 2019)"),
    "rt_median_s": ("assumption", "response times (not analysed)"),
    "rt_log_sd": ("assumption", "response times (not analysed)"),
    "rt_per_extra_location_s": ("assumption", "response times (not analysed)"),
}


def _between(rng: np.random.Generator, ends: tuple[float, float]) -> float:
    # A population range is the interval between its two ends, in either order: a fit
    # that frees one end may move it past the fixed other (same draw as uniform(lo, hi)).
    return float(rng.uniform(min(ends), max(ends)))


@dataclass(frozen=True)
class Traits:
    """One simulated participant's traits, drawn once from the participant seed.

    Attributes
    ----------
    threshold_offset_db : float
        Added to the detection threshold, dB.
    acuity_sd_m, prior_sd_m : float
        Localization noise SD and central-prior SD, m.
    bias_m : ndarray, shape (2,)
        Constant bias of the prior's centre, m.
    spread_gain : float
        ``k_i``, extra localization noise SD per metre of percept spread.
    kappa : float
        Study 2 criterion.
    rt_median_s : float
        Median response time, s.
    """

    threshold_offset_db: float
    acuity_sd_m: float
    prior_sd_m: float
    bias_m: np.ndarray
    kappa: float
    rt_median_s: float
    spread_gain: float

    @classmethod
    def draw(cls, model: PerceptualModel, seed: int | np.random.Generator) -> "Traits":
        """Draw traits from ``model``'s population ranges (seeded)."""
        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng([int(seed), 0x7A17])
        return cls(
            threshold_offset_db=float(rng.normal(0.0, model.threshold_sd_db)),
            acuity_sd_m=_between(rng, model.acuity_sd_m),
            prior_sd_m=_between(rng, model.prior_sd_m),
            bias_m=np.asarray(model.bias_mean_m, dtype=float) + rng.normal(0.0, model.bias_sd_m, size=2),
            kappa=_between(rng, model.select_kappa),
            rt_median_s=_between(rng, model.rt_median_s),
            spread_gain=_between(rng, model.spread_gain),
        )

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["bias_m"] = [float(v) for v in self.bias_m]
        return d


def skin_grid(centre_xy: np.ndarray, model: PerceptualModel | None = None) -> np.ndarray:
    """The peripheral stage's skin points, shape (n_points, 2), m, centred on ``centre_xy``."""
    m = model or PerceptualModel()
    half, step = m.grid_half_width_m, m.grid_step_m
    axis = np.arange(-half, half + step / 2, step)
    gx, gy = np.meshgrid(axis + centre_xy[0], axis + centre_xy[1])
    return np.column_stack([gx.ravel(), gy.ravel()])


def _band_bins(n_fft: int, fs: float, band_hz: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    freqs = np.fft.rfftfreq(n_fft, 1.0 / fs)
    bins = np.flatnonzero((freqs >= band_hz[0]) & (freqs <= band_hz[1]) & (freqs > 0))
    return bins, freqs[bins]


def reference_felt_energy(fs: float, n_samples: int, model: PerceptualModel | None = None) -> float:
    """Felt energy of the reference tap (Ricker, 1 ms, 2 µm peak) at one point, m² s."""
    from ..defaults import SIGMA_S, TARGET_PEAK_M
    from ..signals.ricker import ricker

    m = model or PerceptualModel()
    u = ricker(fs, SIGMA_S, duration=n_samples / fs, amplitude=TARGET_PEAK_M)
    bins, f = _band_bins(len(u), fs, m.band_hz)
    return float(_felt(np.fft.rfft(u)[bins], bins, f, len(u), fs, m.integration_s))


def _felt(spec: np.ndarray, bins: np.ndarray, f: np.ndarray, n: int, fs: float, integration_s: float | None) -> np.ndarray:
    """Threshold-weighted energy of band spectra ``spec`` (..., n_bins), m² s.

    Over the whole window (Parseval) when ``integration_s`` is None or spans it; else the
    largest energy in any window of ``integration_s`` (circular, as the spectra are).
    """
    if integration_s is not None and not (np.isfinite(integration_s) and integration_s > 0):
        raise ValidationError(f"integration_s must be None or a time > 0 s, got {integration_s!r}")
    w = threshold_weight(f)
    if integration_s is None or integration_s * fs >= n:
        return 2.0 * np.sum(np.abs(spec) ** 2 * w, axis=-1) / (n * fs)
    full = np.zeros(spec.shape[:-1] + (n // 2 + 1,), dtype=complex)
    full[..., bins] = spec * np.sqrt(w)
    power = np.fft.irfft(full, n=n, axis=-1) ** 2
    k = max(1, int(round(integration_s * fs)))
    # Sliding sums through a cumulative sum over the circularly extended signal.
    c = np.cumsum(np.concatenate([power, power[..., : k - 1]], axis=-1), axis=-1)
    c = np.concatenate([np.zeros(c.shape[:-1] + (1,)), c], axis=-1)
    return (c[..., k:] - c[..., :-k]).max(axis=-1) / fs


def felt_energy(
    H_points: np.ndarray, drives: np.ndarray, fs: float, model: PerceptualModel | None = None
) -> np.ndarray:
    """Threshold-weighted skin energy at points, relative to the reference tap's.

    Parameters
    ----------
    H_points : ndarray, complex, shape (n_bins, n_points, n_actuators)
        True transfer (m/V) on the model's band bins of ``rfftfreq(n_samples, 1/fs)`` (see
        :func:`band_transfer`).
    drives : ndarray, shape (n_stimuli, n_actuators, n_samples) or (n_actuators, n_samples)
        V.
    fs : float
        Hz.

    Returns
    -------
    ndarray, shape (n_stimuli, n_points) (or (n_points,))
        ``E_p / E_ref`` (dimensionless; 1 = as felt as the reference tap). With
        ``model.integration_s`` set, both are the largest energy in any window of that
        length instead of the whole stimulus's.
    """
    m = model or PerceptualModel()
    d = np.asarray(drives, dtype=float)
    single = d.ndim == 2
    if single:
        d = d[None]
    if d.ndim != 3 or d.shape[1] != H_points.shape[2]:
        raise StudyError(f"drives must have shape (n_stimuli, {H_points.shape[2]}, n_samples), got {d.shape}")
    n = d.shape[-1]
    bins, f = _band_bins(n, fs, m.band_hz)
    if len(bins) != H_points.shape[0]:
        raise StudyError("H_points was not computed on this drive length's band bins")
    spec = np.fft.rfft(d, axis=-1)[:, :, bins]  # (s, q, f)
    u = np.einsum("fpq,sqf->spf", H_points, spec)
    out = _felt(u, bins, f, n, fs, m.integration_s) / reference_felt_energy(fs, n, m)
    return out[0] if single else out


def actuator_energy(
    forearm: Any, actuators_xy: np.ndarray, drives: np.ndarray, model: PerceptualModel | None = None
) -> np.ndarray:
    """Felt energy each actuator's own drive makes at its own contact, re the reference tap.

    The central (funneling) stage integrates one input per actuator (the paper's
    explanation, Sec. IV: funneling is coded centrally, Gardner & Spencer 1972; Chen et al.
    2003): the skin under actuator ``q`` moved by actuator ``q`` alone, ``H_qq(f) D_q(f)``,
    weighted as in :func:`felt_energy`. A partly coupled actuator (the wrist-side ones,
    :data:`vibrofocus.skin.parameters.WRIST_CONTACT_RANGE`) delivers less than its drive.

    Parameters
    ----------
    forearm : SimulatedForearm
    actuators_xy : ndarray, shape (n_actuators, 2)
        Actuator centres, m.
    drives : ndarray, shape (n_stimuli, n_actuators, n_samples)
        V.

    Returns
    -------
    ndarray, shape (n_stimuli, n_actuators)
    """
    d = np.asarray(drives, dtype=float)
    return felt_energy(own_transfer(forearm, actuators_xy, d.shape[-1], model), d, forearm.fs, model)


def own_transfer(forearm: Any, actuators_xy: np.ndarray, n_samples: int, model: PerceptualModel | None = None) -> np.ndarray:
    """Transfer from each actuator to its own contact only, on the model's band bins.

    Returns
    -------
    ndarray, complex, shape (n_bins, n_actuators, n_actuators)
        Diagonal in the last two axes (each contact hears its own actuator only), m/V:
        with it :func:`felt_energy` gives :func:`actuator_energy`.
    """
    H = band_transfer(forearm, actuators_xy, n_samples, model)
    return H * np.eye(H.shape[1], H.shape[2])[None]


def band_transfer(forearm: Any, points_xy: np.ndarray, n_samples: int, model: PerceptualModel | None = None) -> np.ndarray:
    """True transfer of ``forearm`` to ``points_xy`` on the model's band bins, (n_bins, n_points, n_act)."""
    m = model or PerceptualModel()
    _, f = _band_bins(int(n_samples), forearm.fs, m.band_hz)
    return forearm.transfer(np.asarray(points_xy, dtype=float), f)


@dataclass(frozen=True)
class Percepts:
    """Noise-free central percepts of stimuli for one participant.

    Attributes
    ----------
    position_m : ndarray, shape (n, 2)
        Energy-law (funneling) position of the felt points, m (NaN where nothing is felt).
    spread_m : ndarray, shape (n,)
        Weighted RMS distance of the felt points from it, m.
    felt : ndarray of bool, shape (n,)
        Whether any point is above threshold.
    conflict_m : ndarray, shape (n,)
        Distance between the skin cue and the drive cue, m (0 without a drive cue).
    reliability : ndarray, shape (n,), optional
        Reliability of the sensed position in (0, 1]: its noise variance is divided by it
        (a hypothesis in which weak taps are localized less reliably,
        :mod:`vibrofocus.simulation.hypotheses`); None: 1.
    drive_position_m : ndarray, shape (n, 2), optional
        The drive cue's place: the energy-law position over the actuators' contacts, m
        (NaN where the actuators deliver nothing felt); None without a drive cue.
    """

    position_m: np.ndarray
    spread_m: np.ndarray
    felt: np.ndarray
    conflict_m: np.ndarray | None = None
    reliability: np.ndarray | None = None
    drive_position_m: np.ndarray | None = None


def felt_threshold(model: PerceptualModel, traits: Traits) -> float:
    """A participant's detection threshold as a felt energy re the reference tap (linear)."""
    return 10.0 ** ((traits.threshold_offset_db - model.sl_ref_db) / 10.0)


def _nan_to(x: np.ndarray, value: float = 0.0) -> np.ndarray:
    """``numpy.nan_to_num(x, nan=value)`` of a float array, the same values at a fraction of its
    overhead (these run once per simulated participant and trial set)."""
    x = np.asarray(x, dtype=float)
    if np.isinf(x).any():
        return np.nan_to_num(x, nan=value)
    return np.where(np.isnan(x), value, x)


def funneling_weights(e: np.ndarray, e_thr: float, exponent: float) -> np.ndarray:
    """Central integration weights ``(E / E_thr - 1)^gamma`` of felt energies, 0 below threshold."""
    w = np.maximum(e / e_thr - 1.0, 0.0)
    return w**exponent if exponent != 1.0 else w


def weighted_centre(w: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted position (n, 2), RMS spread (n,) and total weight (n,) of points ``xy`` (m)."""
    total = w.sum(axis=1)
    safe = np.where(total > 0, total, 1.0)[:, None]
    pos = (w @ xy) / safe
    d2 = (xy[None, :, 0] - pos[:, 0, None]) ** 2 + (xy[None, :, 1] - pos[:, 1, None]) ** 2
    return pos, np.sqrt(np.sum(w * d2, axis=1) / safe[:, 0]), total


def _energy_law(e: np.ndarray, e_thr: float, xy: np.ndarray, exponent: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Energy-law position (n, 2), spread (n,) and total weight (n,) of sources at ``xy``."""
    return weighted_centre(funneling_weights(e, e_thr, exponent), xy)


def central_percepts(
    energy: np.ndarray,
    points_xy: np.ndarray,
    model: PerceptualModel,
    traits: Traits,
    actuator_energy: np.ndarray | None = None,
    actuators_xy: np.ndarray | None = None,
) -> Percepts:
    """Detection and central funneling for stimuli of felt energies ``energy``.

    Parameters
    ----------
    energy : ndarray, shape (n, n_points)
        Felt energy at the skin points (:func:`felt_energy`).
    points_xy : ndarray, shape (n_points, 2)
        m.
    actuator_energy : ndarray, shape (n, n_actuators), optional
        Felt energy each actuator delivers at its own contact (:func:`actuator_energy`);
        without it the place is the skin cue alone (``beta = 0``).
    actuators_xy : ndarray, shape (n_actuators, 2), optional
        m.
    """
    e = np.atleast_2d(np.asarray(energy, dtype=float))
    e_thr = felt_threshold(model, traits)
    pos, spread, total = _energy_law(e, e_thr, points_xy, model.funneling_exponent)
    felt = total > 0
    conflict = np.zeros(len(e))
    drive_place = None
    if actuator_energy is not None:
        a = np.atleast_2d(np.asarray(actuator_energy, dtype=float))
        drive_pos, _, drive_total = _energy_law(a, e_thr, np.asarray(actuators_xy, dtype=float), model.funneling_exponent)
        has = drive_total > 0
        conflict = np.where(has, np.linalg.norm(drive_pos - pos, axis=1), 0.0)
        drive_place = np.where(has[:, None], drive_pos, np.nan)
        beta = np.where(has, model.central_weight, 0.0)[:, None]
        pos = (1.0 - beta) * pos + beta * drive_pos
    pos[~felt] = np.nan
    spread[~felt] = np.nan
    conflict[~felt] = np.nan
    return Percepts(pos, spread, felt, conflict, drive_position_m=drive_place)


@dataclass(frozen=True)
class TrialPosteriors:
    """A participant's belief about where each trial's tap was (central prior applied).

    Attributes
    ----------
    perceived_m : ndarray, shape (n_trials, 2)
        Posterior mean of the tap's place, m.
    sd_m : ndarray, shape (n_trials,)
        Posterior SD per axis, m (the prior's SD where nothing was felt).
    felt : ndarray of bool, shape (n_trials,)
        Whether the tap was felt.
    """

    perceived_m: np.ndarray
    sd_m: np.ndarray
    felt: np.ndarray


def trial_posteriors(
    percepts: Percepts,
    index: np.ndarray,
    centre_xy: np.ndarray,
    model: PerceptualModel,
    traits: Traits,
    noise: np.ndarray,
    conflict_noise: np.ndarray | None = None,
) -> TrialPosteriors:
    """Posteriors of trials from their noise-free percepts and standard-normal noise.

    Parameters
    ----------
    percepts : Percepts
        Of the distinct stimuli.
    index : ndarray of int, shape (n_trials,)
        Which stimulus each trial presents.
    centre_xy : ndarray, shape (2,)
        Array centre, m (the prior's centre before the participant's bias).
    traits : Traits
        One participant's; or, to take many participants' trials in one call, one value
        per trial: ``acuity_sd_m``, ``prior_sd_m`` and ``spread_gain`` of shape
        (n_trials,), ``bias_m`` (n_trials, 2) (the likelihood's batches of population
        draws, :mod:`vibrofocus.simulation.fitting.likelihood_fit`).
    noise : ndarray, shape (n_trials, 2)
        Standard-normal draws of the sensed position's noise (without ``conflict_noise``:
        all of it; with it: the part not due to the cue conflict).
    conflict_noise : ndarray, shape (n_trials, 2), optional
        Standard-normal draws of the part due to the cue conflict, given only where the
        model's ``conflict_awareness`` is on: the place's noise is then the same in law,
        and the posterior SD (the selection's width) carries this trial's conflict
        displacement ``v`` as ``conflict_awareness**2 * |v|**2 / 2`` per axis instead of its
        expected variance; the shrinkage toward the prior, and so the place, is unchanged.
    """
    idx = np.asarray(index, dtype=int)
    n = idx.size
    c = np.asarray(centre_xy, dtype=float) + traits.bias_m
    pos = percepts.position_m[idx]
    spread = percepts.spread_m[idx]
    felt = percepts.felt[idx]
    conflict = percepts.conflict_m[idx] if percepts.conflict_m is not None else np.zeros(n)
    other2 = traits.acuity_sd_m**2 + (traits.spread_gain * _nan_to(spread)) ** 2
    conflict2 = (model.conflict_gain * _nan_to(conflict)) ** 2
    reliability = 1.0
    if percepts.reliability is not None:
        reliability = np.clip(_nan_to(percepts.reliability[idx], 1.0), 1e-6, 1.0)
    sig_s2 = (other2 + conflict2) / reliability
    sp2 = traits.prior_sd_m**2
    g = np.where(felt, sp2 / (sp2 + sig_s2), 0.0)
    if conflict_noise is None:
        displacement = noise * np.sqrt(sig_s2)[:, None]
        width2, g_width = sig_s2, g
    else:
        # The same noise in law, drawn in two parts, so that the selection can read this
        # trial's own cue discrepancy (PerceptualModel.conflict_awareness).
        by_conflict = conflict_noise * np.sqrt(conflict2 / reliability)[:, None]
        displacement = noise * np.sqrt(other2 / reliability)[:, None] + by_conflict
        width2 = other2 / reliability + model.conflict_awareness**2 * np.sum(by_conflict**2, axis=1) / 2.0
        g_width = np.where(felt, sp2 / (sp2 + width2), 0.0)
    sensed = np.where(felt[:, None], _nan_to(pos) + displacement, c)
    perceived = c + g[:, None] * (sensed - c)
    post_sd = np.where(felt, np.sqrt(g_width * width2), traits.prior_sd_m)
    perceived = np.where(felt[:, None], perceived, c + noise * np.reshape(traits.prior_sd_m, (-1, 1)))
    return TrialPosteriors(perceived, post_sd, felt)


def unfused_probability(conflict_m: np.ndarray, model: PerceptualModel) -> np.ndarray:
    """Probability that a felt trial's percept is unfused, shape of ``conflict_m``.

    ``unfused_per_m`` times the cue conflict, capped at 1 (0 where there is no conflict).
    :func:`unfuse` draws with it, :mod:`vibrofocus.simulation.likelihood` integrates it.

    Parameters
    ----------
    conflict_m : ndarray
        Distance between the skin cue and the drive cue, m (NaN or 0: no conflict).
    model : PerceptualModel
    """
    return np.clip(model.unfused_per_m * np.nan_to_num(np.asarray(conflict_m, dtype=float)), 0.0, 1.0)


def unfuse(
    posteriors: TrialPosteriors,
    conflict_m: np.ndarray,
    model: PerceptualModel,
    uniform: np.ndarray,
    angle: np.ndarray,
) -> tuple[TrialPosteriors, np.ndarray]:
    """Move the unfused trials' percepts and widen their selection (``model.unfused_*``).

    Parameters
    ----------
    posteriors : TrialPosteriors
        Of the trials, fused.
    conflict_m : ndarray, shape (n_trials,)
        Distance between the skin cue and the drive cue, m (NaN or 0: no conflict).
    uniform, angle : ndarray, shape (n_trials,)
        Uniform draws in [0, 1) (a trial is unfused where ``uniform`` is below its
        probability) and directions of the jump, rad.

    Returns
    -------
    posteriors : TrialPosteriors
        With the unfused trials' means moved by ``unfused_jump_m`` and their SD multiplied
        by ``unfused_width``.
    unfused : ndarray of bool, shape (n_trials,)
    """
    unfused = (np.asarray(uniform) < unfused_probability(conflict_m, model)) & posteriors.felt
    jump = model.unfused_jump_m * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    perceived = posteriors.perceived_m + np.where(unfused[:, None], jump, 0.0)
    sd = np.where(unfused, posteriors.sd_m * model.unfused_width, posteriors.sd_m)
    return TrialPosteriors(perceived, sd, posteriors.felt), unfused


def location_distances(perceived_m: np.ndarray, locations_xy: np.ndarray,
                       allowed: np.ndarray | None = None) -> np.ndarray:
    """Squared distances of perceived places to the locations, m^2, shape (n_trials, n_locations).

    Locations outside ``allowed`` (0-based indices) are infinitely far: never answered,
    never selected.
    """
    locs = np.asarray(locations_xy, dtype=float)
    d2 = np.sum((locs[None, :, :] - np.asarray(perceived_m, dtype=float)[:, None, :]) ** 2, axis=2)
    if allowed is not None:
        mask = np.zeros(locs.shape[0], dtype=bool)
        mask[np.asarray(allowed, dtype=int)] = True
        d2 = np.where(mask[None, :], d2, np.inf)
    return d2


def select_locations(d2: np.ndarray, sd_m: np.ndarray, criterion: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Study 1 answer and Study 2 selection from a posterior over the locations.

    The answer is the location nearest the posterior mean; the selection holds every
    location whose posterior density is at least ``criterion`` times the answer's.

    Parameters
    ----------
    d2 : ndarray, shape (n_trials, n_locations)
        Squared distances of the posterior means to the locations, m^2
        (:func:`location_distances`).
    sd_m : ndarray, shape (n_trials,)
        Posterior SD, m.
    criterion : ndarray, shape (n_trials,)
        Fraction of the answer's density, 0-1 (the participant's ``kappa`` times the
        trial's jitter).

    Returns
    -------
    answer : ndarray of int, shape (n_trials,)
    selected : ndarray of bool, shape (n_trials, n_locations)
        Always contains ``answer``.
    """
    n = d2.shape[0]
    answer = np.argmin(d2, axis=1)
    # Posterior density ratio to the best location: exp(-(d2 - d2_min) / (2 sd^2)).
    ratio = np.exp(-(d2 - d2[np.arange(n), answer][:, None]) / (2.0 * np.asarray(sd_m)[:, None] ** 2))
    selected = ratio >= np.clip(criterion, 0.0, 1.0)[:, None]
    selected[np.arange(n), answer] = True
    return answer, selected


def posterior_ratio_rule(
    posteriors: TrialPosteriors,
    criterion: np.ndarray,
    locations_xy: np.ndarray,
    allowed: np.ndarray | None,
    percepts: Percepts,
    index: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The model's answer rule: the nearest location, and the locations within the posterior's criterion.

    Every answer rule takes these arguments (``percepts`` and ``index``, the noise-free
    percepts and which one each trial presents, serve rules that read more than the
    posterior) and returns ``(answer, selected)`` as :func:`select_locations` does.
    ``scripts/selection_rules.py`` compares other rules with this one.
    """
    return select_locations(location_distances(posteriors.perceived_m, locations_xy, allowed), posteriors.sd_m,
                            criterion)


def draw_answers(
    percepts: Percepts,
    index: np.ndarray,
    locations_xy: np.ndarray,
    centre_xy: np.ndarray,
    model: PerceptualModel,
    traits: Traits,
    rng: np.random.Generator,
    *,
    allowed: np.ndarray | None = None,
    rule: Callable[..., tuple[np.ndarray, np.ndarray]] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Answers to trials (vectorized): Study 1 location and Study 2 selection.

    Parameters
    ----------
    percepts : Percepts
        Of the distinct stimuli.
    index : ndarray of int, shape (n_trials,)
        Which stimulus each trial presents.
    locations_xy : ndarray, shape (n_locations, 2)
        m.
    centre_xy : ndarray, shape (2,)
        Array centre, m.
    rng : numpy.random.Generator
        Source of all per-trial noise (drawn in a fixed order: position noise (n, 2),
        criterion jitter (n,), response time (n,); then, only where the model has
        unfused percepts (``unfused_per_m > 0``), whether each trial is unfused (n,) and
        the direction of its jump (n,); then, only where it has ``conflict_awareness > 0``,
        the conflict's part of the position noise (n, 2)).
    allowed : ndarray of int, optional
        0-based indices of the locations that may be answered (default all).
    rule : callable, optional
        How the answer and the selection follow from the posterior (default
        :func:`posterior_ratio_rule`, the model's own).

    Returns
    -------
    answer : ndarray of int, shape (n_trials,)
        0-based index of the Study 1 answer.
    selected : ndarray of bool, shape (n_trials, n_locations)
        Study 2 selection (contains ``answer``).
    rt_s : ndarray, shape (n_trials,)
        Response time for Study 1, s (Study 2 adds the per-location cost, see
        :func:`study2_rt`).
    """
    idx = np.asarray(index, dtype=int)
    n = idx.size
    noise = rng.standard_normal((n, 2))
    jitter = rng.lognormal(0.0, model.select_log_sd, size=n)
    rt = traits.rt_median_s * rng.lognormal(0.0, model.rt_log_sd, size=n)
    unfusing = model.unfused_per_m > 0 and percepts.conflict_m is not None
    if unfusing:
        uniform, angle = rng.random(n), rng.uniform(0.0, 2.0 * np.pi, n)
    conflict_noise = rng.standard_normal((n, 2)) if model.conflict_awareness > 0 else None
    post = trial_posteriors(percepts, idx, centre_xy, model, traits, noise, conflict_noise)
    if unfusing:
        post, _ = unfuse(post, percepts.conflict_m[idx], model, uniform, angle)
    answer, selected = (rule or posterior_ratio_rule)(post, traits.kappa * jitter, locations_xy, allowed, percepts,
                                                      idx)
    return answer, selected, rt


def study2_rt(rt_s: np.ndarray, selected: np.ndarray, model: PerceptualModel) -> np.ndarray:
    """Study 2 response times: Study 1's plus a cost per extra selected location, s."""
    return rt_s + model.rt_per_extra_location_s * (selected.sum(axis=1) - 1)
