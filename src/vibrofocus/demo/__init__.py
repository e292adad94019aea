"""The ``vibrofocus demo``: every rendering method at every location on the simulated
forearm, with focus metrics and figures."""

from .run import DemoResult, calibrated_transfer, model_transfer, record_clean, run_demo, summarize

__all__ = ["DemoResult", "calibrated_transfer", "model_transfer", "record_clean", "run_demo", "summarize"]
