"""vibrofocus: focused vibrotactile stimuli on wearable, sparse actuator arrays.

Calibrate how vibration travels through skin, render a sharp tap at a virtual point
between actuators (funneling, inverse filter, their combination, time reversal), run
localization studies and analyse them. Runs on real rigs and, by default, on a
physically based simulated forearm.
"""

from importlib.metadata import PackageNotFoundError, version as _version

try:
    __version__ = _version("vibrofocus")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"

from .errors import (
    CalibrationFileError,
    CausalityError,
    DriveLimitError,
    SafetyError,
    StudyError,
    ValidationError,
    VibrofocusError,
)
from .layout import ArrayLayout
from .rigs import Rig, SafetyLimits
from .signals import exponential_sweep, linear_sweep, ricker
from .rendering import InverseOperator, Rendering, focus_metrics, funneling_gains, inverse_filter, render
from .skin import SimulatedForearm
from .calibration import Calibration, calibrate, load_calibration, save_calibration

__all__ = [
    "__version__",
    "ArrayLayout",
    "Rig",
    "SafetyLimits",
    "SimulatedForearm",
    "ricker",
    "funneling_gains",
    "inverse_filter",
    "InverseOperator",
    "focus_metrics",
    "render",
    "Rendering",
    "calibrate",
    "Calibration",
    "load_calibration",
    "save_calibration",
    "linear_sweep",
    "exponential_sweep",
    "VibrofocusError",
    "ValidationError",
    "SafetyError",
    "DriveLimitError",
    "CausalityError",
    "CalibrationFileError",
    "StudyError",
]
