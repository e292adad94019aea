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
from .demo import DemoOutcome, demo_methods, demo_moving_focus, demo_paper_figures
from .design import DesignOutcome, design_study
from .layout import LayoutOutcome, design_layout
from .live_taps import serve_live_taps
from .power import PowerOutcome, study_power
from .progress import Progress, QuietProgress, WorkflowCancelled
from .render import TapOutcome, render_tap
from .session import first_unfinished_block, plan_session, run_session, run_study_at_terminal
from .simulate import SimulationOutcome, simulate_study

__all__ = [
    "CalibrationOutcome",
    "DemoOutcome",
    "DesignOutcome",
    "LayoutOutcome",
    "PowerOutcome",
    "Progress",
    "QuietProgress",
    "SimulationOutcome",
    "TapOutcome",
    "WorkflowCancelled",
    "calibrate_participant",
    "check_calibration_out",
    "demo_methods",
    "demo_moving_focus",
    "demo_paper_figures",
    "design_layout",
    "design_study",
    "first_unfinished_block",
    "plan_session",
    "render_tap",
    "run_session",
    "run_study_at_terminal",
    "serve_live_taps",
    "simulate_study",
    "study_power",
]
