"""Options several commands share: their help texts, ranges and checks.

Only typer at module level (see :mod:`vibrofocus.cli.main`). Every numeric option of a
command has its range in ``--help`` (docs/method.md, "Bad input, full disks and
interrupts"); the ranges that size memory or run time live here, so the help and the
checks cannot disagree.
"""

from __future__ import annotations

from pathlib import Path

import typer

#: Largest ``--seed`` of every command: seeds are stored as 64-bit integers.
SEED_MAX = 2**63 - 1
#: ``--n-samples`` of render: 64 samples (a few ms) up to 2**21 (3.5 min at 10 kHz).
N_SAMPLES_RANGE = (64, 2**21)
#: ``--repeats`` of calibrate: a 2.5 s sweep per take, so 64 repeats are about 3 min of sweeps per point.
REPEATS_MAX = 64
#: Shortest ``--sweep-s`` of calibrate, s (the longest is the rig's ``max_duration_s``).
SWEEP_S_MIN = 0.1
#: ``--amplitude-v`` of calibrate, V: below 1 mV no skin motion is measurable (the
#: rig's own peak limit is the upper bound, checked by the safety layer).
AMPLITUDE_V_MIN = 1e-3
#: ``--limit-v`` of render, V (the upper bound is the rig's limit stored in the calibration).
LIMIT_V_MIN = 1e-3

RIG_CONFIG_HELP = "Hardware settings file for audio/nidaq (refused with the simulated rig, which takes none)."
FORCE_HELP = "Replace an existing output file of another kind (e.g. a calibration under a .csv name)."


LSL_HELP = ("Send a marker per cue, stimulus onset and answer to the Lab Streaming Layer outlet "
            "'vibrofocus-markers' (type Markers): a short event code (cue, tap/METHOD/PHASE/studyN, answer), "
            "with each marker's JSON detail on 'vibrofocus-markers-detail', stamped with each event's own time on "
            "LSL's clock (an onset at the device's output); needs pip install 'vibrofocus[lsl]'.")
LSL_SOURCE_ID_HELP = ("Source id of the LSL streams (letters, digits, _.:+-). Default: derived from the study "
                      "database and this machine, the same in every run, so a recorder (LabRecorder) recovers the "
                      "stream of a killed run when it is resumed.")
LSL_WAIT_HELP = ("Wait up to this long, s, for a recorder to connect to the LSL stream before the first trial "
                 "(0: do not wait); a recorder recovering a killed run's stream then misses no marker.")
#: Longest ``--lsl-wait``, s.
LSL_WAIT_MAX_S = 600.0


def lsl_option() -> bool:
    """The ``--lsl`` option of the commands that run trials (``study run``, ``simulate-study``, ``serve``)."""
    return typer.Option(False, "--lsl", help=LSL_HELP)


def lsl_source_id_option() -> str | None:
    """The ``--lsl-source-id`` option of the commands that take ``--lsl``."""
    return typer.Option(None, "--lsl-source-id", show_default=False, help=LSL_SOURCE_ID_HELP)


def lsl_wait_option() -> float:
    """The ``--lsl-wait`` option of the commands that take ``--lsl``."""
    return typer.Option(0.0, "--lsl-wait", min=0.0, max=LSL_WAIT_MAX_S, help=LSL_WAIT_HELP)


def lsl_source(lsl: bool, source_id: str | None, db: Path, study: int | None = None) -> str | None:
    """The source id of a command's marker streams: ``--lsl-source-id`` (checked) or the database's.

    Parameters
    ----------
    lsl : bool
        Whether ``--lsl`` was given (``--lsl-source-id`` alone is refused).
    source_id : str or None
        ``--lsl-source-id``.
    db : Path
        The study database.
    study : int, optional
        The study the command runs, when it runs one.
    """
    from ..errors import ValidationError
    from ..io.lsl import check_source_id, stable_source_id

    if not lsl:
        if source_id is not None:
            raise ValidationError("--lsl-source-id needs --lsl")
        return None
    return check_source_id(source_id) if source_id is not None else stable_source_id(db, study)


def force_option() -> bool:
    """The ``--force`` option of the commands that write files."""
    return typer.Option(False, "--force", help=FORCE_HELP)


def check_rig_options(rig: str, rig_config: Path | None) -> None:
    """Refuse ``--rig-config`` with the simulated rig instead of ignoring it; no output may replace the config.

    Parameters
    ----------
    rig : str
        ``--rig``.
    rig_config : Path or None
        ``--rig-config``.

    Raises
    ------
    ValidationError
    """
    if rig_config is not None:
        from .._atomic import protect

        protect(rig_config, "rig config")
    if rig == "simulated" and rig_config is not None:
        from ..errors import ValidationError

        raise ValidationError(
            f"--rig-config {rig_config}: the simulated rig takes no settings file; give --rig audio or --rig nidaq "
            "with it, or leave it out"
        )


def comma_list(text: str, name: str, kind: type = int) -> tuple:
    """Values of an option written as a comma (or space) separated list, one line naming it if bad.

    Parameters
    ----------
    text : str
    name : str
        The option, for the error (``--participants``).
    kind : type
        ``int``, ``float`` or ``str``.

    Returns
    -------
    tuple
    """
    from .._validation import shorten
    from ..errors import ValidationError

    try:
        values = tuple(kind(x) for x in text.replace(",", " ").split())
    except ValueError:
        what = "integers" if kind is int else "numbers"
        raise ValidationError(f"{name} must be {what} separated by commas, got {shorten(text)}") from None
    if not values:
        raise ValidationError(f"{name} is empty")
    return values
