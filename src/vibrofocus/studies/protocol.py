"""Planning of the localization studies (docs/file-formats.md, trials file): designs, trial lists, response rules.

A session's whole trial list is planned up front from a stored seed, so that the order a
participant saw can be reproduced and a crashed session resumes on the very same plan.

Study 1 ("performance") asks for exactly one location per trial; Study 2 ("confidence")
allows one or more distinct locations. Both use the same design: every method at every
location, repeated, in random order, after a few training trials.
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass
from functools import lru_cache
from importlib import resources
from typing import Any

import numpy as np

from .._validation import shorten
from ..defaults import METHODS, STUDY_METHODS
from ..errors import StudyError
from ..io.responses import format_response  # the stored form of a response: one home, re-exported
from ..layout import ArrayLayout
from .staircase import Staircase

__all__ = [
    "STUDIES",
    "PHASES",
    "LEVEL_RULES",
    "DEFAULT_LEVELS",
    "LEGACY_LEVELS",
    "level_options",
    "REFERENCE_LOCATIONS",
    "StudyDesign",
    "PlannedTrial",
    "plan_trials",
    "parse_response",
    "format_response",
]

#: Study numbers: 1 = one location per trial, 2 = several locations allowed.
STUDIES = (1, 2)
#: Phases of a session, in the order they are run.
PHASES = ("training", "main")
#: Location numbers of the reference setup (docs/method.md): the default design's
#: locations. A design names its own (any layout's ``location_numbers``).
REFERENCE_LOCATIONS: tuple[int, ...] = ArrayLayout.reference().location_numbers
#: Level rules of a study protocol (:func:`level_options`): ``"paper"`` plays each method
#: at the level the source paper gave it (Sec. II.C); ``"equal-peak"`` plays every method
#: at the drive limit.
LEVEL_RULES = ("paper", "equal-peak")
#: The level rule of a new session: the paper's (its Study 1 and Study 2 protocols).
DEFAULT_LEVELS = "paper"
#: The rule of a session stored before sessions kept their level rule (vibrofocus up to
#: 0.x without the ``levels`` key): every method was played at the drive limit then.
LEGACY_LEVELS = "equal-peak"


def level_options(levels: str, limit_v: float) -> dict[str, Any]:
    """The rendering options of a level rule (keywords of ``rendering.render``).

    Parameters
    ----------
    levels : {"paper", "equal-peak"}
        ``"paper"`` (de Vlam et al. 2023, Sec. II.C): funneling by eq. 3 unscaled with
        ``A = limit_v`` (2.5 V on each exciter for the centre of a square cell); the
        inverse filter asks its ``target_peak_m`` (2 µm) and is scaled down only where it
        would need more than ``limit_v``; the combination asks the displacement funneling
        makes at the target, capped the same way; any other method at its own level,
        capped the same way. ``"equal-peak"``: every method scaled up or down to exactly
        ``limit_v`` (``render``'s own default, for comparing designs at equal drive).
    limit_v : float
        Drive limit, V peak.

    Returns
    -------
    dict
        ``scale_to_limit`` and, for ``"paper"``, ``funneling_amplitude_v``.
    """
    if levels not in LEVEL_RULES:
        raise StudyError(f"levels must be one of {', '.join(LEVEL_RULES)}, got {shorten(levels)}")
    if levels == "equal-peak":
        return {"scale_to_limit": True}
    return {"scale_to_limit": False, "funneling_amplitude_v": float(limit_v)}


@dataclass(frozen=True)
class StudyDesign:
    """The design of one localization study.

    Parameters
    ----------
    study : {1, 2}
        1: the participant answers exactly one location; 2: one or more.
    methods : tuple of str
        Rendering methods compared (default: funneling, inverse, combination).
    locations : tuple of int
        Location numbers (1-based) used as targets and accepted as answers
        (default :data:`REFERENCE_LOCATIONS`).
    repetitions : int
        Times each (method, location) condition appears in the main phase.
    n_training : int
        Training trials before the main phase, drawn from the same conditions.
    levels : {"paper", "equal-peak"}
        The level rule of the stimuli (:func:`level_options`); default
        :data:`DEFAULT_LEVELS`, the paper's.
    level_db : float
        Level of every stimulus re the level rule, dB (0: the rule's own level; a
        protocol file's block level). A level that would need more than the drive limit
        is refused when the session is planned
        (:func:`~vibrofocus.studies.engine.check_drive_levels`).
    point : bool
        The participant answers a point on a picture of the arm area, mm
        (:mod:`vibrofocus.studies.points`); its nearest location is the answer's
        response. Study 1 only (one location per answer). Default False.
    staircase : Staircase, optional
        A threshold block (docs/protocols.md, "Threshold blocks"): each trial asks whether the
        tap was felt (answers 1 or 0), at the level the staircase sets from the answers so
        far (:class:`~vibrofocus.studies.staircase.Staircase`, dB re the level rule;
        ``level_db`` is then 0). Study 1 sessions; the training trials play at its start level.

    Notes
    -----
    The built-in designs of Study 1 and Study 2 (:meth:`from_config`) are read from the
    shipped protocol files ``paper-study1`` and ``paper-study2``
    (:mod:`vibrofocus.studies.protocol_files`); the defaults here are the same design.
    """

    study: int = 1
    methods: tuple[str, ...] = STUDY_METHODS
    locations: tuple[int, ...] = REFERENCE_LOCATIONS
    repetitions: int = 3
    n_training: int = 5
    levels: str = DEFAULT_LEVELS
    level_db: float = 0.0
    point: bool = False
    staircase: Staircase | None = None

    def __post_init__(self) -> None:
        if isinstance(self.study, bool) or self.study not in STUDIES:
            raise StudyError(f"study must be 1 or 2, got {self.study!r}")
        methods = tuple(self.methods)
        if not methods:
            raise StudyError("a study needs at least one method, got none")
        # The registry's methods: a lab's own, registered or installed, may be studied too.
        from ..rendering.registry import available_methods

        known = available_methods()
        for m in methods:
            if m not in known:
                raise StudyError(f"unknown method {m!r} in the study design; known: {', '.join(known)}")
        if len(set(methods)) != len(methods):
            raise StudyError(f"methods are repeated in the study design: {methods}")
        locations = tuple(self.locations)
        if not locations or any(isinstance(x, bool) or not isinstance(x, (int, np.integer)) or x < 1 for x in locations):
            raise StudyError(f"locations must be location numbers >= 1, got {locations!r}")
        if len(set(locations)) != len(locations):
            raise StudyError(f"locations are repeated in the study design: {locations}")
        for name in ("repetitions", "n_training"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
                raise StudyError(f"{name} must be an integer >= 0, got {value!r}")
        if self.repetitions < 1:
            raise StudyError(f"repetitions must be >= 1, got {self.repetitions}")
        if self.levels not in LEVEL_RULES:
            raise StudyError(f"levels must be one of {', '.join(LEVEL_RULES)}, got {shorten(self.levels)}")
        if (isinstance(self.level_db, bool) or not isinstance(self.level_db, (int, float, np.integer, np.floating))
                or not np.isfinite(self.level_db) or abs(float(self.level_db)) > 120.0):
            raise StudyError(f"level_db must be a finite number within +-120 dB, got {shorten(self.level_db)}")
        if not isinstance(self.point, bool):
            raise StudyError(f"point must be true or false, got {shorten(self.point)}")
        if self.point and self.study != 1:
            raise StudyError("a point answer stands for one location: it needs study 1, got study 2")
        if self.staircase is not None:
            if isinstance(self.staircase, Mapping):
                object.__setattr__(self, "staircase", Staircase.from_dict(self.staircase))
            if not isinstance(self.staircase, Staircase):
                raise StudyError(f"staircase must be a Staircase, got {shorten(self.staircase)}")
            if self.study != 1 or self.point or self.level_db:
                raise StudyError("a threshold block (staircase) is a study 1 session of detection answers at the "
                                 "staircase's levels: no point answers, level_db 0")
        object.__setattr__(self, "level_db", float(self.level_db))
        object.__setattr__(self, "methods", methods)
        object.__setattr__(self, "locations", tuple(int(x) for x in locations))
        object.__setattr__(self, "study", int(self.study))

    @property
    def multi_select(self) -> bool:
        """Whether a trial accepts several locations (Study 2)."""
        return self.study == 2

    @property
    def n_main(self) -> int:
        """Number of main trials: methods x locations x repetitions."""
        return len(self.methods) * len(self.locations) * self.repetitions

    @property
    def n_trials(self) -> int:
        """All trials of a session, training included."""
        return self.n_training + self.n_main

    @property
    def detection(self) -> bool:
        """Whether trials ask "felt or not" (a threshold block: :attr:`staircase` is set)."""
        return self.staircase is not None

    @property
    def gain(self) -> float:
        """Amplitude factor of :attr:`level_db` on the level rule's drives: 10^(level_db / 20)."""
        return float(10.0 ** (self.level_db / 20.0))

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable form, stored in the session's config (``level_db`` only when not 0,
        ``point`` only when true, ``staircase`` only when set)."""
        d = asdict(self)
        if self.staircase is None:
            del d["staircase"]
        else:
            d["staircase"] = self.staircase.to_dict()
        d["methods"] = list(self.methods)
        d["locations"] = list(self.locations)
        if not self.level_db:
            del d["level_db"]
        if not self.point:
            del d["point"]
        return d

    @classmethod
    def from_config(cls, study: int, config: Mapping[str, Any] | None, *, stored: bool = False) -> "StudyDesign":
        """The design of ``study`` with the design keys found in ``config`` applied.

        The design of ``study`` is the shipped protocol ``paper-study<study>``'s block
        (:func:`~vibrofocus.studies.protocol_files.shipped_protocol`). Keys other than
        ``methods``, ``locations``, ``repetitions``, ``n_training``, ``levels`` and
        ``level_db``, ``point``, ``staircase`` are ignored here (they are stored with the session as they are).
        ``stored=True``: ``config`` is a stored session's, and one without ``levels``
        was planned before sessions kept it, so its rule is :data:`LEGACY_LEVELS`.
        """
        config = dict(config or {})
        if isinstance(study, bool) or study not in STUDIES:
            raise StudyError(f"study must be 1 or 2, got {study!r}")
        base = design_of_block(study, _paper_block(study))
        kwargs: dict[str, Any] = {key: getattr(base, key) for key in
                                  ("methods", "locations", "repetitions", "n_training", "levels", "level_db")}
        if stored and "levels" not in config:
            kwargs["levels"] = LEGACY_LEVELS
        for key in ("methods", "locations", "repetitions", "n_training", "levels", "level_db", "point", "staircase"):
            if key in config:
                value = config[key]
                kwargs[key] = tuple(value) if key in ("methods", "locations") else value
        return cls(study=study, **kwargs)


@dataclass(frozen=True)
class PlannedTrial:
    """One planned trial of a session.

    Attributes
    ----------
    session_id : int
        The session it belongs to (0 before it is stored).
    trial_index : int
        0-based position in the session, training trials first.
    phase : {"training", "main"}
        Which part of the session.
    trial : int
        1-based number within its phase (the ``trial`` column of the export).
    method : str
        Rendering method.
    target : int
        Target location number (1-based).
    """

    session_id: int
    trial_index: int
    phase: str
    trial: int
    method: str
    target: int

    def condition(self) -> tuple[str, int]:
        """``(method, target)``."""
        return self.method, self.target


def plan_trials(design: StudyDesign, seed: int, *, session_id: int = 0) -> list[PlannedTrial]:
    """The full trial list of a session: training trials, then the shuffled main trials.

    Parameters
    ----------
    design : StudyDesign
        What to plan.
    seed : int
        Seed of the randomization (``numpy.random.default_rng``); stored with the
        session so that the order can be reproduced.
    session_id : int
        Copied into each trial.

    Returns
    -------
    list of PlannedTrial
        ``design.n_trials`` trials. Every (method, location) condition appears exactly
        ``design.repetitions`` times in the main phase. Training trials are distinct
        conditions drawn at random (repeating only when there are more training trials
        than conditions).
    """
    seed = _check_seed(seed)
    rng = np.random.default_rng(seed)
    conditions = [(m, loc) for m in design.methods for loc in design.locations]
    n_cond = len(conditions)
    # Training: distinct conditions where possible, so a participant meets variety early.
    picks: list[int] = []
    while len(picks) < design.n_training:
        take = min(n_cond, design.n_training - len(picks))
        picks.extend(rng.choice(n_cond, size=take, replace=False).tolist())
    main = np.repeat(np.arange(n_cond), design.repetitions)
    main = rng.permutation(main)
    trials = []
    for k, c in enumerate(picks):
        m, loc = conditions[c]
        trials.append(PlannedTrial(session_id, k, "training", k + 1, m, loc))
    for k, c in enumerate(main.tolist()):
        m, loc = conditions[c]
        trials.append(PlannedTrial(session_id, design.n_training + k, "main", k + 1, m, loc))
    return trials


_SPLIT = re.compile(r"[\s,;]+")


def parse_response(response: Any, design: StudyDesign) -> tuple[int, ...]:
    """Validate an answer and return its locations, sorted.

    Parameters
    ----------
    response : int, str or iterable of int
        ``5``, ``"5"``, ``"4 5"``, ``"45"`` (keypad digits typed together, allowed while
        every location number is a single digit), ``[4, 5]``.
    design : StudyDesign
        Study 1 needs exactly one location; Study 2 one or more distinct ones. Every
        location must be one of the design's locations.

    Returns
    -------
    tuple of int
        The locations, ascending.

    Raises
    ------
    StudyError
        Empty, non-numeric, out-of-range, repeated, or (Study 1) more than one location.
    """
    valid = design.locations
    lo, hi = min(valid), max(valid)
    if isinstance(response, bool):
        raise StudyError(f"response must be location numbers {lo}-{hi}, got {shorten(response)}")
    if isinstance(response, (int, np.integer)):
        items: list[Any] = [int(response)]
    elif isinstance(response, str):
        text = response.strip()
        tokens = [t for t in _SPLIT.split(text) if t]
        # Keypad digits typed together ("45") mean several single-digit locations; a 0
        # among them ("10") is a number the participant meant, not location 0.
        if len(tokens) == 1 and len(tokens[0]) > 1 and tokens[0].isascii() and tokens[0].isdigit() and hi <= 9:
            if "0" in tokens[0] and 0 not in valid:
                raise StudyError(f"response location {int(tokens[0])} is outside the study's locations {lo}-{hi} "
                                 "(several locations: type their digits together, e.g. 45)")
            tokens = list(tokens[0])
        items = tokens
    elif isinstance(response, Iterable):
        items = list(response)
    else:
        raise StudyError(f"response must be location numbers {lo}-{hi}, got {type(response).__name__}")
    if not items:
        raise StudyError(f"response is empty; answer at least one location {lo}-{hi}")
    locations: list[int] = []
    for item in items:
        try:
            if isinstance(item, bool):
                raise ValueError
            if isinstance(item, (float, np.floating)) and not float(item).is_integer():
                raise ValueError
            if isinstance(item, str) and not item.isascii():  # int() reads other scripts' digits too
                raise ValueError
            value = int(item)
        except (TypeError, ValueError):
            raise StudyError(f"response must be location numbers {lo}-{hi}, got {shorten(item)}") from None
        if value not in valid:
            raise StudyError(f"response location {value} is outside the study's locations {lo}-{hi}")
        locations.append(value)
    if len(set(locations)) != len(locations):
        raise StudyError(f"response names a location more than once: {locations}")
    if not design.multi_select and len(locations) != 1:
        raise StudyError(f"Study 1 takes exactly one location per trial, got {len(locations)}: {locations}")
    return tuple(sorted(locations))


def design_of_block(study: int, block: Mapping[str, Any]) -> StudyDesign:
    """The :class:`StudyDesign` of one protocol block, given as the protocol file's fields.

    ``block`` holds ``methods``, ``locations``, ``repetitions``, ``training_trials``,
    ``level_rule``, ``levels`` (one level, in dB re the level rule) and ``response``, as in
    a protocol file's ``[[blocks]]`` table (docs/protocols.md). A ``detection`` block's level
    is its staircase's start (with ``steps_db`` and ``max_db`` where given).
    """
    staircase = None
    level_db = float(block["levels"][0])
    if block["response"] == "detection":
        staircase = Staircase(start_db=level_db, **{k: (tuple(block[k]) if k == "steps_db" else block[k])
                                                    for k in ("steps_db", "max_db") if block.get(k) is not None})
        level_db = 0.0
    return StudyDesign(study=study, methods=tuple(block["methods"]), locations=tuple(block["locations"]),
                       repetitions=int(block["repetitions"]), n_training=int(block["training_trials"]),
                       levels=block["level_rule"], level_db=level_db,
                       point=block["response"] == "point", staircase=staircase)


@lru_cache(maxsize=None)
def _paper_block(study: int) -> Mapping[str, Any]:
    """Block 0 of the shipped protocol of the paper's study ``study``, read as plain TOML.

    Read here, not through :mod:`.protocol_files` (which builds on this module): the file
    ships with the package, and tests/studies/test_protocol_files.py checks that it passes
    the protocol checks and gives the same trials as this design.
    """
    text = resources.files("vibrofocus.studies").joinpath("protocols", f"paper-study{study}.toml").read_text(
        encoding="utf-8")
    return tomllib.loads(text)["blocks"][0]


def _check_seed(seed: Any) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= int(seed) < 2**63:
        raise StudyError(f"seed must be an integer in [0, 2**63), got {seed!r}")
    return int(seed)

