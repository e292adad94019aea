"""The simulated forearm: a physically based rig that runs without hardware.

The skin's waves follow a causal viscoelastic law fitted to published forearm
measurements; see ``docs/skin-model.md``.
"""

from .fit import WaveLawFit, fit_wave_law, load_forearm_data
from .forearm import SimulatedForearm, drive_sensitivity
from .geometry import ForearmGeometry
from .parameters import NOMINAL_LAW, ForearmParameters, attenuation_range_laws
from .propagation import exciter_response, surface_green, wavenumber
from .viscoelastic import ViscoelasticLaw

__all__ = [
    "SimulatedForearm",
    "ForearmParameters",
    "ForearmGeometry",
    "drive_sensitivity",
    "wavenumber",
    "surface_green",
    "exciter_response",
    "ViscoelasticLaw",
    "NOMINAL_LAW",
    "attenuation_range_laws",
    "fit_wave_law",
    "load_forearm_data",
    "WaveLawFit",
]
