"""Pydantic models of every request body and of the main responses of the web API.

The models refuse what is malformed on its own (a location the participant page cannot
show, a negative reaction time, an unknown method); the rules that need the database
(is this the current trial? is the location one of the session's? does the study allow
several locations?) are the store's (:meth:`StudyStore.record_answer`).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import Path
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, field_validator, model_validator
from pydantic_core import PydanticCustomError

from ..studies.protocol import REFERENCE_LOCATIONS

__all__ = [
    "N_LOCATIONS",
    "AnswerIn",
    "AnswerReceipt",
    "ParticipantIn",
    "CalibrationIn",
    "SessionIn",
    "ProtocolIn",
    "AnalysisIn",
    "MAX_ID",
    "SessionId",
    "CalibrationId",
]

#: Locations the participant page can show, and so name: those of the reference setup
#: (its grid is web/templates/participant.html's). Which of them a session takes is its
#: design's, checked by the store.
N_LOCATIONS = len(REFERENCE_LOCATIONS)

#: Largest id accepted anywhere (SQLite integers are 64-bit; larger numbers are refused with 422, not an error).
MAX_ID = 2**53

#: Path parameters: a session or calibration id.
SessionId = Annotated[int, Path(ge=1, le=MAX_ID, description="session id")]
CalibrationId = Annotated[int, Path(ge=1, le=MAX_ID, description="calibration id")]

Location = Annotated[int, Field(ge=1, le=N_LOCATIONS, strict=True)]
# Ids end up in file names and URLs; keep them to a safe, readable alphabet.
ParticipantId = Annotated[str, Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")]


def _study_number(value: Any) -> Any:
    # A Literal takes True and 1.0 for 1 even in strict mode (they compare equal): only an int is a study.
    if type(value) is not int:
        raise PydanticCustomError("literal_error", "Input should be {expected}", {"expected": "1 or 2"})
    return value


#: The study: 1 or 2, as a JSON integer (not ``true``, ``1.0`` or ``"1"``).
Study = Annotated[Literal[1, 2], BeforeValidator(_study_number)]


class _Strict(BaseModel):
    # Unknown fields are refused: a typo in a client must not pass silently. Strict types:
    # "true", 1 or "yes" for a boolean, true or "5" for a number are refused, not
    # converted: such a mistake would change what a participant or session is.
    model_config = ConfigDict(extra="forbid", strict=True)


class AnswerIn(_Strict):
    """One answer of the participant page.

    ``answer_id`` is made by the page when the participant answers and sent again
    unchanged on every retry, so that the server can tell a re-send from a new answer.
    An answer names locations (``response``) or, in a point session, a point on the
    picture of the arm area (``point_mm``: ``[x, y]`` in the layout frame, mm); whether
    the point lies in the picture is the store's rule (422 when it does not). In a
    threshold session it says whether the tap was felt (``felt``, stored as 1 or 0).
    """

    session_id: int = Field(ge=1, le=MAX_ID, strict=True)
    trial_index: int = Field(ge=0, le=MAX_ID, strict=True)
    response: list[Location] | None = Field(default=None, min_length=1, max_length=N_LOCATIONS)
    point_mm: list[Annotated[float, Field(allow_inf_nan=False, ge=-10_000.0, le=10_000.0)]] | None = (
        Field(default=None, min_length=2, max_length=2))
    #: A threshold block's answer (docs/protocols.md, "Threshold blocks"): whether the tap was felt.
    felt: bool | None = None
    rt_s: float = Field(ge=0.0, le=3600.0, allow_inf_nan=False)
    answer_id: str = Field(min_length=8, max_length=64, pattern=r"^[A-Za-z0-9_-]+$")

    @field_validator("response")
    @classmethod
    def _distinct(cls, value: list[int] | None) -> list[int] | None:
        if value is None:
            return None
        if len(set(value)) != len(value):
            raise ValueError(f"response names a location twice: {value}")
        return sorted(value)

    @model_validator(mode="after")
    def _one_answer(self) -> "AnswerIn":
        given = [self.response is not None, self.point_mm is not None, self.felt is not None]
        if sum(given) != 1:
            raise ValueError("an answer gives one of response (locations), point_mm ([x, y] in mm) or felt "
                             "(true or false), not " + {0: "neither", 2: "both"}.get(sum(given), "all three"))
        return self


class RestartIn(_Strict):
    """A participant page asks for a trial again: it did not see that trial's stimulus onset."""

    session_id: int = Field(ge=1, le=MAX_ID, strict=True)
    trial_index: int = Field(ge=0, le=MAX_ID, strict=True)


class AnswerReceipt(BaseModel):
    """What the server sends back once an answer is committed to the database."""

    session_id: int
    trial_index: int
    answer_id: str
    response: list[int]
    point_mm: list[float] | None = None
    committed: bool = True
    duplicate: bool = False
    next_trial_index: int | None


class ParticipantIn(_Strict):
    """Create a participant."""

    participant_id: ParticipantId
    simulated: bool = False


class CalibrationIn(_Strict):
    """Start a calibration of a participant on a rig."""

    participant_id: ParticipantId
    rig: str = Field(default="simulated", min_length=1, max_length=32)
    seed: int | None = Field(default=None, ge=0, le=2**32 - 1)
    #: Measure only this many points and predict the rest (``calibrate(measure=...)``);
    #: None measures every point.
    points: int | None = Field(default=None, ge=2, le=1000)


class SessionIn(_Strict):
    """Plan a study session (the full trial list is written to the database)."""

    participant_id: ParticipantId
    # Required unless a protocol gives it (its block's study).
    study: Study | None = None
    seed: int | None = Field(default=None, ge=0, le=2**32 - 1)
    calibration_id: int | None = Field(default=None, ge=1, le=MAX_ID)
    rig: str = Field(default="simulated", min_length=1, max_length=32)
    rig_seed: int | None = Field(default=None, ge=0, le=2**32 - 1)
    # Shorter designs for pilots and demonstrations; the defaults are docs/file-formats.md, trials file's.
    repetitions: int | None = Field(default=None, ge=1, le=10)
    n_training: int | None = Field(default=None, ge=0, le=30)
    # The experimenter has read the calibration's error verdicts and uses it anyway.
    allow_calibration_errors: bool = False
    # The level rule of the stimuli (vibrofocus.studies.protocol.level_options); None: the paper's.
    levels: Literal["paper", "equal-peak"] | None = None
    # The participant answers a point on a picture of the arm area (study 1 only): the
    # calibration's layout is the picture (docs/web.md, point answers).
    point: bool = False
    # A study protocol (docs/protocols.md): a shipped one or one uploaded (/api/protocols) by
    # its name, and its block (None: the participant's first unfinished one). The protocol
    # then sets the study and the design: study, repetitions, n_training, levels and point
    # are not given with it.
    protocol: str | None = Field(default=None, min_length=1, max_length=64, pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
    block: int | None = Field(default=None, ge=0, le=63)


class ProtocolIn(_Strict):
    """Upload a study protocol: the text of its TOML file (docs/protocols.md)."""

    text: str = Field(min_length=1, max_length=60_000)
    #: The file's name, for the error messages.
    filename: str = Field(default="upload.toml", min_length=1, max_length=128, pattern=r"^[^/\\\x00-\x1f]+$")


class AnalysisIn(_Strict):
    """Run the analysis on the current export."""

    study: Study | None = None
    # One kind of participant per analysis (vibrofocus.analysis.trials.KINDS; the CLI's default, --simulated,
    # --rehearsals): people on hardware, simulated participants, or people's rehearsals on the simulated rig.
    kind: Literal["people", "simulated", "rehearsals"] = "people"
