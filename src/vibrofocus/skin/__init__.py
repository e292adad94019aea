"""The simulated forearm: a physically based rig that runs without hardware.

The skin's waves follow a named preset (``nominal``, ``low``, ``high``: a layered arm
whose dispersion and loss come from separate published measurements; ``voigt-fit``: a
homogeneous Voigt law fitted to phase speeds); see ``docs/skin-model.md``.
"""

from .fit import WaveLawFit, fit_wave_law, load_forearm_data
from .forearm import SimulatedForearm, drive_sensitivity
from .geometry import ForearmGeometry
from .layered import LayeredLaw
from .parameters import NOMINAL_LAW, ForearmParameters, attenuation_range_laws
from .presets import DEFAULT_SKIN, LAYERED_NOMINAL, SKIN_PRESETS, SkinPreset, skin_preset
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
    "LayeredLaw",
    "LAYERED_NOMINAL",
    "SKIN_PRESETS",
    "DEFAULT_SKIN",
    "SkinPreset",
    "skin_preset",
    "NOMINAL_LAW",
    "attenuation_range_laws",
    "fit_wave_law",
    "load_forearm_data",
    "WaveLawFit",
]
