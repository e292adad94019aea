"""Rendering methods (docs/method.md, "Rendering methods"): funneling, inverse filter, combination, time reversal,
the contrast designs (acoustic contrast control, constrained) and their bound, the
wrap-around check, focus metrics, the methods as objects with their registry, the
:class:`TransferMatrix` they design through, and the high-level :func:`render`."""

from .causality import CausalityWarning, WraparoundCheck, check_wraparound, wraparound_fraction
from .combination import combination_target
from .contrast import (
    ContrastBound,
    constrained_drives,
    contrast_bound,
    contrast_drives,
    energy_contrast_db,
    generalized_eigh_max,
)
from .funneling import funneling_gains, funneling_weights
from .inverse import DesignReport, DriveScaledWarning, InverseOperator, inverse_filter, predict_response
from .metrics import focus_metrics
from .design import Design
from .method import Method, Problem, Solution
from .methods import Combination, Constrained, Contrast, Funneling, Inverse, Minimax, TimeReversal
from .minimax import MinimaxFrontier, MinimaxReport, coherence_radius, minimax_filter, minimax_frontier
from .registry import ENTRY_POINT_GROUP, available_methods, make_method, method_class, register_method
from .render import render, render_fitted
from .taper import band_taper
from .time_reversal import time_reversal_drives
from .timing import ResponseTiming, response_timing
from .transfer import TransferMatrix, calibration_window

__all__ = [
    "band_taper",
    "funneling_gains",
    "funneling_weights",
    "inverse_filter",
    "InverseOperator",
    "DesignReport",
    "DriveScaledWarning",
    "predict_response",
    "combination_target",
    "contrast_drives",
    "constrained_drives",
    "contrast_bound",
    "ContrastBound",
    "generalized_eigh_max",
    "energy_contrast_db",
    "time_reversal_drives",
    "wraparound_fraction",
    "check_wraparound",
    "WraparoundCheck",
    "CausalityWarning",
    "focus_metrics",
    "render",
    "render_fitted",
    "response_timing",
    "ResponseTiming",
    "calibration_window",
    "Design",
    "TransferMatrix",
    "Method",
    "Problem",
    "Solution",
    "Funneling",
    "Inverse",
    "Combination",
    "TimeReversal",
    "Contrast",
    "Constrained",
    "Minimax",
    "minimax_filter",
    "MinimaxReport",
    "minimax_frontier",
    "coherence_radius",
    "MinimaxFrontier",
    "register_method",
    "method_class",
    "make_method",
    "available_methods",
    "ENTRY_POINT_GROUP",
]

from .._deprecated import module_getattr  # noqa: E402

__getattr__ = module_getattr(__name__, {"Rendering": ("vibrofocus.rendering.design", "Design",
                                                      "vibrofocus.rendering.Design")})
