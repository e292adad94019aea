"""The simulated forearm's physics: a physically based arm that runs without hardware.

:class:`SimulatedArm` is the physics and imports nothing from :mod:`vibrofocus.rigs`; the
rig over it is :class:`vibrofocus.rigs.SimulatedForearm` (``vibrofocus.skin.SimulatedForearm``,
its former place, is deprecated: DEVELOPING.md, "Names").

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
    # The simulated rig lives in vibrofocus.rigs (an adapter over this physics); its former
    # place here warns, and loads the rigs only when used.
    if name == "SimulatedForearm":
        from .._deprecated import warn_deprecated
        from ..rigs.simulated import SimulatedForearm

        warn_deprecated(f"{__name__}.SimulatedForearm", "vibrofocus.rigs.SimulatedForearm")
        return SimulatedForearm
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
