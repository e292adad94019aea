"""The simulated forearm's physics: a physically based arm that runs without hardware.

:class:`SimulatedArm` is the physics and imports nothing from :mod:`vibrofocus.rigs`; the
rig over it, :class:`~vibrofocus.rigs.simulated.SimulatedForearm`, is reachable here too
(loaded on first use, so that importing the physics does not load the rigs).

The skin's waves follow a named preset (``nominal``, ``low``, ``high``: a layered arm
whose dispersion and loss come from separate published measurements; ``voigt-fit``: a
homogeneous Voigt law fitted to phase speeds); see ``docs/skin-model.md``.
"""

from .fit import WaveLawFit, fit_wave_law, load_forearm_data
from .forearm import SimulatedArm, drive_sensitivity
from .geometry import ForearmGeometry
from .layered import LayeredLaw
from .parameters import NOMINAL_LAW, ForearmParameters, attenuation_range_laws
from .presets import DEFAULT_SKIN, LAYERED_NOMINAL, SKIN_PRESETS, SkinPreset, skin_preset
from .propagation import exciter_response, surface_green, wavenumber
from .viscoelastic import ViscoelasticLaw

__all__ = [
    "SimulatedForearm",
    "SimulatedArm",
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


def __getattr__(name: str):
    # The simulated rig lives in vibrofocus.rigs (an adapter over this physics); it is
    # offered here under its long-standing name without the physics importing the rigs.
    if name == "SimulatedForearm":
        from ..rigs.simulated import SimulatedForearm

        return SimulatedForearm
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
