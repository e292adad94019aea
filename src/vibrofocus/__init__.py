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
    "SimulatedForearm": ".rigs",
    "ricker": ".signals",
    "linear_sweep": ".signals",
    "exponential_sweep": ".signals",
    "minimax_frontier": ".rendering",
    "focus_metrics": ".rendering",
    "render": ".rendering",
    "Method": ".rendering",
    "Funneling": ".rendering",
    "Inverse": ".rendering",
    "Combination": ".rendering",
    "TimeReversal": ".rendering",
    "Contrast": ".rendering",
    "Constrained": ".rendering",
    "Minimax": ".rendering",
    "contrast_bound": ".rendering",
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
        Combination,
        Constrained,
        Contrast,
        Design,
        Funneling,
        Inverse,
        Method,
        Minimax,
        TimeReversal,
        TransferMatrix,
        available_methods,
        contrast_bound,
        focus_metrics,
        minimax_frontier,
        register_method,
        render,
    )
    from .rigs import Rig, SafetyLimits
    from .signals import exponential_sweep, linear_sweep, ricker
    from .rigs import SimulatedForearm


#: Subpackages reachable as attributes without importing them first (``vf.rigs.make_rig``).
_SUBPACKAGES = frozenset({"analysis", "calibration", "defaults", "demo", "errors", "layout", "participant_models",
                          "rendering", "rigs", "signals", "skin", "studies"})


#: Former top-level names (DEVELOPING.md, "Names"): one way to design a tap is
#: ``render(method, ...)`` with a method object; the functions and the operator the methods
#: are built from stay in :mod:`vibrofocus.rendering` as building blocks.
_FORMER = {
    "simulation": ("vibrofocus", "participant_models", "vibrofocus.participant_models"),
    "Rendering": ("vibrofocus.rendering.design", "Design", "vibrofocus.Design"),
    "inverse_filter": ("vibrofocus.rendering", "inverse_filter",
                       "vibrofocus.render(vibrofocus.Inverse(...), H, fs, layout, location)"),
    "InverseOperator": ("vibrofocus.rendering", "InverseOperator",
                        "vibrofocus.render(vibrofocus.Inverse(...), H, fs, layout, location) or "
                        "vibrofocus.rendering.InverseOperator"),
    "funneling_gains": ("vibrofocus.rendering", "funneling_gains",
                        "vibrofocus.render(vibrofocus.Funneling(...), H, fs, layout, location)"),
    "minimax_filter": ("vibrofocus.rendering", "minimax_filter",
                       "vibrofocus.render(vibrofocus.Minimax(...), H, fs, layout, location)"),
}


def _installed_version() -> str:
    # Read on first use: importlib.metadata costs a third of a second, which the
    # terminal stop (vibrofocus._stop_client) must not pay.
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("vibrofocus")
    except PackageNotFoundError:  # running from a source tree without installation
        return "0.0.0+unknown"


def _lazy(name: str):
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


def __getattr__(name: str):
    if name in _FORMER:  # not cached: each use warns
        from ._deprecated import warn_deprecated

        new_module, new_name, advice = _FORMER[name]
        warn_deprecated(f"vibrofocus.{name}", advice)
        return getattr(import_module(new_module), new_name)
    return _lazy(name)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


__all__ = [
    "__version__",
    "ArrayLayout",
    "Rig",
    "SafetyLimits",
    "SimulatedForearm",
    "ricker",
    "render",
    "Method",
    "Funneling",
    "Inverse",
    "Combination",
    "TimeReversal",
    "Contrast",
    "Constrained",
    "Minimax",
    "Design",
    "minimax_frontier",
    "focus_metrics",
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
