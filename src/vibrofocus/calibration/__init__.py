"""Calibration: measure the skin's transfer matrix with sweeps, judge its quality, and
keep it in one self-describing netCDF4/HDF5 file (docs/method.md, calibration)."""

from .accuracy import transfer_error
from .calibrate import SCHEMA_VERSION, Calibration, calibrate
from .excitation import METHODS, SweepSettings, default_settings, make_excitation
from .figures import plot_calibration
from .io import load_calibration, save_calibration
from .quality import QualityIssue, QualityReport, QualityThresholds, assess_quality, detect_clipping

__all__ = [
    "calibrate",
    "Calibration",
    "save_calibration",
    "load_calibration",
    "plot_calibration",
    "SCHEMA_VERSION",
    "METHODS",
    "SweepSettings",
    "default_settings",
    "make_excitation",
    "QualityIssue",
    "QualityReport",
    "QualityThresholds",
    "assess_quality",
    "detect_clipping",
    "transfer_error",
]
