"""Study protocols as data: a TOML file naming a study's blocks of trials (docs/protocols.md).

A protocol file names a study and its blocks; each block is the design of one session
(:class:`~vibrofocus.studies.protocol.StudyDesign`): its methods, its locations, its levels,
its repetitions, the answer it takes, its training trials, its pacing and its seed. The
source paper's Study 1 and Study 2 ship as ``paper-study1`` and ``paper-study2``
(:func:`shipped_protocol`); the built-in designs are read from them.

A file is read in three steps, each refusing bad input with one line that names the file,
the line and the field (``blocks[0].methods[1]``): its size (at most
:data:`MAX_PROTOCOL_BYTES`, checked before it is read), its TOML syntax (:mod:`tomllib`), and
its fields (pydantic models that forbid unknown keys and convert no types). What the study
engine cannot run yet (targets given as points in mm, several levels in one block) is
accepted by the format and refused when a session is planned (:meth:`StudyProtocol.check_runnable`), before anything
is written.
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any, Literal

from .._validation import shorten
from ..errors import StudyError
from .protocol import LEVEL_RULES, StudyDesign, design_of_block

__all__ = [
    "MAX_PROTOCOL_BYTES",
    "PROTOCOL_FORMAT",
    "RESPONSES",
    "LEVEL_UNITS",
    "SHIPPED_PROTOCOLS",
    "ProtocolBlock",
    "StudyProtocol",
    "load_protocol",
    "parse_protocol",
    "shipped_protocol",
    "paper_protocol_name",
]

#: Largest protocol file read, bytes: a larger one is refused before it is parsed.
MAX_PROTOCOL_BYTES = 1_000_000
#: The version of the file format (the file's ``format`` key).
PROTOCOL_FORMAT = 1
#: Answers a block takes: one location (Study 1), one or more locations (Study 2), or a
#: point in mm on a picture of the arm area (stored beside its nearest location, which is
#: the answer's response: :mod:`vibrofocus.studies.points`), or whether the tap was felt
#: (``detection``: a threshold block, its levels set by a staircase,
#: :mod:`vibrofocus.studies.staircase`).
RESPONSES = ("location", "locations", "point", "detection")
#: Units of a block's levels: ``dB`` re the block's level rule (0 dB: the rule's own level),
#: or ``dB SL`` re the participant's detection threshold measured by an earlier threshold
#: block of the protocol.
LEVEL_UNITS = ("dB", "dB SL")
#: Protocols shipped with the package (``vibrofocus/studies/protocols/<name>.toml``).
SHIPPED_PROTOCOLS = ("paper-study1", "paper-study2")
#: Most blocks in one protocol, and most trials in one block.
MAX_BLOCKS = 64
MAX_BLOCK_TRIALS = 20_000

_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")
#: A point answer stands for one location (its nearest): a study 1 session whose design has ``point``.
_STUDY_OF_RESPONSE = {"location": 1, "locations": 2, "point": 1, "detection": 1}


def paper_protocol_name(study: int) -> str:
    """The shipped protocol of the paper's study ``study`` (1 or 2): ``paper-study<study>``."""
    return f"paper-study{int(study)}"


@dataclass(frozen=True)
class ProtocolBlock:
    """One block of a protocol: the design of one session.

    Attributes
    ----------
    index : int
        0-based position in the protocol.
    name : str
        The block's name.
    response : {"location", "locations", "point", "detection"}
        The answer a trial takes (``detection``: felt or not, a threshold block).
    methods : tuple of str
        Rendering methods (registered ones).
    locations : tuple of int or None
        Target location numbers (1-based); None where the block gives ``points_mm``.
    points_mm : tuple of (float, float) or None
        Target points in the layout frame, mm; None where the block gives ``locations``.
    levels : tuple of float
        Levels, in ``level_unit``.
    level_unit : {"dB", "dB SL"}
        ``dB`` re the level rule, or ``dB SL`` re the participant's threshold.
    level_rule : {"paper", "equal-peak"}
        The level rule 0 dB refers to (:func:`~vibrofocus.studies.protocol.level_options`).
    repetitions : int
        Times each condition appears in the main phase.
    training_trials : int
        Training trials before the main phase.
    pacing_s : float
        Wait after each answer, s.
    seed : int or None
        Seed of the trial order, the same for every participant; None: each session's own
        seed (``seed = "session"`` in the file).
    steps_db : tuple of float or None
        A threshold block's staircase steps, dB (None: the staircase's default).
    max_db : float or None
        A threshold block's highest level, dB re the level rule (None: 0 dB).
    represent_after_xrun : int
        Times a trial whose stimulus lost samples (an xrun) is presented again, 0-10
        (:func:`~vibrofocus.studies.engine.represent_after_xrun`).
    """

    index: int
    name: str
    response: str
    methods: tuple[str, ...]
    locations: tuple[int, ...] | None
    points_mm: tuple[tuple[float, float], ...] | None
    levels: tuple[float, ...]
    level_unit: str
    level_rule: str
    repetitions: int
    training_trials: int
    pacing_s: float
    seed: int | None
    steps_db: tuple[float, ...] | None = None
    max_db: float | None = None
    represent_after_xrun: int = 1

    @property
    def study(self) -> int | None:
        """The study number of the block's sessions: 1 (one location, or a point), 2 (several)."""
        return _STUDY_OF_RESPONSE.get(self.response)

    def session_seed(self, seed: int) -> int:
        """The seed a session of this block is planned with: the block's own, else ``seed``."""
        return int(seed) if self.seed is None else self.seed


@dataclass(frozen=True)
class StudyProtocol:
    """A study protocol read from a file (:func:`load_protocol`).

    Attributes
    ----------
    name : str
        The protocol's name, stored with every session planned from it.
    description : str
        Free text.
    blocks : tuple of ProtocolBlock
        The blocks, in the order they are run.
    source : str
        Where it was read from (a path, or ``<shipped paper-study1>``).
    """

    name: str
    description: str
    blocks: tuple[ProtocolBlock, ...]
    source: str
    _lines: dict[str, int] = field(default_factory=dict, repr=False, compare=False)

    def where(self, path: str) -> str:
        """``"<source>, line N, <path>"``: a field of the file, for an error message."""
        line = self._lines.get(path)
        return f"protocol {self.source}, line {line}, {path}" if line else f"protocol {self.source}, {path}"

    def check_runnable(self) -> None:
        """Refuse, in one line naming the field, what the study engine cannot run yet.

        Raises
        ------
        StudyError
            Targets given as points in mm, several levels in one block, or levels in dB SL
            without a threshold block (``response = "detection"``) before them.
        """
        for b in self.blocks:
            at = f"blocks[{b.index}]"
            if b.points_mm is not None:
                raise StudyError(f"{self.where(at + '.points_mm')}: targets given as points in mm are not run yet; "
                                 "name location numbers (locations = [...])")
            if b.level_unit == "dB SL" and self.threshold_block(b.index) is None:
                raise StudyError(f"{self.where(at + '.level_unit')}: levels in dB SL need the participant's measured "
                                 "threshold: put a threshold block (response = \"detection\") before this one, or "
                                 "use \"dB\" (re the level rule)")
            if len(b.levels) != 1:
                raise StudyError(f"{self.where(at + '.levels')}: a block plays one level for now, got "
                                 f"{len(b.levels)}; make one block per level")

    def threshold_block(self, index: int) -> int | None:
        """The threshold block (``response = "detection"``) whose threshold block ``index``'s
        levels in dB SL refer to: the last one before it; None if there is none."""
        found = [b.index for b in self.blocks[:index] if b.response == "detection"]
        return found[-1] if found else None

    def design(self, index: int, threshold_db: float | None = None) -> StudyDesign:
        """The :class:`~vibrofocus.studies.protocol.StudyDesign` of block ``index`` (runnable ones only).

        Parameters
        ----------
        index : int
            The block.
        threshold_db : float, optional
            The participant's threshold from :meth:`threshold_block`, dB re the level rule:
            required by a block in dB SL, whose level is then ``threshold_db + level``.
        """
        self.check_runnable()
        b = self.blocks[index]
        assert b.study is not None and b.locations is not None  # check_runnable
        levels = b.levels
        if b.level_unit == "dB SL":
            if threshold_db is None:
                raise StudyError(f"{self.where(f'blocks[{index}].level_unit')}: levels in dB SL need the "
                                 "participant's threshold from the threshold block "
                                 f"{self.blocks[self.threshold_block(index) or 0].name!r}, which has none yet")
            levels = tuple(float(threshold_db) + x for x in b.levels)
        try:
            return design_of_block(b.study, {"methods": b.methods, "locations": b.locations,
                                             "repetitions": b.repetitions, "training_trials": b.training_trials,
                                             "level_rule": b.level_rule, "levels": levels,
                                             "response": b.response, "steps_db": b.steps_db, "max_db": b.max_db})
        except StudyError as exc:
            raise StudyError(f"{self.where(f'blocks[{index}]')}: {exc}") from None

    def participant_threshold(self, store: Any, participant_id: str, index: int) -> float | None:
        """The participant's threshold that block ``index`` uses (dB re the level rule), from
        ``store`` (:meth:`~vibrofocus.studies.StudyStore.threshold`); None for a block in dB.

        Raises
        ------
        StudyError
            A block in dB SL whose threshold block the participant has not finished, or whose
            staircase reversed too few times for a threshold.
        """
        if self.blocks[index].level_unit != "dB SL":
            return None
        source = self.threshold_block(index)
        assert source is not None  # check_runnable
        found = store.threshold(participant_id, protocol=self.name, block=source)
        if found is None or found[1] is None:
            raise StudyError(f"{self.where(f'blocks[{index}].level_unit')}: {participant_id} has no threshold from the "
                             f"threshold block {self.blocks[source].name!r}" + (
                                 "" if found is None else " (its staircase reversed too few times: give that block "
                                                          "more repetitions)"))
        return found[1]

    def session_config(self, index: int, threshold_db: float | None = None) -> dict[str, Any]:
        """The session config of block ``index``: its design, the protocol's name, the block's
        index, name and pacing (stored with the session; see
        :meth:`~vibrofocus.studies.StudyStore.create_session`); for a block in dB SL also
        ``level_sl_db`` (the block's level, dB SL) and ``threshold_db`` (the threshold it
        was planned on, dB re the level rule; see :meth:`design`)."""
        b = self.blocks[index]
        config = {**self.design(index, threshold_db).to_dict(), "protocol": self.name, "block": b.index,
                  "block_name": b.name, "level_unit": b.level_unit, "pace_s": b.pacing_s,
                  "represent_after_xrun": b.represent_after_xrun}
        if b.level_unit == "dB SL":
            config.update(level_sl_db=b.levels[0], threshold_db=float(threshold_db))  # type: ignore[arg-type]
        return config

    def level_where(self, index: int) -> str:
        """:meth:`where` of block ``index``'s levels."""
        return self.where(f"blocks[{index}].levels")


# ---------------------------------------------------------------------- the file's models
def _models() -> tuple[type, type]:
    """The pydantic models of the file (built on first use: pydantic loads only when a file is read)."""
    from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

    class Block(BaseModel):
        model_config = ConfigDict(extra="forbid", strict=True)
        name: str = Field(default="", max_length=64)
        response: Literal["location", "locations", "point", "detection"]
        methods: list[str] = Field(min_length=1, max_length=64)
        locations: list[int] | None = Field(default=None, min_length=1, max_length=1000)
        points_mm: list[tuple[float, float]] | None = Field(default=None, min_length=1, max_length=1000)
        levels: list[float] = Field(default=[0.0], min_length=1, max_length=64)
        level_unit: Literal["dB", "dB SL"] = "dB"
        level_rule: Literal["paper", "equal-peak"] = "paper"
        repetitions: int = Field(ge=1, le=1000)
        training_trials: int = Field(default=0, ge=0, le=1000)
        pacing_s: float = Field(default=0.0, ge=0.0, le=60.0)
        seed: Any = "session"
        steps_db: list[float] | None = Field(default=None, min_length=1, max_length=16)
        max_db: float | None = Field(default=None, ge=-120.0, le=120.0)
        represent_after_xrun: int = Field(default=1, ge=0, le=10)

        @field_validator("methods")
        @classmethod
        def _methods(cls, value: list[str]) -> list[str]:
            from ..rendering.registry import available_methods

            known = available_methods()
            for m in value:
                if m not in known:
                    raise ValueError(f"unknown method {shorten(m)}; known: {', '.join(known)}")
            if len(set(value)) != len(value):
                raise ValueError(f"a method is named twice: {value}")
            return value

        @field_validator("locations")
        @classmethod
        def _locations(cls, value: list[int] | None) -> list[int] | None:
            if value is not None:
                if any(x < 1 for x in value):
                    raise ValueError(f"location numbers start at 1, got {min(value)}")
                if len(set(value)) != len(value):
                    raise ValueError(f"a location is named twice: {value}")
            return value

        @field_validator("points_mm")
        @classmethod
        def _points(cls, value: Any) -> Any:
            if value is not None and not all(math.isfinite(c) for p in value for c in p):
                raise ValueError("points must be finite numbers, mm")
            return value

        @field_validator("levels")
        @classmethod
        def _levels(cls, value: list[float]) -> list[float]:
            if not all(math.isfinite(x) and -120.0 <= x <= 120.0 for x in value):
                raise ValueError(f"levels must be finite numbers within +-120 dB, got {value}")
            if len(set(value)) != len(value):
                raise ValueError(f"a level is named twice: {value}")
            return value

        @field_validator("seed")
        @classmethod
        def _seed(cls, value: Any) -> Any:
            if value == "session" and isinstance(value, str):
                return value
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 2**63:
                raise ValueError(f"seed must be \"session\" or an integer in [0, 2**63), got {shorten(value)}")
            return value

        @model_validator(mode="after")
        def _targets(self) -> "Block":
            if (self.locations is None) == (self.points_mm is None):
                raise ValueError("give the targets as locations = [...] or as points_mm = [[x, y], ...], "
                                 "exactly one of them")
            if self.response != "detection" and (self.steps_db is not None or self.max_db is not None):
                raise ValueError("steps_db and max_db belong to a threshold block (response = \"detection\")")
            if self.response == "detection":
                from .staircase import Staircase

                if self.level_unit != "dB" or len(self.levels) != 1:
                    raise ValueError("a threshold block starts its staircase at one level in dB re the level rule: "
                                     "levels = [start], level_unit = \"dB\"")
                try:
                    Staircase(start_db=self.levels[0], **({} if self.steps_db is None else
                                                          {"steps_db": tuple(self.steps_db)}),
                              **({} if self.max_db is None else {"max_db": self.max_db}))
                except StudyError as exc:
                    raise ValueError(str(exc)) from None
            n = len(self.methods) * len(self.locations or self.points_mm or ()) * len(self.levels)
            if n * self.repetitions + self.training_trials > MAX_BLOCK_TRIALS:
                raise ValueError(f"the block has {n * self.repetitions + self.training_trials} trials, more than "
                                 f"{MAX_BLOCK_TRIALS}")
            return self

    class Protocol(BaseModel):
        model_config = ConfigDict(extra="forbid", strict=True)
        format: Literal[1]
        name: str = Field(max_length=64)
        description: str = Field(default="", max_length=2000)
        blocks: list[Block] = Field(min_length=1, max_length=MAX_BLOCKS)

        @field_validator("name")
        @classmethod
        def _name(cls, value: str) -> str:
            if not _NAME.fullmatch(value):
                raise ValueError(f"name must be 1-64 letters, digits, _ . - (starting with a letter or digit), got "
                                 f"{shorten(value)}")
            return value

    return Block, Protocol


@lru_cache(maxsize=1)
def _cached_models() -> tuple[type, type]:
    return _models()


# ---------------------------------------------------------------------- reading
def _path_text(loc: Sequence[Any]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


def _key_lines(text: str) -> dict[str, int]:
    """Line numbers (1-based) of the file's keys, by TOML path: ``name``, ``blocks[0]``
    (the block's header), ``blocks[0].methods``. A simple scan of ``key =`` lines under
    ``[[blocks]]`` headers (other layouts of the same data get no line, only the path)."""
    lines: dict[str, int] = {}
    prefix = ""
    n_blocks = -1
    key = re.compile(r"\s*([A-Za-z0-9_-]+|\"[^\"]*\")\s*=")
    for no, raw in enumerate(text.splitlines(), start=1):
        stripped = raw.strip()
        if stripped.startswith("[[") and stripped[2:].split("]]")[0].strip() == "blocks":
            n_blocks += 1
            prefix = f"blocks[{n_blocks}]"
            lines.setdefault(prefix, no)
            continue
        if stripped.startswith("["):
            prefix = "?"
            continue
        m = key.match(raw)
        if m and prefix != "?":
            name = m.group(1).strip('"')
            lines.setdefault(f"{prefix}.{name}" if prefix else name, no)
    return lines


def _line_of(lines: dict[str, int], path: str) -> int | None:
    """The line of ``path`` or of its nearest enclosing key (``blocks[0].methods[1]`` ->
    ``blocks[0].methods``; a missing ``blocks[0].repetitions`` -> ``blocks[0]``)."""
    while path:
        if path in lines:
            return lines[path]
        cut = max(path.rfind("."), path.rfind("["))
        if cut <= 0:
            return None
        path = path[:cut]
    return None


def parse_protocol(text: str, source: str = "<text>") -> StudyProtocol:
    """Read a protocol from its TOML text.

    Parameters
    ----------
    text : str
        The file's text.
    source : str
        What to call it in an error message (its path).

    Returns
    -------
    StudyProtocol

    Raises
    ------
    StudyError
        One line naming the source, the line and the field: not TOML, a missing field, an
        unknown field or method, a wrong type, a value out of range.
    """
    import pydantic

    if len(text) > MAX_PROTOCOL_BYTES:
        raise StudyError(f"protocol {source}: {len(text)} characters, more than the {MAX_PROTOCOL_BYTES} allowed")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"protocol {source}: not valid TOML: {exc}") from None
    lines = _key_lines(text)
    _, model = _cached_models()
    try:
        parsed = model.model_validate(data)
    except pydantic.ValidationError as exc:
        err = exc.errors(include_url=False)[0]
        loc = list(err["loc"])
        path = _path_text(loc)
        msg = str(err["msg"]).removeprefix("Value error, ")
        if err["type"] == "missing":
            msg = "missing; every block needs it" if len(loc) > 2 else "missing"
        elif err["type"] == "extra_forbidden":
            msg = "unknown field"
        elif err["type"] == "literal_error":
            msg = f"{msg}, got {shorten(err.get('input'))}"
        elif "type" in err["type"] or err["type"].endswith("_parsing"):
            msg = f"{msg}, got {shorten(err.get('input'))} ({type(err.get('input')).__name__})"
        line = _line_of(lines, path)
        at = f", line {line}" if line else ""
        more = f" (and {exc.error_count() - 1} more problem(s))" if exc.error_count() > 1 else ""
        raise StudyError(f"protocol {source}{at}, {path or 'the file'}: {msg}{more}") from None
    blocks = tuple(
        ProtocolBlock(
            index=i, name=b.name or f"block{i + 1}", response=b.response, methods=tuple(b.methods),
            locations=None if b.locations is None else tuple(b.locations),
            points_mm=None if b.points_mm is None else tuple((float(x), float(y)) for x, y in b.points_mm),
            levels=tuple(float(x) for x in b.levels), level_unit=b.level_unit, level_rule=b.level_rule,
            repetitions=int(b.repetitions), training_trials=int(b.training_trials), pacing_s=float(b.pacing_s),
            seed=None if b.seed == "session" else int(b.seed),
            steps_db=None if b.steps_db is None else tuple(float(x) for x in b.steps_db),
            max_db=None if b.max_db is None else float(b.max_db),
            represent_after_xrun=int(b.represent_after_xrun),
        )
        for i, b in enumerate(parsed.blocks)
    )
    assert all(b.level_rule in LEVEL_RULES for b in blocks)
    return StudyProtocol(parsed.name, parsed.description, blocks, source, lines)


def load_protocol(path: str | Path) -> StudyProtocol:
    """Read a protocol file (TOML, docs/protocols.md).

    Parameters
    ----------
    path : str or Path
        The file; at most :data:`MAX_PROTOCOL_BYTES` bytes (a larger one is refused before
        it is read), UTF-8.

    Returns
    -------
    StudyProtocol

    Raises
    ------
    StudyError
        No such file, not a regular file, too large, not UTF-8, or any problem
        :func:`parse_protocol` finds; one line naming the file and the field.
    """
    p = Path(path)
    try:
        if not p.is_file():
            raise StudyError(f"protocol {p}: no such file" if not p.exists() else f"protocol {p}: not a regular file")
        size = p.stat().st_size
        if size > MAX_PROTOCOL_BYTES:
            raise StudyError(f"protocol {p}: {size} bytes, more than the {MAX_PROTOCOL_BYTES} allowed")
        with open(p, "rb") as fh:
            raw = fh.read(MAX_PROTOCOL_BYTES + 1)  # a file that grew since: still capped
    except OSError as exc:
        raise StudyError(f"protocol {p}: cannot read it ({exc.strerror or exc})") from None
    if len(raw) > MAX_PROTOCOL_BYTES:
        raise StudyError(f"protocol {p}: more than the {MAX_PROTOCOL_BYTES} bytes allowed")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise StudyError(f"protocol {p}: not UTF-8 text (byte {exc.start})") from None
    return parse_protocol(text, str(p))


@lru_cache(maxsize=None)
def shipped_protocol(name: str) -> StudyProtocol:
    """A protocol shipped with the package (:data:`SHIPPED_PROTOCOLS`), read once.

    Parameters
    ----------
    name : str
        ``paper-study1`` or ``paper-study2``.

    Returns
    -------
    StudyProtocol
    """
    if name not in SHIPPED_PROTOCOLS:
        raise StudyError(f"no shipped protocol {shorten(name)}; shipped: {', '.join(SHIPPED_PROTOCOLS)}")
    text = resources.files("vibrofocus.studies").joinpath("protocols", f"{name}.toml").read_text(encoding="utf-8")
    return parse_protocol(text, f"<shipped {name}>")
