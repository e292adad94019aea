"""Simulated participants: a perceptual model (v3) that answers from the simulated skin.

This is a **model, not data** (:data:`MODEL_NOTICE`). It lets a whole study run end to end
without people; nothing it produces is evidence about how people perceive the stimuli.
The model itself — its stages, their sources and which parameters are fitted to the
source paper's statistics — is :mod:`vibrofocus.simulation.perception`; this module plugs it
into the study engine as a responder.

Per stimulus (drive signals on the participant's simulated forearm) the peripheral
stage (felt energy on an 11 x 11 skin grid) is computed once and cached by the drives'
hash; each trial then costs a few numpy operations. Every random draw is seeded from the
participant seed (traits) and, per trial, from ``(seed, study, trial_index)`` in a
protocol's first block (the paper's studies) and ``(seed, study, trial_index, block)`` in
a later one, so that every trial of a participant has its own stream: a resumed session
gets the answers an uninterrupted one would have given.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import StudyError
from ..studies.engine import Presentation, Response, drive_sha256
from .perception import (
    MODEL_LABEL,
    MODEL_VERSION,
    PerceptualModel,
    Percepts,
    Traits,
    band_transfer,
    draw_answers,
    felt_energy,
    posterior_ratio_rule,
    own_transfer,
    skin_grid,
    study2_rt,
)
from ..studies.protocol import StudyDesign

__all__ = ["PerceptualModel", "Percepts", "SimulatedParticipant", "MODEL_NOTICE", "MODEL_VERSION", "MODEL_LABEL"]

#: What tools print next to results from simulated participants.
MODEL_NOTICE = (
    f"{MODEL_LABEL}: answers come from a perceptual MODEL (Pacinian detection threshold, "
    "energy-law funneling from the skin field and from what each actuator delivers through its contact, "
    "central bias toward the array centre, localization noise; parameters fitted to the source paper's "
    "statistics), not from people."
)


class SimulatedParticipant:
    """A simulated participant who feels stimuli on a :class:`SimulatedForearm`.

    Parameters
    ----------
    forearm : SimulatedForearm
        The participant's forearm (the rig the stimuli play on).
    seed : int
        Participant seed for the participant's traits and per-trial noise.
    model : PerceptualModel, optional
        Model parameters (default: the hypothesis' fitted parameters,
        :meth:`~vibrofocus.simulation.hypotheses.Hypothesis.model`).
    hypothesis : str or Hypothesis, optional
        How the participant reads the felt field (:mod:`vibrofocus.simulation.hypotheses`;
        default :data:`~vibrofocus.simulation.hypotheses.DEFAULT_HYPOTHESIS`).

    Notes
    -----
    Implements the :class:`~vibrofocus.studies.engine.Responder` protocol
    (``respond``, ``wait_resume``) so a :class:`StudyEngine` can run it.
    """

    def __init__(self, forearm: Any, seed: int, model: PerceptualModel | None = None, hypothesis: Any = None) -> None:
        from .hypotheses import hypothesis as find_hypothesis

        if not hasattr(forearm, "transfer"):
            raise StudyError("a simulated participant needs the simulated forearm rig (with .transfer)")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise StudyError(f"participant seed must be a non-negative integer, got {seed!r}")
        self.forearm = forearm
        self.seed = int(seed)
        self.hypothesis = find_hypothesis(hypothesis)
        self.model = model if model is not None else self.hypothesis.model()
        self.traits = Traits.draw(self.model, self.seed)
        layout = forearm.layout
        self.locations_xy = np.asarray(layout.locations_xy, dtype=float)
        self.centre_xy = np.asarray(layout.actuators_xy, dtype=float).mean(axis=0)
        self.grid_xy = skin_grid(self.centre_xy, self.model)
        self.actuators_xy = np.asarray(layout.actuators_xy, dtype=float)
        # Per drive length: the transfer to the skin grid and to each actuator's own contact.
        self._H: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._cache: dict[str, tuple[np.ndarray, Percepts]] = {}

    def describe(self) -> dict[str, Any]:
        """The participant's traits and the model parameters (JSON-serialisable)."""
        return {
            "model": MODEL_LABEL,
            "hypothesis": self.hypothesis.to_dict(),
            "seed": self.seed,
            "traits": self.traits.to_dict(),
            "parameters": self.model.to_dict(),
        }

    # ------------------------------------------------------------------ model
    def energy(self, drives: np.ndarray) -> np.ndarray:
        """Felt energy on the skin grid (re the reference tap), shape (n_grid,).

        Parameters
        ----------
        drives : ndarray, shape (n_actuators, n_samples)
            V.
        """
        d = np.asarray(drives, dtype=float)
        n_act = self.forearm.layout.n_actuators
        if d.ndim != 2 or d.shape[0] != n_act or d.shape[1] < 16:
            raise StudyError(f"drives must have shape ({n_act}, n_samples >= 16), got {d.shape}")
        return felt_energy(self._transfers(d.shape[1])[0], d, self.forearm.fs, self.model)

    def _transfers(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        if n not in self._H:
            self._H[n] = (band_transfer(self.forearm, self.grid_xy, n, self.model),
                          own_transfer(self.forearm, self.actuators_xy, n, self.model))
        return self._H[n]

    def percept(self, drives: np.ndarray) -> Percepts:
        """The noise-free central percept of a stimulus (cached per drive), one entry."""
        key = drive_sha256(drives)
        if key not in self._cache:
            e = self.energy(drives)
            if not np.all(np.isfinite(e)) or e.max() <= 0:
                raise StudyError("the stimulus produces no vibration on the skin: nothing to perceive")
            d = np.asarray(drives, dtype=float)
            own = felt_energy(self._transfers(d.shape[1])[1], d[None], self.forearm.fs, self.model)
            self._cache[key] = (e, self.hypothesis.percepts(e[None], self.grid_xy, self.model, self.traits, own,
                                                            self.actuators_xy, self.locations_xy))
        return self._cache[key][1]

    def answer(self, drives: np.ndarray, study: int, trial_index: int, design: StudyDesign | None = None,
               block: int = 0) -> Response:
        """The model's answer to one trial.

        Parameters
        ----------
        drives : ndarray, shape (n_actuators, n_samples)
            The stimulus, V.
        study : {1, 2}
        trial_index : int
            Seeds the trial's noise together with the participant seed, the study and the block.
        design : StudyDesign, optional
            Which locations may be answered (default all of the layout's). A point design
            (``design.point``) gets a point answer: the trial's perceived place (the
            posterior mean the model's Study 1 answer is the nearest location to), in mm
            in the layout frame, kept within the picture's area
            (:func:`~vibrofocus.studies.points.point_area`); its location is left for the
            store to take (the point's nearest). A threshold design (``design.detection``)
            gets whether the tap was felt: 1 where some skin point's felt energy exceeds the
            participant's own threshold (:func:`~vibrofocus.simulation.perception.felt_threshold`,
            the hypothesis' reference sensation level and the participant's offset), else 0.
        block : int
            The session's block of its protocol (:attr:`Presentation.block`). A trial index
            restarts in every block, so a later block's trials draw from streams of their
            own, ``(seed, study, trial_index, block)``; block 0's are ``(seed, study,
            trial_index)``, so that the paper's studies keep their answers.
        """
        if study not in (1, 2):
            raise StudyError(f"study must be 1 or 2, got {study!r}")
        if isinstance(block, bool) or not isinstance(block, (int, np.integer)) or block < 0:
            raise StudyError(f"block must be a non-negative integer, got {block!r}")
        p = self.percept(drives)
        key = [self.seed, int(study), int(trial_index)] + ([int(block)] if block else [])
        if design is not None and design.detection:
            rt = float(np.random.default_rng(key).lognormal(np.log(0.6), 0.3))
            return Response((int(bool(p.felt[0])),), rt)
        rng = np.random.default_rng(key)
        allowed = np.asarray(design.locations if design is not None else range(1, len(self.locations_xy) + 1)) - 1
        seen: dict[str, np.ndarray] = {}

        def rule(posteriors: Any, *args: Any) -> tuple[np.ndarray, np.ndarray]:
            seen["perceived_m"] = posteriors.perceived_m  # the trial's percept: what a point answer shows
            return posterior_ratio_rule(posteriors, *args)

        a, sel, rt = draw_answers(
            p, np.zeros(1, dtype=int), self.locations_xy, self.centre_xy, self.model, self.traits, rng,
            allowed=allowed, rule=rule,
        )
        if design is not None and design.point:
            from ..studies.points import point_area

            area = point_area(self.forearm.layout, design.locations)
            x_mm, y_mm = (float(v) * 1e3 for v in seen["perceived_m"][0])
            point = (min(max(x_mm, area["x_mm"][0]), area["x_mm"][1]), min(max(y_mm, area["y_mm"][0]), area["y_mm"][1]))
            return Response(None, float(rt[0]), point_mm=point)
        if study == 1:
            return Response((int(a[0]) + 1,), float(rt[0]))
        chosen = tuple(int(i) + 1 for i in allowed if sel[0, i])
        return Response(chosen, float(study2_rt(rt, sel[:, allowed], self.model)[0]))

    # ------------------------------------------------------------------ Responder
    def respond(self, presentation: Presentation) -> Response:
        """Answer a presented trial (the :class:`Responder` protocol)."""
        return self.answer(
            presentation.stimulus.drives, presentation.study, presentation.trial.trial_index, presentation.design,
            presentation.block,
        )

    def wait_resume(self) -> bool:
        """A simulated participant never pauses."""
        return True
