"""The ``vibrofocus demo``: every rendering method at every location on the simulated
forearm, with focus metrics and figures."""

from .frontier import FRONTIER_FIDELITIES, LocationFrontier, frontier_figure, peak_bound, peak_frontiers
from .run import DemoResult, calibrated_transfer, design_window, model_transfer, record_clean, run_demo, summarize
from .trust import calibration_trust, tap_band

__all__ = ["DemoResult", "calibrated_transfer", "design_window", "model_transfer", "record_clean", "run_demo", "summarize",
           "calibration_trust", "tap_band", "FRONTIER_FIDELITIES", "LocationFrontier", "frontier_figure",
           "peak_bound", "peak_frontiers"]
