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


LSL_HELP = ("Send a JSON marker per cue, stimulus onset and answer to the Lab Streaming Layer outlet "
            "'vibrofocus-markers' (type Markers), stamped with each event's own time on LSL's clock; needs "
            "pip install 'vibrofocus[lsl]'.")


def lsl_option() -> bool:
    """The ``--lsl`` option of the commands that run trials (``study run``, ``simulate-study``, ``serve``)."""
    return typer.Option(False, "--lsl", help=LSL_HELP)


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
