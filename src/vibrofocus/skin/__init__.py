"""The simulated forearm (SPEC §3): a physically based rig that runs without hardware."""

from .forearm import SimulatedForearm, drive_sensitivity
from .geometry import ForearmGeometry
from .parameters import ForearmParameters
from .propagation import exciter_response, surface_green, wavenumber

__all__ = [
    "SimulatedForearm",
    "ForearmParameters",
    "ForearmGeometry",
    "drive_sensitivity",
    "wavenumber",
    "surface_green",
    "exciter_response",
]
