"""Calibration: measure the skin's transfer matrix with sweeps, judge its quality, and
keep it in one self-describing netCDF4/HDF5 file (docs/method.md, calibration)."""

from .accuracy import transfer_error
from .calibrate import DEFAULT_METHOD, SCHEMA_VERSION, Calibration, CalibrationPlan, calibrate, plan_calibration
from .estimate import MimoEstimate, mimo_h1
from .excitation import METHODS, SweepSettings, default_settings, hadamard_codes, make_excitation
from .figures import plot_calibration
from .fitmodel import FIT_LAWS, FittedSkin, fit_model
from .plan import subset_points
from .files import (calibration_from_record, calibration_record, export_sofa, import_sofa, load_calibration,
                    save_calibration)
from .quality import TRUSTED_COHERENCE, QualityIssue, QualityReport, QualityThresholds, assess_quality, detect_clipping

__all__ = [
    "TRUSTED_COHERENCE",
    "calibrate",
    "plan_calibration",
    "subset_points",
    "CalibrationPlan",
    "DEFAULT_METHOD",
    "Calibration",
    "save_calibration",
    "load_calibration",
    "calibration_record",
    "calibration_from_record",
    "export_sofa",
    "import_sofa",
    "plot_calibration",
    "SCHEMA_VERSION",
    "METHODS",
    "SweepSettings",
    "default_settings",
    "make_excitation",
    "hadamard_codes",
    "mimo_h1",
    "MimoEstimate",
    "QualityIssue",
    "QualityReport",
    "QualityThresholds",
    "assess_quality",
    "detect_clipping",
    "transfer_error",
    "fit_model",
    "FittedSkin",
    "FIT_LAWS",
]
