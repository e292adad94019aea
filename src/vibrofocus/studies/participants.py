"""Simulated participants: a perceptual model that answers from the simulated skin field.

This is a **model, not data**. It lets a whole study run end to end without people and
gives answers with the spread human forearm localization shows, but nothing it produces
is evidence about how people perceive the stimuli.

The model, per stimulus (drive signals ``s_q(t)`` on the participant's simulated forearm):

1. **Skin field energy.** ``E(x) = ∫ u(x, t)² dt`` over a square grid around the array
   (default ±32 mm, 4 mm pitch) plus the nine locations, where ``u`` is the noise-free
   displacement of :meth:`SimulatedForearm.field`. It is computed by Parseval's theorem
   from the forearm's transfer on the grid, restricted to the band the skin's
   vibrotactile channels respond to (default 10-1000 Hz); the grid's transfer is
   computed once per participant, so a stimulus costs one matrix product.
2. **Perceived position (Study 1).** The energy-weighted centroid ``c = Σ E(x) x / Σ E``,
   pulled toward the array centre (``(1 - pull) c``, the central tendency that
   localization on the forearm shows), plus a participant-specific constant bias and
   per-trial isotropic Gaussian noise of participant-specific SD. The answer is the
   location nearest to the perceived position. A diffuse field (funneling) puts energy
   under the actuators, so its centroid strays from the target; a focused field puts it
   at the target.
3. **Selected locations (Study 2).** The locations whose energy, times per-trial
   log-normal noise, reaches a participant-specific fraction of the largest such
   energy, together with the Study 1 answer: a spread field selects more locations.
4. **Response time.** Log-normal around a participant-specific median (0.9-1.4 s), plus
   a fixed cost per extra selected location in Study 2.

Parameters were chosen so that errors fall in the ranges reported for vibrotactile
point localization on the forearm: roughly 10-20 mm (Cholewiak & Collins 2003,
*Perception & Psychophysics* 65(7):1058-1077, about 1 cm at best near anatomical
anchors and worse elsewhere; Mancini et al. 2014, *Annals of Neurology* 75(6):917-924,
tactile acuity maps with forearm values in the centimetre range), and phantom
(funneling) sensations are diffuse and often felt over several locations (Israr &
Poupyrev 2011, CHI "Tactile brush"). Response times of 1-1.5 s are typical of
keypad localization responses.

Every random draw is seeded from the participant seed and, per trial, from
``(seed, study, trial_index)``: a resumed session gets the answers an uninterrupted one
would have given.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..errors import StudyError
from .engine import Presentation, Response, drive_sha256
from .protocol import StudyDesign

__all__ = ["PerceptualModel", "Percept", "SimulatedParticipant", "MODEL_NOTICE"]

#: What tools print next to results from simulated participants.
MODEL_NOTICE = (
    "Simulated participants answer through a perceptual MODEL (energy centroid of the simulated "
    "skin field, pulled toward the array centre, plus noise); their answers are not data about people."
)


@dataclass(frozen=True)
class PerceptualModel:
    """Parameters of the simulated participants' perceptual model (SI units).

    Attributes
    ----------
    grid_half_width_m, grid_step_m : float
        Square grid over which the skin is felt, m (centred on the array).
    band_hz : (float, float)
        Frequencies that count toward the felt energy, Hz.
    n_fft : int
        Transform length for the energy (long enough for the drive and its decay).
    pull : float
        Fraction of the way from the energy centroid toward the array centre.
    noise_sd_m : (float, float)
        Range (uniform) of a participant's per-trial position noise SD, m.
    bias_sd_m : float
        SD of a participant's constant position bias, m, per axis.
    select_fraction : (float, float)
        Range (uniform) of a participant's Study 2 threshold, as a fraction of the
        largest location energy.
    select_log_sd : float
        SD of the per-trial, per-location log-normal noise on location energies.
    rt_median_s : (float, float)
        Range (uniform) of a participant's median response time, s.
    rt_log_sd : float
        SD of the log of response times.
    rt_per_extra_location_s : float
        Study 2: extra time per selected location after the first, s.
    """

    grid_half_width_m: float = 32e-3
    grid_step_m: float = 4e-3
    band_hz: tuple[float, float] = (10.0, 1000.0)
    n_fft: int = 8192
    pull: float = 0.25
    noise_sd_m: tuple[float, float] = (9e-3, 14e-3)
    bias_sd_m: float = 2e-3
    select_fraction: tuple[float, float] = (0.55, 0.75)
    select_log_sd: float = 0.35
    rt_median_s: tuple[float, float] = (0.9, 1.4)
    rt_log_sd: float = 0.3
    rt_per_extra_location_s: float = 0.35

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class Percept:
    """What a stimulus feels like to the model (before noise).

    Attributes
    ----------
    centroid_xy : ndarray, shape (2,)
        Energy-weighted centroid of the field, m.
    location_energy : ndarray, shape (n_locations,)
        Field energy at each location, m² s.
    spread_m : float
        Energy-weighted RMS distance from the centroid, m (how diffuse the field is).
    """

    centroid_xy: np.ndarray
    location_energy: np.ndarray
    spread_m: float


class SimulatedParticipant:
    """A simulated participant who feels stimuli on a :class:`SimulatedForearm`.

    Parameters
    ----------
    forearm : SimulatedForearm
        The participant's forearm (the rig the stimuli play on).
    seed : int
        Participant seed for the participant's traits and per-trial noise.
    model : PerceptualModel, optional
        Model parameters.

    Notes
    -----
    Implements the :class:`~vibrofocus.studies.engine.Responder` protocol
    (``respond``, ``wait_resume``) so a :class:`StudyEngine` can run it. See the module
    docstring for the model; it is a model, not data.
    """

    def __init__(self, forearm: Any, seed: int, model: PerceptualModel | None = None) -> None:
        if not hasattr(forearm, "transfer"):
            raise StudyError("a simulated participant needs the simulated forearm rig (with .transfer)")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise StudyError(f"participant seed must be a non-negative integer, got {seed!r}")
        self.forearm = forearm
        self.seed = int(seed)
        self.model = model if model is not None else PerceptualModel()
        m = self.model
        traits = np.random.default_rng([self.seed, 0x7A17])
        self.noise_sd_m = float(traits.uniform(*m.noise_sd_m))
        self.bias_m = traits.normal(0.0, m.bias_sd_m, size=2)
        self.select_fraction = float(traits.uniform(*m.select_fraction))
        self.rt_median_s = float(traits.uniform(*m.rt_median_s))
        layout = forearm.layout
        self.locations_xy = np.asarray(layout.locations_xy, dtype=float)
        self.centre_xy = np.asarray(layout.actuators_xy, dtype=float).mean(axis=0)
        half, step = m.grid_half_width_m, m.grid_step_m
        axis = np.arange(-half, half + step / 2, step)
        gx, gy = np.meshgrid(axis + self.centre_xy[0], axis + self.centre_xy[1])
        self.grid_xy = np.column_stack([gx.ravel(), gy.ravel()])
        self._n_grid = len(self.grid_xy)
        freqs = np.fft.rfftfreq(m.n_fft, 1.0 / forearm.fs)
        self._bins = np.flatnonzero((freqs >= m.band_hz[0]) & (freqs <= m.band_hz[1]))
        self._freqs = freqs[self._bins]
        self._H_grid: np.ndarray | None = None
        self._cache: dict[str, Percept] = {}

    @property
    def _H(self) -> np.ndarray:
        # The transfer to the grid and the locations, computed once on first use (the
        # costly part): each stimulus is then one matrix product.
        if self._H_grid is None:
            points = np.concatenate([self.grid_xy, self.locations_xy])
            self._H_grid = self.forearm.transfer(points, self._freqs)  # (n_bins, n_points, n_act)
        return self._H_grid

    def describe(self) -> dict[str, Any]:
        """The participant's traits and the model parameters (JSON-serialisable)."""
        return {
            "model": "energy-centroid perceptual model (simulated, not data)",
            "seed": self.seed,
            "noise_sd_m": self.noise_sd_m,
            "bias_m": self.bias_m.tolist(),
            "select_fraction": self.select_fraction,
            "rt_median_s": self.rt_median_s,
            "parameters": self.model.to_dict(),
        }

    # ------------------------------------------------------------------ model
    def energy(self, drives: np.ndarray) -> np.ndarray:
        """Felt field energy ``∫ u² dt`` at the grid points then the locations, m² s.

        Parameters
        ----------
        drives : ndarray, shape (n_actuators, n_samples)
            V.
        """
        d = np.asarray(drives, dtype=float)
        n_act = self.forearm.layout.n_actuators
        if d.ndim != 2 or d.shape[0] != n_act:
            raise StudyError(f"drives must have shape ({n_act}, n_samples), got {d.shape}")
        if d.shape[1] > self.model.n_fft:
            raise StudyError(f"drives of {d.shape[1]} samples are longer than the model's n_fft={self.model.n_fft}")
        spec = np.fft.rfft(d, self.model.n_fft, axis=1)[:, self._bins]  # (n_act, n_bins)
        u = np.einsum("fpq,qf->pf", self._H, spec)
        # Parseval for a real signal: sum_t u^2 = (2 / N) sum_{0<f<fs/2} |U_f|^2; dt = 1/fs.
        return 2.0 * np.sum(np.abs(u) ** 2, axis=1) / (self.model.n_fft * self.forearm.fs)

    def percept(self, drives: np.ndarray) -> Percept:
        """The noise-free percept of a stimulus (cached per drive)."""
        key = drive_sha256(drives)
        if key not in self._cache:
            e = self.energy(drives)
            grid_e, loc_e = e[: self._n_grid], e[self._n_grid:]
            total = grid_e.sum()
            if not np.isfinite(total) or total <= 0:
                raise StudyError("the stimulus produces no vibration on the skin: nothing to perceive")
            w = grid_e / total
            centroid = w @ self.grid_xy
            spread = float(np.sqrt(w @ np.sum((self.grid_xy - centroid) ** 2, axis=1)))
            self._cache[key] = Percept(centroid, loc_e, spread)
        return self._cache[key]

    def answer(self, drives: np.ndarray, study: int, trial_index: int, design: StudyDesign | None = None) -> Response:
        """The model's answer to one trial.

        Parameters
        ----------
        drives : ndarray, shape (n_actuators, n_samples)
            The stimulus, V.
        study : {1, 2}
        trial_index : int
            Seeds the trial's noise together with the participant seed and the study.
        design : StudyDesign, optional
            Which locations may be answered (default all of the layout's).
        """
        m = self.model
        p = self.percept(drives)
        rng = np.random.default_rng([self.seed, int(study), int(trial_index)])
        allowed = np.asarray(design.locations if design is not None else range(1, len(self.locations_xy) + 1)) - 1
        perceived = (1.0 - m.pull) * (p.centroid_xy - self.centre_xy) + self.centre_xy
        perceived = perceived + self.bias_m + rng.normal(0.0, self.noise_sd_m, size=2)
        dist = np.linalg.norm(self.locations_xy[allowed] - perceived, axis=1)
        best = int(allowed[np.argmin(dist)]) + 1
        chosen = {best}
        if study == 2:
            noisy = p.location_energy[allowed] * rng.lognormal(0.0, m.select_log_sd, size=allowed.size)
            chosen |= {int(i) + 1 for i in allowed[noisy >= self.select_fraction * noisy.max()]}
        rt = self.rt_median_s * rng.lognormal(0.0, m.rt_log_sd)
        if study == 2:
            rt += m.rt_per_extra_location_s * (len(chosen) - 1)
        return Response(tuple(sorted(chosen)), float(rt))

    # ------------------------------------------------------------------ Responder
    def respond(self, presentation: Presentation) -> Response:
        """Answer a presented trial (the :class:`Responder` protocol)."""
        return self.answer(
            presentation.stimulus.drives, presentation.study, presentation.trial.trial_index, presentation.design
        )

    def wait_resume(self) -> bool:
        """A simulated participant never pauses."""
        return True
