"""vibrofocus: focused vibrotactile stimuli on wearable, sparse actuator arrays.

Calibrate how vibration travels through skin, render a sharp tap at a virtual point
between actuators (funneling, inverse filter, their combination, time reversal), run
localization studies and analyse them. Runs on real rigs and, by default, on a
physically based simulated forearm.
"""

from importlib import import_module
from typing import TYPE_CHECKING

from .errors import (
    CalibrationFileError,
    CausalityError,
    DriveLimitError,
    InfeasibleDesignError,
    SafetyError,
    StudyError,
    ValidationError,
    VibrofocusError,
)
# The public API is loaded on first use (PEP 562), as MNE-Python does, so that
# ``vibrofocus --help`` and light scripts do not import SciPy's signal stack, the skin
# model or xarray. ``from vibrofocus import ricker`` works as usual.
_LAZY_ATTRIBUTES = {
    "ArrayLayout": ".layout",
    "Rig": ".rigs",
    "SafetyLimits": ".rigs",
    "SimulatedForearm": ".skin",
    "ricker": ".signals",
    "linear_sweep": ".signals",
    "exponential_sweep": ".signals",
    "funneling_gains": ".rendering",
    "inverse_filter": ".rendering",
    "minimax_filter": ".rendering",
    "minimax_frontier": ".rendering",
    "InverseOperator": ".rendering",
    "focus_metrics": ".rendering",
    "render": ".rendering",
    "contrast_bound": ".rendering",
    "Rendering": ".rendering",
    "Design": ".rendering",
    "TransferMatrix": ".rendering",
    "register_method": ".rendering",
    "available_methods": ".rendering",
    "calibrate": ".calibration",
    "Calibration": ".calibration",
    "load_calibration": ".calibration",
    "save_calibration": ".calibration",
}

if TYPE_CHECKING:  # static analysers and IDEs see the real imports
    from .calibration import Calibration, calibrate, load_calibration, save_calibration
    from .layout import ArrayLayout
    from .rendering import (
        Design,
        InverseOperator,
        Rendering,
        TransferMatrix,
        available_methods,
        contrast_bound,
        focus_metrics,
        funneling_gains,
        inverse_filter,
        minimax_filter,
        minimax_frontier,
        register_method,
        render,
    )
    from .rigs import Rig, SafetyLimits
    from .signals import exponential_sweep, linear_sweep, ricker
    from .skin import SimulatedForearm


#: Subpackages reachable as attributes without importing them first (``vf.rigs.make_rig``).
_SUBPACKAGES = frozenset({"analysis", "calibration", "defaults", "demo", "errors", "layout", "rendering", "rigs",
                          "signals", "simulation", "skin", "studies"})


def _installed_version() -> str:
    # Read on first use: importlib.metadata costs a third of a second, which the
    # terminal stop (vibrofocus._stop_client) must not pay.
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("vibrofocus")
    except PackageNotFoundError:  # running from a source tree without installation
        return "0.0.0+unknown"


def __getattr__(name: str):
    if name == "__version__":
        value = globals()["__version__"] = _installed_version()
        return value
    if name in _SUBPACKAGES:
        value = import_module(f".{name}", __name__)
        globals()[name] = value
        return value
    module = _LAZY_ATTRIBUTES.get(name)
    if module is None:
        raise AttributeError(f"module 'vibrofocus' has no attribute {name!r}")
    value = getattr(import_module(module, __name__), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


__all__ = [
    "__version__",
    "ArrayLayout",
    "Rig",
    "SafetyLimits",
    "SimulatedForearm",
    "ricker",
    "funneling_gains",
    "inverse_filter",
    "minimax_filter",
    "minimax_frontier",
    "InverseOperator",
    "focus_metrics",
    "render",
    "Rendering",
    "Design",
    "TransferMatrix",
    "register_method",
    "available_methods",
    "contrast_bound",
    "calibrate",
    "Calibration",
    "load_calibration",
    "save_calibration",
    "linear_sweep",
    "exponential_sweep",
    "VibrofocusError",
    "ValidationError",
    "InfeasibleDesignError",
    "SafetyError",
    "DriveLimitError",
    "CausalityError",
    "CalibrationFileError",
    "StudyError",
]
