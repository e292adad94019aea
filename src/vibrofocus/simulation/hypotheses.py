"""Simulated participants as competing hypotheses: registered readouts of the felt field.

The paper's data cannot single out how a person turns a felt skin field into an answer
(docs/simulated-participants.md, "Hypotheses"). Each :class:`Hypothesis` is one such
readout, named, versioned and cited, registered as rendering methods are
(:func:`register_hypothesis`; :func:`hypothesis` finds one by name). All share the
peripheral stage (felt energies, :func:`~vibrofocus.simulation.perception.felt_energy`),
the participants' traits and the central prior of
:class:`~vibrofocus.simulation.perception.PerceptualModel`; they differ in where the
percept lies and how reliable it is (:meth:`Hypothesis.percepts`). Every one is
level-aware: it reads felt energies relative to the reference tap and to the
participant's threshold, so a stimulus played louder is felt louder.

A MODEL, not data: every output made from simulated participants names its hypothesis
and model version (:meth:`Hypothesis.label`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from importlib import resources
from typing import Any, Mapping

import numpy as np

from .._validation import check_choice
from ..errors import ValidationError
from .parameters import ParameterRange
from .perception import (MODEL_VERSION, Percepts, PerceptualModel, Traits, central_percepts, felt_threshold,
                         funneling_weights, weighted_centre)

__all__ = ["Hypothesis", "register_hypothesis", "hypothesis", "available_hypotheses", "DEFAULT_HYPOTHESIS",
           "GRID_MARGIN_M", "PEAK_SOFTNESS_DB", "hypothesis_fits"]

#: Margin of the grid area beyond the outer locations, m (half the 10 mm pitch): the
#: area the participant sees numbered on the foil (the paper's Sec. II.D).
GRID_MARGIN_M = 5e-3
#: Softness of the "most intense" readout, dB: points within a few dB of the field's
#: largest felt level share the percept (an assumption).
PEAK_SOFTNESS_DB = 1.5

_REGISTRY: dict[str, "Hypothesis"] = {}


@dataclass(frozen=True)
class Hypothesis:
    """One hypothesis of how a simulated participant reads the felt field.

    Attributes
    ----------
    name : str
        Registered name (``simulate-study --hypothesis NAME``).
    version : str
        Version of the hypothesis' model; bump it whenever answers for the same seeds change.
    title : str
        One line: what the participant does.
    sources : str
        Its sources, or its assumption stated as one.
    readout : {"centroid", "grid-peak"}
        Where the percept lies: the energy-law centroid of the whole felt field (v3), or
        the soft peak of the felt field inside the grid area.
    level_reliability : bool
        Whether the sensed position's reliability grows with the recruited activity (the
        summed supra-threshold weights): a weak tap is localized less reliably, so the
        central prior pulls it harder toward the array centre.
    fitted : bool
        Whether the model's parameters were fitted under this hypothesis (False: the
        defaults of :class:`~vibrofocus.simulation.perception.PerceptualModel` are used as
        they are).
    parameters : mapping
        The fitted parameters: changes to the defaults of
        :class:`~vibrofocus.simulation.perception.PerceptualModel` (:meth:`model`).
    levels : str or None
        The level rule of the stimuli the parameters were fitted at (``"paper"``), or None.
    free_parameters : tuple of ParameterRange
        The parameters left free under this hypothesis, each with its range and source;
        every other parameter is fixed (empty: none declared yet).
    """

    name: str
    version: str
    title: str
    sources: str
    readout: str = "centroid"
    level_reliability: bool = False
    fitted: bool = False
    parameters: Mapping[str, Any] = field(default_factory=dict, hash=False)
    levels: str | None = None
    free_parameters: tuple[ParameterRange, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or any(c.isspace() for c in self.name):
            raise ValidationError(f"a hypothesis' name must be a word, got {self.name!r}")
        check_choice(self.readout, "readout", ("centroid", "grid-peak"))
        self.model()  # unknown parameter names fail here, at registration

    def model(self) -> PerceptualModel:
        """The perceptual model with this hypothesis' fitted parameters.

        Returns
        -------
        PerceptualModel
            The defaults changed by :attr:`parameters`.
        """
        return PerceptualModel().replace(**dict(self.parameters)) if self.parameters else PerceptualModel()

    def label(self) -> str:
        """What every output made under this hypothesis says of itself."""
        if not self.fitted:
            fit = " with the model's default parameters, not refitted"
        else:
            fit = f" fitted at {self.levels} levels" if self.levels else ""
        return f"simulated participants: model v{MODEL_VERSION}, hypothesis {self.name} v{self.version}{fit}, not data"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description."""
        return {"name": self.name, "version": self.version, "title": self.title, "sources": self.sources,
                "readout": self.readout, "level_reliability": self.level_reliability, "fitted": self.fitted,
                "levels": self.levels, "parameters": dict(self.parameters), "label": self.label()}

    def percepts(
        self,
        energy: np.ndarray,
        points_xy: np.ndarray,
        model: PerceptualModel,
        traits: Traits,
        actuator_energy: np.ndarray | None = None,
        actuators_xy: np.ndarray | None = None,
        locations_xy: np.ndarray | None = None,
    ) -> Percepts:
        """Noise-free percepts of stimuli of felt energies ``energy`` under this hypothesis.

        Parameters
        ----------
        energy : ndarray, shape (n, n_points)
            Felt energy at the skin points, re the reference tap.
        points_xy : ndarray, shape (n_points, 2)
            m.
        model : PerceptualModel
        traits : Traits
        actuator_energy : ndarray, shape (n, n_actuators), optional
            Felt energy each actuator delivers at its own contact (the drive cue).
        actuators_xy : ndarray, shape (n_actuators, 2), optional
            m.
        locations_xy : ndarray, shape (n_locations, 2), optional
            m; the grid area of the ``grid-peak`` readout (required there).

        Returns
        -------
        Percepts
            With ``reliability`` (n,) when ``level_reliability``.
        """
        base = central_percepts(energy, points_xy, model, traits, actuator_energy, actuators_xy)
        e = np.atleast_2d(np.asarray(energy, dtype=float))
        e_thr = felt_threshold(model, traits)
        position, spread, felt = base.position_m, base.spread_m, base.felt
        if self.readout == "grid-peak":
            if locations_xy is None:
                raise ValidationError(f"hypothesis {self.name!r} needs the locations (the grid area)")
            position, spread = _grid_peak(e, np.asarray(points_xy, float), np.asarray(locations_xy, float))
            position[~felt] = np.nan
            spread[~felt] = np.nan
        reliability = None
        if self.level_reliability:
            # Recruited activity in units of the reference tap felt at one point: a stimulus
            # recruiting as much has half the full reliability (an assumption of form).
            activity = funneling_weights(e, e_thr, model.funneling_exponent).sum(axis=1)
            ref = float(funneling_weights(np.ones((1, 1)), e_thr, model.funneling_exponent)[0, 0])
            reliability = np.where(felt, activity / (activity + max(ref, 1e-12)), np.nan)
        # Every hypothesis detects on the whole skin, so v3's conflict (NaN where nothing is
        # felt) serves as it is.
        return Percepts(position, spread, felt, base.conflict_m, reliability, base.drive_position_m)


def _grid_peak(e: np.ndarray, xy: np.ndarray, locations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Soft peak of the felt level inside the grid area: position (n, 2) and spread (n,), m.

    Whether a stimulus is felt is decided on the whole skin (a tap felt under a cone is
    felt); where it felt most intense is read on the grid area the participant answers
    on, relative to the largest level there, whether or not that level is above threshold.
    """
    lo, hi = locations.min(axis=0) - GRID_MARGIN_M, locations.max(axis=0) + GRID_MARGIN_M
    inside = np.all((xy >= lo - 1e-12) & (xy <= hi + 1e-12), axis=1)
    level = 10.0 * np.log10(np.maximum(e[:, inside], 1e-30))  # dB re the reference tap
    w = np.exp((level - level.max(axis=1, keepdims=True)) / PEAK_SOFTNESS_DB)
    pos, spread, _ = weighted_centre(w, xy[inside])
    return pos, spread


def register_hypothesis(h: Hypothesis, *, replace: bool = False) -> Hypothesis:
    """Register a hypothesis under its name.

    Parameters
    ----------
    h : Hypothesis
    replace : bool
        Allow replacing one registered under the same name.

    Returns
    -------
    Hypothesis
    """
    if not isinstance(h, Hypothesis):
        raise ValidationError(f"a hypothesis must be a Hypothesis, got {type(h).__name__}")
    if h.name in _REGISTRY and _REGISTRY[h.name] != h and not replace:
        raise ValidationError(f"a hypothesis named {h.name!r} is registered already; pass replace=True to replace it")
    _REGISTRY[h.name] = h
    return h


def available_hypotheses() -> tuple[str, ...]:
    """Names of the registered hypotheses, the default first."""
    return tuple(sorted(_REGISTRY, key=lambda n: n != DEFAULT_HYPOTHESIS))


def hypothesis(name: str | Hypothesis | None = None) -> Hypothesis:
    """The hypothesis registered under ``name`` (None: :data:`DEFAULT_HYPOTHESIS`).

    Parameters
    ----------
    name : str or Hypothesis, optional
        A registered name (a :class:`Hypothesis` is returned as it is).

    Returns
    -------
    Hypothesis

    Raises
    ------
    ValidationError
        For a name nothing is registered under (the message lists the known names).
    """
    if isinstance(name, Hypothesis):
        return name
    check_choice(DEFAULT_HYPOTHESIS if name is None else name, "hypothesis", available_hypotheses())
    return _REGISTRY[DEFAULT_HYPOTHESIS if name is None else name]


def hypothesis_fits() -> dict[str, dict[str, Any]]:
    """The fits of the hypotheses shipped with vibrofocus (``simulation/data/hypotheses_fit.json``).

    Written by ``scripts/fit_participants.py adopt``: per hypothesis name, its version,
    the fitted parameters (``model``), the level rule and feature bank they were fitted
    on, the search budget, and the fit loss on the fit seeds and on held-out seeds.

    Returns
    -------
    dict
        ``{"default": name, "hypotheses": {name: fit}}``; empty ``hypotheses`` if none.
    """
    try:
        text = resources.files("vibrofocus.simulation").joinpath("data/hypotheses_fit.json").read_text(encoding="utf-8")
    except FileNotFoundError:
        return {"default": "v3-centroid", "hypotheses": {}}
    return json.loads(text)


def _builtin(name: str, **kw: Any) -> Hypothesis:
    fit = hypothesis_fits()["hypotheses"].get(name)
    if fit is not None:
        kw.update(version=fit["version"], fitted=True, parameters=fit["model"], levels=fit["levels"])
    return register_hypothesis(Hypothesis(name=name, **kw))


_builtin(
    "v3-centroid", version=MODEL_VERSION, fitted=True, readout="centroid",
    title="the place is the energy-law centroid of the whole felt field (perceptual model v3)",
    sources="energy-law funneling (Alles 1970; Israr & Poupyrev 2011; Park & Choi 2018), central prior "
            "(Cholewiak et al. 2020), cue conflict (Koerding et al. 2007); fitted to de Vlam et al. 2023, Sec. III",
)
_builtin(
    "grid-peak", version="1.0", readout="grid-peak",
    title="the place is where it felt most intense inside the grid area (a soft peak of the felt level)",
    sources="the paper's instruction: the participant types the grid number where the stimulus felt most "
            "intense, on a foil over the grid (de Vlam et al. 2023, Sec. II.D); the softness "
            f"({PEAK_SOFTNESS_DB:g} dB) and the area (the locations plus {GRID_MARGIN_M * 1e3:g} mm) are assumptions",
)
_builtin(
    "level-reliability", version="1.0", readout="centroid", level_reliability=True,
    title="v3's centroid, with a reliability that grows with the recruited activity, so weak taps are pulled "
          "to the centre",
    sources="reliability-weighted cue combination with a prior (Koerding et al. 2007); localization improves "
            "with intensity (an assumption of form here: reliability activity / (activity + one reference tap))",
)

#: The hypothesis simulated participants use unless told: the one whose fit, at the paper's
#: levels, holds best on held-out seeds (``hypothesis_fits()["default"]``; how it is chosen:
#: docs/simulated-participants.md, "Hypotheses").
DEFAULT_HYPOTHESIS: str = hypothesis_fits()["default"]
