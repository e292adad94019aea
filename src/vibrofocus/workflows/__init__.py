"""The lab's workflows, one function each, under every front-end.

The command line, the web app and the PsychoPy component parse their input, call one
workflow and show what it reports; none of them wires a workflow of its own. A workflow
reports through one :class:`Progress` interface (steps, lines to show, a cancel check)
that each front-end renders in its own form: a bar and printed lines, a live card.

Layering: workflows sit above calibration, studies, rigs and io, and below cli, web,
demo and psychopy (tests/test_layering.py).
"""

from __future__ import annotations

from .calibrate import CalibrationOutcome, calibrate_participant, check_calibration_out
from .progress import Progress, QuietProgress, WorkflowCancelled

__all__ = [
    "CalibrationOutcome",
    "Progress",
    "QuietProgress",
    "WorkflowCancelled",
    "calibrate_participant",
    "check_calibration_out",
]
